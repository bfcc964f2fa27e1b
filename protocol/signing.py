"""MAVLink 2 message signing: the shared key on disk, timestamps that never repeat across
restarts, and a signature check that follows the specification.

The key is 32 secret bytes kept as 64 hex characters in a file only its owner may read
(refused otherwise, as ssh refuses a private key others can read). ``write_key`` makes one.

A signature carries a 48-bit timestamp (10 µs units since 2015-01-01 UTC) that a receiver
requires to grow on every stream ``(link id, system, component)``: a restarted sender that
reused an old timestamp would be ignored, and an attacker replaying captured bytes is. So
``TimestampStore`` keeps a *reservation* in a small file: a timestamp the process promises
not to pass before it writes a higher one. A restart starts above it even after a crash or
with a clock that went back.

``Signer`` puts one signing state on any number of pymavlink ``MAVLink`` objects (a vehicle's
encoder and one parser per peer share it, so a replay is caught whichever address it comes
from) and replaces pymavlink's ``check_signature``, which records a stream's timestamp
*before* verifying the signature: there a forged packet with a far-future timestamp would
lock the real sender out. Here the signature is checked first, as the C library does.
"""

from __future__ import annotations

import fcntl
import hashlib
import hmac
import os
import secrets
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from pymavlink.dialects.v20 import common as mavlink

from .errors import SigningError

KEY_BYTES = 32
MAVLINK_EPOCH_UNIX_S = 1420070400
"""2015-01-01T00:00:00Z, the origin of signing timestamps."""
TICKS_PER_S = 100_000
"""Timestamp units per second (10 µs)."""
NEW_STREAM_WINDOW = 60 * TICKS_PER_S
"""A stream not seen before is accepted only if at most one minute behind our timestamp (spec)."""
RESERVE_TICKS = 30 * TICKS_PER_S
"""How far ahead of the timestamp in use the stored reservation runs. After a crash a restart
begins at most this far ahead of the wall clock: well inside a peer's one-minute window."""
MAX_TIMESTAMP = (1 << 48) - 1
ACCEPT_UNSIGNED = frozenset({mavlink.MAVLINK_MSG_ID_RADIO_STATUS})
"""Unsigned messages a signing system still accepts: the spec's example, for telemetry radios."""
SIGNATURE_LEN = 13


def timestamp_at(unix_s: float) -> int:
    """The signing timestamp of a wall-clock time (seconds since 1970)."""
    return max(0, int((unix_s - MAVLINK_EPOCH_UNIX_S) * TICKS_PER_S))


def key_from_passphrase(passphrase: str) -> bytes:
    """SHA-256 of an ASCII passphrase: the key MAVProxy's ``signing setup PASSPHRASE`` makes."""
    try:
        return hashlib.sha256(passphrase.encode("ascii")).digest()
    except UnicodeEncodeError:
        raise SigningError("passphrase", "must be ASCII (MAVProxy hashes the ASCII bytes)") from None


# --- the key file ------------------------------------------------------------------------------
def load_key(path: str | os.PathLike[str]) -> bytes:
    """The 32-byte key in ``path``: 64 hex characters, an optional trailing newline.
    ``SigningError`` naming the file if it is missing, malformed, or open to group or others."""
    name = str(path)
    try:
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        raise SigningError(name, "no such key file (make one with: python -m planner_service keygen PATH)") from None
    except OSError as err:
        raise SigningError(name, f"cannot open the key file: {err.strerror or err}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise SigningError(name, "is not a regular file")
        if info.st_mode & 0o077:
            raise SigningError(name, f"permissions {stat.S_IMODE(info.st_mode):04o} are too open: the key must be "
                                     f"readable by its owner only (chmod 600 {name})")
        raw = os.read(fd, 4 * KEY_BYTES)
    finally:
        os.close(fd)
    text = raw.decode("ascii", errors="replace")
    text = text[:-1] if text.endswith("\n") else text
    if len(text) != 2 * KEY_BYTES:
        raise SigningError(name, f"must hold {2 * KEY_BYTES} hex characters (a 32-byte key), "
                                 f"found {len(text)} characters")
    try:
        return bytes.fromhex(text)
    except ValueError:
        raise SigningError(name, f"must hold {2 * KEY_BYTES} hex characters (0-9, a-f)") from None


def write_key(path: str | os.PathLike[str], key: bytes | None = None) -> bytes:
    """Create ``path`` (never overwriting) with mode 0600 holding ``key`` (default: 32 fresh
    random bytes) as hex; returns the key. The file is created with its final mode, so it is
    never readable by others, even for a moment."""
    key = secrets.token_bytes(KEY_BYTES) if key is None else key
    if len(key) != KEY_BYTES:
        raise SigningError(str(path), f"a key is {KEY_BYTES} bytes, got {len(key)}")
    name = str(path)
    try:
        fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0), 0o600)
    except FileExistsError:
        raise SigningError(name, "already exists (a key is never overwritten: remove it first)") from None
    except OSError as err:
        raise SigningError(name, f"cannot create the key file: {err.strerror or err}") from None
    try:
        os.fchmod(fd, 0o600)  # the umask may only remove bits; this makes the mode exact
        os.write(fd, (key.hex() + "\n").encode("ascii"))
        os.fsync(fd)
    except OSError as err:  # a full disk: no half-written key is left to be refused later
        os.close(fd)
        os.unlink(name)
        raise SigningError(name, f"cannot write the key file: {err.strerror or err}") from None
    os.close(fd)
    return key


