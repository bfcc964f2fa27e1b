"""The operator key's file and the proof's text: made owner-only, refused when others may
read it, and a proof that is exactly one HMAC-SHA256 checkable with the standard library."""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import stat
from pathlib import Path

import pytest

from protocol import Keys, SigningError
from protocol.operator_proof import CONTEXT, REPLY_CONTEXT, ProofCheck, load_or_create_key, prove_reply, sign, signed_text


def test_the_key_is_made_owner_only_and_then_read_back(tmp_path: Path) -> None:
    path = tmp_path / "operator.key"
    key, made = load_or_create_key(path)
    assert made and len(key) == 32 and stat.S_IMODE(path.stat().st_mode) == 0o600
    again, made = load_or_create_key(path)
    assert (again, made) == (key, False)


@pytest.mark.parametrize("mode", [0o640, 0o604, 0o644])
def test_a_key_others_may_read_is_refused_naming_the_file(tmp_path: Path, mode: int) -> None:
    path = tmp_path / "operator.key"
    load_or_create_key(path)
    os.chmod(path, mode)
    with pytest.raises(SigningError, match=f"permissions {mode:04o} are too open") as err:
        load_or_create_key(path)
    assert err.value.path == str(path)


def test_a_key_in_a_missing_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SigningError, match="cannot create the key file"):
        load_or_create_key(tmp_path / "no-such-folder" / "operator.key")


def test_the_proof_is_an_hmac_sha256_of_the_fields_as_a_json_array() -> None:
    key, keys = b"k" * 32, Keys("uavmec", "uav1")
    nonce = "ab" * 16
    text = signed_text(keys, "start", 'a "reason", with, commas', "r-1", 1_700_000_000_000, nonce)
    assert json.loads(text) == [CONTEXT, "uavmec", "uav1", "start", 'a "reason", with, commas', "r-1",
                                1_700_000_000_000, nonce]
    assert sign(key, keys, "start", 'a "reason", with, commas', "r-1", 1_700_000_000_000, nonce) == \
        hmac.new(key, text, hashlib.sha256).hexdigest()
    # fields cannot run into each other: moving a character across a boundary changes the proof
    assert sign(key, keys, "start", "ab", "c", 1, nonce) != sign(key, keys, "start", "a", "bc", 1, nonce)


def test_a_reply_proof_is_an_hmac_sha256_of_its_context_and_bytes() -> None:
    key, keys = b"k" * 32, Keys("uavmec", "uav1")
    head = json.dumps([REPLY_CONTEXT, "uavmec", "uav1", "ab" * 32], separators=(",", ":")).encode()
    assert prove_reply(key, keys, "AB" * 32, b'{"kind":"x"}') == \
        hmac.new(key, head + b"\n" + b'{"kind":"x"}', hashlib.sha256).hexdigest()


def test_every_run_draws_its_own_nonce() -> None:
    nonces = {ProofCheck(b"k" * 32, Keys()).nonce for _ in range(100)}
    assert len(nonces) == 100 and all(len(n) == 32 and int(n, 16) >= 0 for n in nonces)
