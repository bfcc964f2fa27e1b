"""The operator's proof: an operator command carries an HMAC-SHA256 of its fields under a
secret key that only the service and the operator hold, so that on a zenoh without access
control (any peer may query the operator key) a command from anyone else is refused; and
every reply of the service carries the HMAC of its exact bytes (the zenoh reply's
attachment), so that the operator believes no reply but the service's.

The secret itself never crosses the link: an eavesdropper on an unencrypted zenoh link
sees a command and its proof, which tells nothing of the key (HMAC-SHA256 is a PRF) and
proves nothing for any other command. Replaying the captured command is refused three
times over: the proof covers the service's ``nonce`` (128 random bits drawn at each start,
given to anyone by ``hello``), so a command made for another run of the service is refused
whatever its time; its ``sent_at_ms`` must lie within ``window_s`` of the service's clock;
and a ``client_ref`` already seen within that window is refused. The proof covers the
vehicle's keys too, so a command for ``uav1`` is no proof for ``uav2`` under the same key.
A reply's proof covers the command's proof it answers (empty for ``hello``), so a reply
made for one command proves nothing for another.

Python's ``hmac`` (with ``hmac.compare_digest``, a comparison in constant time) and
``secrets`` are the standard library's, maintained with CPython and used by its own
``multiprocessing`` authentication: no dependency to add, nothing of our own to get wrong.

The key file is the MAVLink signing key's format (``protocol.signing``): 32 random bytes as
64 hex characters, mode 0600, refused if its group or others may read it.

Pure: the clock is an argument; ``ProofCheck`` keeps its nonce and the client_refs seen.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
from dataclasses import dataclass, field

import msgspec

from .errors import ProtocolError, SigningError
from .keys import Keys
from .signing import load_key, write_key

CONTEXT = "uavmec-operator-command-2"
"""The first element of the signed text: a proof made for anything else never matches."""
REPLY_CONTEXT = "uavmec-operator-reply-1"
"""The first element of a reply's signed text (never a command's: a reply is no command)."""
WINDOW_S = 30.0
"""Default: how far ``sent_at_ms`` may lie from the service's clock (either way)."""
MAX_REMEMBERED = 1024
"""client_refs kept to refuse replays; a key holder sending more within one window is
refused until the oldest expire (a person types a few commands a minute)."""


def new_nonce() -> str:
    """A service's nonce for one run: 128 random bits, 32 hex digits."""
    return secrets.token_hex(16)


def signed_text(keys: Keys, command: str, reason: str, client_ref: str, sent_at_ms: int, nonce: str) -> bytes:
    """What the proof covers, as unambiguous bytes (a JSON array: no field can run into the
    next one, whatever characters the reason holds)."""
    return msgspec.json.encode([CONTEXT, keys.prefix, keys.vehicle, command, reason, client_ref, sent_at_ms,
                                nonce])


def sign(key: bytes, keys: Keys, command: str, reason: str, client_ref: str, sent_at_ms: int, nonce: str) -> str:
    """The proof of a command: HMAC-SHA256 of ``signed_text`` under ``key``, 64 hex digits."""
    return _hmac(key, signed_text(keys, command, reason, client_ref, sent_at_ms, nonce))


def prove_reply(key: bytes, keys: Keys, command_proof: str | None, payload: bytes) -> str:
    """The proof of a reply: HMAC-SHA256 of the reply's exact bytes, the vehicle's keys and the
    proof of the command it answers (none for ``hello``), under ``key``."""
    head = msgspec.json.encode([REPLY_CONTEXT, keys.prefix, keys.vehicle, (command_proof or "").lower()])
    return _hmac(key, head + b"\n" + payload)


def reply_proved(key: bytes, keys: Keys, command_proof: str | None, payload: bytes, proof: bytes | None) -> bool:
    """Whether ``proof`` (a reply's attachment) proves ``payload`` the service's answer to the
    command whose proof is ``command_proof``."""
    if proof is None:
        return False
    expected = prove_reply(key, keys, command_proof, payload)
    return hmac.compare_digest(expected.encode(), proof.strip().lower())


def _hmac(key: bytes, text: bytes) -> str:
    return hmac.new(key, text, hashlib.sha256).hexdigest()


@dataclass
class ProofCheck:
    """The service's check of operator commands' proofs (one per service)."""

    key: bytes
    keys: Keys
    window_s: float = WINDOW_S
    nonce: str = field(default_factory=new_nonce)
    """This run's: a command's proof covers it, so no command made for another run passes."""
    max_remembered: int = MAX_REMEMBERED
    seen: dict[str, float] = field(default_factory=dict)
    """client_ref -> until when (the service's clock, s) a command with it is refused."""

    def refusal(self, command: str, reason: str, client_ref: str | None, sent_at_ms: int | None,
                proof: str | None, nonce: str | None, now_s: float) -> ProtocolError | None:
        """None if the command carries a valid, fresh proof not seen before (its client_ref is
        then remembered); else the error naming the field at fault. The proof is checked
        before the time and the client_ref are, so that nobody without the key learns from
        the replies what the service's clock reads or which refs it has seen."""
        if proof is None:
            return ProtocolError("proof", "an operator command needs the operator's proof (HMAC of the command "
                                          "under the operator key; without zenoh access control the service takes "
                                          "commands only from the holder of its key file)")
        if client_ref is None or sent_at_ms is None or nonce is None:
            missing = "client_ref" if client_ref is None else "sent_at_ms" if sent_at_ms is None else "nonce"
            return ProtocolError(missing, "a command with a proof needs client_ref, sent_at_ms and nonce "
                                          "(the service's, from hello)")
        expected = sign(self.key, self.keys, command, reason, client_ref, sent_at_ms, nonce)
        if not hmac.compare_digest(expected, proof.lower()):
            return ProtocolError("proof", "does not match: not made with the service's operator key "
                                          "(or for another vehicle, or the command was altered)")
        if not hmac.compare_digest(nonce.lower(), self.nonce):
            return ProtocolError("nonce", "made for another run of the service (it restarted since the "
                                          "command was made, or the command is replayed): ask hello again")
        skew_s = sent_at_ms / 1000.0 - now_s
        if abs(skew_s) > self.window_s:
            return ProtocolError("sent_at_ms", f"{skew_s:+.1f} s from the service's clock (at most "
                                               f"{self.window_s:g} s either way: a replay, or clocks apart)")
        for ref in [r for r, until in self.seen.items() if until < now_s]:
            del self.seen[ref]
        if client_ref in self.seen:
            return ProtocolError("client_ref", f"{client_ref!r} was already used: a replayed command")
        if len(self.seen) >= self.max_remembered:
            return ProtocolError("service", f"{self.max_remembered} operator commands within {self.window_s:g} s; "
                                            "retry in a moment")
        # refused until the command's own time has left the window for good
        self.seen[client_ref] = max(now_s, sent_at_ms / 1000.0) + 2 * self.window_s
        return None

    def prove(self, command_proof: str | None, payload: bytes) -> str:
        """The proof of the reply ``payload`` to the command whose proof is ``command_proof``."""
        return prove_reply(self.key, self.keys, command_proof, payload)


def load_or_create_key(path: str | os.PathLike[str]) -> tuple[bytes, bool]:
    """The operator key in ``path``, made (32 random bytes, mode 0600) if there is none;
    and whether it was made now. ``SigningError`` naming the file if it cannot be read,
    is malformed, or its group or others may read it."""
    try:
        return write_key(path), True
    except SigningError:
        if not os.path.lexists(path):
            raise
    return load_key(path), False