# --- timestamps ---------------------------------------------------------------------------------
def default_timestamp_path(key_path: str | os.PathLike[str], role: str) -> Path:
    """Where a process of ``role`` ("service", "vehicle") keeps its timestamp beside the key:
    two processes sharing a key must not share a timestamp file."""
    key = Path(key_path)
    return key.with_name(f"{key.name}.{role}-timestamp")


class TimestampStore:
    """The reservation file: ``open`` -> start timestamp; ``advance`` as time passes; ``close``.

    The file holds one decimal number: a timestamp this process will not exceed before it
    stores a higher one. A lock beside it refuses a second process on the same file.
    """

    def __init__(self, path: str | os.PathLike[str], clock: Callable[[], float] = time.time,
                 reserve_ticks: int = RESERVE_TICKS) -> None:
        self.path = Path(path)
        self.clock = clock
        self.reserve_ticks = reserve_ticks
        self.reserved = 0
        self._lock_fd: int | None = None

    def open(self) -> int:
        """Lock the file and return the first timestamp to use: the larger of the wall clock's
        and the stored reservation + 1."""
        self._lock()
        try:
            stored = self._read()
            start = max(timestamp_at(self.clock()), stored + 1)
            self._store(start + self.reserve_ticks)
        except BaseException:
            self._unlock()
            raise
        return start

    def advance(self, current: int) -> int:
        """The timestamp to continue from: ``current`` raised to the wall clock (a quiet link
        must not fall minutes behind, or a restarted peer would take it for a replay); the
        reservation is moved ahead before it could be reached."""
        now = max(current, timestamp_at(self.clock()))
        if now + self.reserve_ticks // 2 > self.reserved:
            self._store(now + self.reserve_ticks)
        return now

    def close(self, current: int) -> None:
        """Store the last timestamp used and release the lock."""
        if self._lock_fd is None:
            return
        try:
            self._store(max(current, 0))
        finally:
            self._unlock()

    # --- internals ------------------------------------------------------------------------------
    def _lock(self) -> None:
        lock_path = f"{self.path}.lock"
        try:
            fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o600)
        except OSError as err:
            raise SigningError(str(self.path),
                               f"cannot create the lock file {lock_path}: {err.strerror or err}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise SigningError(str(self.path), "is in use by another process: give each process sharing a key "
                                               "its own timestamp file") from None
        self._lock_fd = fd

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing releases the flock
            self._lock_fd = None

    def _read(self) -> int:
        try:
            text = self.path.read_text(encoding="ascii").strip()
        except FileNotFoundError:
            return 0
        except (OSError, UnicodeDecodeError) as err:
            raise SigningError(str(self.path), f"cannot read the timestamp file: {err}") from None
        if not text.isdigit() or int(text) > MAX_TIMESTAMP:
            raise SigningError(str(self.path), f"holds {text[:40]!r}, not a signing timestamp; delete it only if "
                                               "this machine's clock is right (a stale timestamp gets our messages "
                                               "ignored as replays)")
        return int(text)

    def _store(self, value: int) -> None:
        """Write ``value`` atomically (a crash leaves the old or the new number, never half)."""
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            try:
                os.write(fd, f"{value}\n".encode("ascii"))
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
        except OSError as err:
            raise SigningError(str(self.path), f"cannot write the timestamp file: {err.strerror or err}") from None
        self.reserved = value


