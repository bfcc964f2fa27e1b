"""Fleet messages that prove who sent them: every message a member puts on the fleet's keys
(announcement, intentions, services, positions) travels in an envelope signed with its
vehicle's Ed25519 key, and is read only from a vehicle the operator enrolled (its public key
in the fleet's roster file). Without it any zenoh peer could speak for any member (issue 34:
forged services, a rogue member's airspace, a token that bars a start).

Keys, as the operator key (``protocol.operator_proof``): a vehicle's private key is the
32-byte Ed25519 seed in ``protocol.signing``'s key-file format (64 hex characters, mode
0600, refused if group or others may read it, or another user owns it). The roster is a text
file, one ``VEHICLE PUBLIC-KEY-HEX`` per line (``#`` comments): public, copied to every member
and to the operator's watch.

The envelope (``FleetEnvelope``) carries the message's JSON as text (``body``), the sender's
vehicle, a random id of the sender's boot (``boot``, 16 hex: a restarted service is a new
boot), a sequence number that rises by one with every message of that boot (``seq``), the
sender's wall clock (``t``), and the signature over all of them and the zenoh key it was put
on (``signed_text``: a message signed for one key is no proof on another).

The replay rule (``ReplayGuard``, per zenoh key): a message is taken only if its signed time
lies within ``max_age_s`` before the reader's clock (and at most ``FUTURE_S`` after it), it was
never taken before (its boot and seq), and, on a key where the latest message wins
(announcement, intentions, position), it is not older than the last taken there. A captured
message replayed later is stale, or already seen; the announcement is signed again every few
seconds, so a replayed old one cannot make an absent vehicle a member for long.

Pure: the clock is an argument; ``cryptography`` (the Python Cryptographic Authority's, over
OpenSSL) does the curve.
"""

from __future__ import annotations

import os
import re
import secrets
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import msgspec
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey, Ed25519PublicKey
from cryptography.hazmat.primitives.serialization import Encoding, PublicFormat

from .errors import SigningError
from .signing import load_key, write_key

CONTEXT = "uavmec-fleet-1"
"""The first element of the signed text: a signature made for anything else never matches."""
FUTURE_S = 5.0
"""How far a message's signed time may lie ahead of the reader's clock (clocks differ a little)."""
CLOCK_WINDOW_S = 10.0
"""A member's clock offset is judged on its messages heard within this long (several
announcements and positions: the freshest of them tells)."""
MAX_ENVELOPE_BYTES = 96 * 1024
"""The largest envelope read (an intentions message of 256 users fits many times)."""
MAX_STREAMS = 4096
"""Zenoh keys the guard remembers: a flood of keys cannot grow it without bound."""
MAX_SEEN_PER_STREAM = 1024
"""(boot, seq) kept per key; a sender that puts more within one ``max_age_s`` is refused until
the oldest expire (a member sends a few messages a second)."""

_VEHICLE = r"\A[A-Za-z0-9_.\-]+\Z"


