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
from protocol.operator_proof import CONTEXT, load_or_create_key, sign, signed_text


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
    text = signed_text(keys, "start", 'a "reason", with, commas', "r-1", 1_700_000_000_000)
    assert json.loads(text) == [CONTEXT, "uavmec", "uav1", "start", 'a "reason", with, commas', "r-1",
                                1_700_000_000_000]
    assert sign(key, keys, "start", 'a "reason", with, commas', "r-1", 1_700_000_000_000) == \
        hmac.new(key, text, hashlib.sha256).hexdigest()
    # fields cannot run into each other: moving a character across a boundary changes the proof
    assert sign(key, keys, "start", "ab", "c", 1) != sign(key, keys, "start", "a", "bc", 1)