# --- signing pymavlink objects ------------------------------------------------------------------
@dataclass
class SigningStats:
    """What the signature check let through and what it dropped, by reason and message."""

    accepted: int = 0
    unsigned_allowed: int = 0
    dropped: dict[str, int] = field(default_factory=dict)
    """reason (unsigned, bad signature, replayed, stale stream) -> count"""
    dropped_types: dict[str, int] = field(default_factory=dict)
    """message name -> count"""

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())

    def summary(self) -> str:
        reasons = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped.items())) or "none"
        kinds = ", ".join(f"{k} {v}" for k, v in sorted(self.dropped_types.items())) or "none"
        return (f"{self.accepted} signed accepted, {self.unsigned_allowed} unsigned allowed, "
                f"{self.dropped_total} dropped ({reasons}; by message: {kinds})")


class Signer:
    """One signing state (key, our timestamp, the streams heard) shared by every pymavlink
    ``MAVLink`` object it is attached to.

    ``store`` None keeps timestamps monotonic within this process only (tests, tools).
    Call ``tick`` about once a second from the thread that sends, and ``close`` at the end.
    """

    def __init__(self, key: bytes, store: TimestampStore | None = None, link_id: int = 0,
                 accept_unsigned: frozenset[int] = ACCEPT_UNSIGNED, clock: Callable[[], float] = time.time) -> None:
        if len(key) != KEY_BYTES:
            raise SigningError("key", f"a key is {KEY_BYTES} bytes, got {len(key)}")
        if not 0 <= link_id <= 255:
            raise SigningError("link_id", f"must lie in 0..255, got {link_id}")
        self.store = store
        self.clock = clock
        self.accept_unsigned = accept_unsigned
        self.stats = SigningStats()
        self.last_drop = ""
        """'<MESSAGE> (<reason>)' of the latest dropped message."""
        self._reason: str | None = None
        self._highest_heard = 0
        state = mavlink.MAVLinkSigning()
        state.secret_key = key
        state.link_id = link_id
        state.sign_outgoing = True
        state.allow_unsigned_callback = self._allow_unsigned
        state.timestamp = store.open() if store is not None else timestamp_at(clock())
        self.state = state

    def attach(self, mav: Any) -> None:
        """Sign everything ``mav`` packs and accept only what passes ``check_signature``."""
        mav.signing = self.state
        mav.check_signature = self.check_signature  # an instance attribute: pymavlink calls self.check_signature

    @property
    def timestamp(self) -> int:
        return int(self.state.timestamp)

    def tick(self) -> None:
        """Bring our timestamp up to the wall clock and to the highest one heard (spec: a
        correctly signed message's timestamp raises ours), and keep the reservation ahead.
        Done here, on the sending thread, so the reader never races the sender's count."""
        current = max(self.state.timestamp, self._highest_heard)
        self.state.timestamp = self.store.advance(current) if self.store is not None else max(
            current, timestamp_at(self.clock()))

    def close(self) -> None:
        if self.store is not None:
            self.store.close(self.state.timestamp)

    def check_signature(self, msgbuf: Any, src_system: int, src_component: int) -> bool:
        """The spec's acceptance of a signed packet: the signature first, then the timestamp
        against the stream's last one (or, for a new stream, within a minute of ours)."""
        buf = bytes(msgbuf)
        digest = hashlib.sha256(self.state.secret_key + buf[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, buf[-6:]):
            self._reason = "bad signature"
            return False
        link_id = buf[-SIGNATURE_LEN]
        timestamp = int.from_bytes(buf[-12:-6], "little")
        stream = (link_id, src_system, src_component)
        last = self.state.stream_timestamps.get(stream)
        if last is None and timestamp + NEW_STREAM_WINDOW < self.state.timestamp:
            self._reason = "stale stream"
            return False
        if last is not None and timestamp <= last:
            self._reason = "replayed"
            return False
        self.state.stream_timestamps[stream] = timestamp
        self._highest_heard = max(self._highest_heard, timestamp)
        self.stats.accepted += 1
        return True

    def _allow_unsigned(self, mav: Any, msg_id: int) -> bool:
        """pymavlink asks this for every message that is unsigned or failed the check."""
        reason, self._reason = self._reason or "unsigned", None
        if msg_id in self.accept_unsigned:
            self.stats.unsigned_allowed += 1
            return True
        name = mavlink.mavlink_map[msg_id].msgname if msg_id in mavlink.mavlink_map else f"MSG {msg_id}"
        self.stats.dropped[reason] = self.stats.dropped.get(reason, 0) + 1
        self.stats.dropped_types[name] = self.stats.dropped_types.get(name, 0) + 1
        self.last_drop = f"{name} ({reason})"
        return False