class FleetEnvelope(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A fleet message and its signature (the payload put on a fleet key)."""

    vehicle: Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=_VEHICLE)]
    boot: Annotated[str, msgspec.Meta(pattern=r"\A[0-9a-f]{16}\Z")]
    seq: Annotated[int, msgspec.Meta(ge=0, le=2 ** 53)]
    t: float
    body: str
    sig: Annotated[str, msgspec.Meta(pattern=r"\A[0-9a-f]{128}\Z")]


def signed_text(key_expr: str, vehicle: str, boot: str, seq: int, t: float, body: str) -> bytes:
    """What the signature covers, as unambiguous bytes (a JSON array)."""
    return msgspec.json.encode([CONTEXT, key_expr, vehicle, boot, seq, t, body])


# --- key files ---------------------------------------------------------------------------------
def load_private_key(path: str | os.PathLike[str]) -> Ed25519PrivateKey:
    """A vehicle's signing key (its 32-byte seed as hex, mode 0600: ``SigningError`` naming
    the file otherwise, as for the operator key)."""
    return Ed25519PrivateKey.from_private_bytes(load_key(path))


def public_hex(key: Ed25519PrivateKey) -> str:
    """The public half of ``key`` as 64 hex characters (a roster line's second word)."""
    return key.public_key().public_bytes(Encoding.Raw, PublicFormat.Raw).hex()


def make_vehicle_key(key_path: str | os.PathLike[str], roster_path: str | os.PathLike[str], vehicle: str) -> str:
    """Create ``key_path`` (mode 0600, never overwritten) with a fresh key for ``vehicle`` and
    add its public key to ``roster_path`` (created if missing; a vehicle already enrolled there
    is refused: remove its line first). Returns the roster line."""
    if not _vehicle_ok(vehicle):
        raise SigningError("vehicle", f"{vehicle!r} is not a vehicle id (letters, digits, _ . -)")
    roster = Path(roster_path)
    if roster.exists() and vehicle in read_roster(roster):
        raise SigningError(str(roster), f"{vehicle} is already enrolled (remove its line to enrol a new key)")
    key = Ed25519PrivateKey.from_private_bytes(write_key(key_path))
    line = f"{vehicle} {public_hex(key)}\n"
    with open(roster, "a", encoding="ascii") as out:
        out.write(line)
    return line.strip()


def _vehicle_ok(vehicle: str) -> bool:
    return 0 < len(vehicle) <= 64 and re.fullmatch(_VEHICLE, vehicle) is not None


def read_roster(path: str | os.PathLike[str]) -> dict[str, Ed25519PublicKey]:
    """The enrolled vehicles and their public keys; ``SigningError`` naming the file and line
    for a missing file, a malformed line or a vehicle named twice."""
    name = str(path)
    try:
        text = Path(path).read_text(encoding="ascii")
    except FileNotFoundError:
        raise SigningError(name, "no such fleet roster (make one with: python -m planner_service fleet-key)") from None
    except (OSError, UnicodeDecodeError) as err:
        raise SigningError(name, f"cannot read the fleet roster: {err}") from None
    out: dict[str, Ed25519PublicKey] = {}
    for number, line in enumerate(text.splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if len(words) != 2 or not _vehicle_ok(words[0]) or len(words[1]) != 64:
            raise SigningError(f"{name}:{number}", "must read VEHICLE PUBLIC-KEY (64 hex characters)")
        if words[0] in out:
            raise SigningError(f"{name}:{number}", f"{words[0]} is enrolled twice")
        try:
            out[words[0]] = Ed25519PublicKey.from_public_bytes(bytes.fromhex(words[1]))
        except ValueError:
            raise SigningError(f"{name}:{number}", "the public key is not 64 hex characters") from None
    return out


# --- sending -----------------------------------------------------------------------------------
class FleetSigner:
    """One service's signer: a boot id of its own, a sequence number per message."""

    def __init__(self, vehicle: str, key: Ed25519PrivateKey) -> None:
        self.vehicle = vehicle
        self._key = key
        self.boot = secrets.token_hex(8)
        self._seq = 0

    def seal(self, key_expr: str, body: bytes, now_s: float) -> bytes:
        """``body`` (a message's JSON) in a signed envelope for ``key_expr``, at wall time ``now_s``."""
        text = body.decode("utf-8")
        self._seq += 1
        sig = self._key.sign(signed_text(key_expr, self.vehicle, self.boot, self._seq, now_s, text)).hex()
        return msgspec.json.encode(FleetEnvelope(self.vehicle, self.boot, self._seq, now_s, text, sig))


# --- reading -----------------------------------------------------------------------------------
def unverified_body(payload: bytes) -> bytes:
    """The message in an envelope, its signature NOT checked (``Unverified`` if it is none):
    for a reader without the roster that trusts its transport (a simulated user counting its
    backlog down); a member always goes through ``FleetVerifier``."""
    try:
        return msgspec.json.decode(payload, type=FleetEnvelope).body.encode("utf-8")
    except (msgspec.DecodeError, msgspec.ValidationError, UnicodeDecodeError, RecursionError) as err:
        raise Unverified(f"not a fleet envelope: {str(err)[:120]}") from None


class Unverified(Exception):
    """A fleet message refused: not enrolled, a bad signature, stale or replayed (``why``)."""

    def __init__(self, why: str) -> None:
        super().__init__(why)
        self.why = why


@dataclass
class ReplayGuard:
    """The replay rule, per zenoh key (the module's doc)."""

    seen: dict[str, dict[tuple[str, int], float]] = field(default_factory=dict)
    latest: dict[str, float] = field(default_factory=dict)

    def check(self, key_expr: str, boot: str, seq: int, t: float, now_s: float, max_age_s: float,
              latest_wins: bool) -> None:
        """Take the message (remember it) or raise ``Unverified``."""
        if t > now_s + FUTURE_S:
            raise Unverified(f"signed {t - now_s:.1f} s in the future")
        if t < now_s - max_age_s:
            raise Unverified(f"stale: signed {now_s - t:.0f} s ago (more than {max_age_s:g} s)")
        stream = self.seen.get(key_expr)
        if stream is None:
            if len(self.seen) >= MAX_STREAMS:
                raise Unverified(f"more than {MAX_STREAMS} fleet keys heard")
            stream = self.seen[key_expr] = {}
        if (boot, seq) in stream:
            raise Unverified(f"replayed (boot {boot}, seq {seq} already taken)")
        if latest_wins and t < self.latest.get(key_expr, float("-inf")):
            raise Unverified("older than the last message taken on its key")
        if len(stream) >= MAX_SEEN_PER_STREAM:
            for mark in [m for m, at in stream.items() if at < now_s - max_age_s]:
                del stream[mark]
            if len(stream) >= MAX_SEEN_PER_STREAM:
                raise Unverified(f"more than {MAX_SEEN_PER_STREAM} messages on its key within {max_age_s:g} s")
        stream[(boot, seq)] = t
        if latest_wins:
            self.latest[key_expr] = t


@dataclass
class FleetVerifier:
    """Reads envelopes from the enrolled vehicles (``roster``), with the replay rule; keeps a
    count of what it refused (``ignored``), for the log and the operator."""

    roster: dict[str, Ed25519PublicKey]
    guard: ReplayGuard = field(default_factory=ReplayGuard)
    ignored: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    """zenoh calls back on its own threads: the guard's memory is one."""
    _ahead: dict[str, tuple[float, float]] = field(default_factory=dict, repr=False)
    """vehicle -> (when, by how much) its clock read furthest ahead of this reader's within
    ``CLOCK_WINDOW_S``: signed time less the reader's clock at arrival, over every message
    its key signed (taken or refused for its time)."""

    def clock_offset(self, vehicle: str, now_s: float) -> float | None:
        """How far ``vehicle``'s clock reads ahead of this reader's (negative: behind), from
        the freshest of its signed messages heard within ``CLOCK_WINDOW_S`` (a message's age
        on the way only lowers the estimate, and a replayed one cannot raise it); None when
        none was heard."""
        with self._lock:
            mark = self._ahead.get(vehicle)
        return None if mark is None or mark[0] < now_s - CLOCK_WINDOW_S else mark[1]

    def _clock(self, vehicle: str, t: float, now_s: float) -> None:
        ahead = t - now_s
        mark = self._ahead.get(vehicle)
        if mark is None or mark[0] < now_s - CLOCK_WINDOW_S or ahead >= mark[1]:
            self._ahead[vehicle] = (now_s, ahead)

    def count_ignored(self) -> None:
        """Count a message the caller refused after opening it (beyond its bounds)."""
        with self._lock:
            self.ignored += 1

    def open(self, key_expr: str, vehicle: str, payload: bytes, now_s: float, max_age_s: float,
             latest_wins: bool = True) -> tuple[bytes, float]:
        """The message signed by ``vehicle`` (the vehicle its key names) in ``payload`` put on
        ``key_expr``, and its signed time; or ``Unverified`` (counted)."""
        with self._lock:
            try:
                return self._open(key_expr, vehicle, payload, now_s, max_age_s, latest_wins)
            except Unverified:
                self.ignored += 1
                raise

    def _open(self, key_expr: str, vehicle: str, payload: bytes, now_s: float, max_age_s: float,
              latest_wins: bool) -> tuple[bytes, float]:
        public = self.roster.get(vehicle)
        if public is None:
            raise Unverified(f"{vehicle} is not enrolled in the fleet's roster")
        if len(payload) > MAX_ENVELOPE_BYTES:
            raise Unverified(f"{len(payload)} bytes (more than {MAX_ENVELOPE_BYTES})")
        try:
            env = msgspec.json.decode(payload, type=FleetEnvelope)
        except (msgspec.DecodeError, msgspec.ValidationError, UnicodeDecodeError, RecursionError) as err:
            raise Unverified(f"not a signed fleet message: {str(err)[:120]}") from None
        if env.vehicle != vehicle:
            raise Unverified(f"signed as {env.vehicle!r} on {vehicle}'s key")
        try:
            public.verify(bytes.fromhex(env.sig), signed_text(key_expr, env.vehicle, env.boot, env.seq, env.t, env.body))
        except InvalidSignature:
            raise Unverified(f"bad signature (not {vehicle}'s enrolled key)") from None
        self._clock(vehicle, env.t, now_s)
        self.guard.check(key_expr, env.boot, env.seq, env.t, now_s, max_age_s, latest_wins)
        return env.body.encode("utf-8"), env.t
