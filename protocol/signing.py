"""MAVLink 2 message signing: the shared key on disk, timestamps that never repeat across
restarts, and a signature check that follows the specification.

The key is 32 secret bytes kept as 64 hex characters in a file only its owner may read
(refused otherwise, or if another user owns it, as ssh refuses such a private key). ``write_key`` makes one.

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

import hashlib
import hmac
import math
import os
import secrets
import stat
import time
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

from pymavlink.dialects.v20 import common as mavlink

from .errors import SigningError
from .file_lock import lock_or_holder, names

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
    ``SigningError`` naming the file if it is missing, malformed, open to group or others,
    or owned by another user than this process's."""
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
        if info.st_uid != os.geteuid():
            # a key someone else owns may have been planted beside the journal (root reads any
            # file): ssh refuses such a private key too
            raise SigningError(name, f"is owned by uid {info.st_uid}, not by this process's user (uid "
                                     f"{os.geteuid()}): a key must belong to whoever uses it (chown it, or make "
                                     f"a new one)")
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

    The file holds a timestamp this process will not exceed before it stores a higher one
    (``close`` stores the last one used), in two slots of one line each, ``<15 digits>
    <count of writes, 8 hex> <CRC-32, 8 hex>``, written in turn in place: a write cut by a
    crash spoils at most the slot being written, whose value was not yet relied on, and the
    other slot still holds the value before it. The valid slot written last counts. (A file of one bare decimal number, from before the slots, is read
    as that number; an empty file, created and never written, as none.)

    One process per file: an exclusive ``flock`` on the file itself, held from ``open`` to
    ``close``, as the journal holds its own. No other file stands for the lock, so none can
    be deleted to get round it, and the kernel drops it when its process dies (a killed
    holder leaves nothing stale). This is why the slots are written in place: a file
    replaced by a rename would be a new file, unlocked.
    """

    def __init__(self, path: str | os.PathLike[str], clock: Callable[[], float] = time.time,
                 reserve_ticks: int = RESERVE_TICKS) -> None:
        self.path = Path(path)
        self.clock = clock
        self.reserve_ticks = reserve_ticks
        self.reserved = 0
        self._lock_fd: int | None = None
        self._slot = 0
        """The slot the next write goes to: never the one holding the reservation in force."""
        self._count = 0
        """Writes so far (kept in the file): the valid slot written last is the one in force."""

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
        """Open (creating it if need be) and lock the file; ``SigningError`` naming it, and the
        holder's pid where ``/proc/locks`` shows it, if another process has it. Another
        process may remove or replace the file between our open and our lock: then the lock
        is on a file the path no longer leads to, and we look again."""
        name = str(self.path)
        for _ in range(LOCK_TRIES):
            try:
                fd = os.open(name, os.O_RDWR | os.O_CREAT | os.O_NOCTTY, 0o600)
            except OSError as err:
                raise SigningError(name, f"cannot open the timestamp file: {err.strerror or err}") from None
            try:
                who = lock_or_holder(fd)
            except OSError as err:
                raise SigningError(name, f"cannot lock the timestamp file: {err.strerror or err}") from None
            if who is not None:
                raise SigningError(name, f"is in use by {who}: each process signing with a key needs its own "
                                         "timestamp file")
            if names(name, fd):
                self._lock_fd = fd
                return
            os.close(fd)
        raise SigningError(name, f"kept being removed or replaced while this process tried to lock it "
                                 f"({LOCK_TRIES} tries); is another program using it?")

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing releases the flock
            self._lock_fd = None

    def _held(self) -> int:
        if self._lock_fd is None:
            raise SigningError(str(self.path), "the timestamp file is not open (open() it first)")
        return self._lock_fd

    def _read(self) -> int:
        try:
            raw = os.pread(self._held(), 4 * SLOT_BYTES, 0)
        except OSError as err:
            raise SigningError(str(self.path), f"cannot read the timestamp file: {err.strerror or err}") from None
        value, count, slot = _parse_slots(raw)
        if value is None:
            shown = raw[:40].decode("ascii", errors="replace")
            raise SigningError(str(self.path), f"holds {shown!r}, not a signing timestamp; delete it only if this "
                                               "machine's clock is right (a stale timestamp gets our messages "
                                               "ignored as replays)")
        self._slot = 1 - slot if slot is not None else 0
        self._count = count
        self.reserved = value
        return value

    def _store(self, value: int) -> None:
        """Write ``value`` into the slot not in force, and sync it: only then is it in force."""
        fd = self._held()
        if not names(str(self.path), fd):
            raise SigningError(str(self.path), "was removed or replaced while this process used it: its "
                                               "reservation can no longer be kept there (restart the process)")
        try:
            if os.fstat(fd).st_size != 2 * SLOT_BYTES:
                # a new file, or the bare number of an older version: the reservation in force
                # into slot 0 (read before, 0 for a new file), the new one into slot 1
                os.pwrite(fd, _slot_line(self.reserved, self._count) + _slot_line(value, self._count + 1), 0)
                os.ftruncate(fd, 2 * SLOT_BYTES)
                self._slot = 0
            else:
                os.pwrite(fd, _slot_line(value, self._count + 1), self._slot * SLOT_BYTES)
                self._slot = 1 - self._slot
            self._count += 1
            os.fsync(fd)
        except OSError as err:
            raise SigningError(str(self.path), f"cannot write the timestamp file: {err.strerror or err}") from None
        self.reserved = value


def read_reservation(path: str | os.PathLike[str]) -> int | None:
    """The reservation a timestamp file holds (None if it holds none), read without its lock:
    for tools and tests, never for a process about to sign."""
    with open(path, "rb") as handle:
        return _parse_slots(handle.read(4 * SLOT_BYTES))[0]


SLOT_DIGITS = 15
"""Digits of a slot's timestamp: enough for any 48-bit value (2**48 has 15)."""
SLOT_BYTES = SLOT_DIGITS + 1 + 8 + 1 + 8 + 1
"""One slot: the timestamp, a space, the write's count (8 hex), a space, the CRC-32 of what
comes before it (8 hex), a newline."""
LOCK_TRIES = 5
"""Looks at the timestamp file's path before giving up, when each finds it removed or
replaced by another process between our open and our lock."""


def _slot_line(value: int, count: int) -> bytes:
    body = f"{value:0{SLOT_DIGITS}d} {count & 0xFFFFFFFF:08x}".encode("ascii")
    return body + f" {zlib.crc32(body):08x}\n".encode("ascii")


def _parse_slots(raw: bytes) -> tuple[int | None, int, int | None]:
    """(reservation, its write count, slot holding it) of a file's bytes: the valid slot
    written last. (0, 0, None) for an empty file; the bare number of the older layout with
    slot None; reservation None if the file holds no timestamp."""
    if not raw:
        return 0, 0, None
    text = raw.decode("ascii", errors="replace")
    bare = text[:-1] if text.endswith("\n") else text
    if len(raw) != 2 * SLOT_BYTES:
        return (int(bare), 0, None) if bare.isdigit() and int(bare) <= MAX_TIMESTAMP else (None, 0, None)
    best: tuple[int | None, int, int | None] = (None, 0, None)
    for slot in (0, 1):
        line = raw[slot * SLOT_BYTES:(slot + 1) * SLOT_BYTES]
        body, crc = line[:SLOT_DIGITS + 9], line[SLOT_DIGITS + 10:SLOT_BYTES - 1]
        digits, count = body[:SLOT_DIGITS], body[SLOT_DIGITS + 1:]
        if (not line.endswith(b"\n") or crc != f"{zlib.crc32(body):08x}".encode("ascii") or not digits.isdigit()
                or int(digits) > MAX_TIMESTAMP):
            continue  # a slot a crash cut short: the other one holds the reservation
        if best[0] is None or int(count, 16) > best[1]:
            best = (int(digits), int(count, 16), slot)
    return best


# --- signing pymavlink objects ------------------------------------------------------------------
HEARD_S = 10.0
"""A sender whose correctly signed messages passed within this many seconds is being heard:
a packet in its name that fails the signature is then not its own."""
DROP_REASONS = ("bad signature", "replayed", "stale stream", "unsigned")


@dataclass(frozen=True)
class Drop:
    """One message the signature check dropped, and why, as far as its bytes tell."""

    reason: str
    """One of ``DROP_REASONS``."""
    message: str
    stream: tuple[int, int, int] | None = None
    """(link id, system, component) a signed packet names; None unsigned."""
    timestamp: int = 0
    """The packet's signing timestamp (signed packets)."""
    reference: int = 0
    """replayed: the stream's last timestamp; stale stream: ours."""
    sender_heard: bool = False
    """bad signature: correctly signed messages of that system and component passed lately."""

    def describe(self) -> str:
        """The packet and what its drop means, in words: a replay is not a key problem."""
        if self.stream is None:
            return f"{self.message} unsigned: the sender does not sign"
        link, system, component = self.stream
        who = f"{self.message} from system {system} component {component} (link id {link})"
        if self.reason == "replayed":
            behind = (self.reference - self.timestamp) / TICKS_PER_S
            return (f"{who}: its timestamp is {behind:.2f} s behind the last one heard on that stream: "
                    f"a replay of captured packets (not a key problem)")
        if self.reason == "stale stream":
            behind = (self.reference - self.timestamp) / TICKS_PER_S
            return (f"{who} opens a stream {behind:.0f} s behind our timestamp (more than "
                    f"{NEW_STREAM_WINDOW // TICKS_PER_S} s allowed): old packets replayed, or a sender whose "
                    f"clock is behind and who keeps no timestamp file (not a key problem)")
        if self.sender_heard:
            return (f"{who}: the signature does not match our key while that sender's correctly signed "
                    f"messages pass: forged, or another station with another key using its ids")
        return f"{who}: the signature does not match our key: the sender signs with another key (or it is forged)"


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
        self.last_drops: dict[str, Drop] = {}
        """The latest drop of each reason."""
        self._failed: Drop | None = None
        """What ``check_signature`` found wrong with the packet pymavlink asks about next."""
        self._good_at: dict[tuple[int, int], float] = {}
        """(system, component) -> when a correctly signed message of it last passed."""
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
        link_id = buf[-SIGNATURE_LEN]
        timestamp = int.from_bytes(buf[-12:-6], "little")
        stream = (link_id, src_system, src_component)
        digest = hashlib.sha256(self.state.secret_key + buf[:-6]).digest()[:6]
        if not hmac.compare_digest(digest, buf[-6:]):
            heard = self.clock() - self._good_at.get((src_system, src_component), -math.inf) <= HEARD_S
            self._failed = Drop("bad signature", "", stream, timestamp, sender_heard=heard)
            return False
        last = self.state.stream_timestamps.get(stream)
        if last is None and timestamp + NEW_STREAM_WINDOW < self.state.timestamp:
            self._failed = Drop("stale stream", "", stream, timestamp, int(self.state.timestamp))
            return False
        if last is not None and timestamp <= last:
            self._failed = Drop("replayed", "", stream, timestamp, last)
            return False
        self.state.stream_timestamps[stream] = timestamp
        self._highest_heard = max(self._highest_heard, timestamp)
        self._good_at[(src_system, src_component)] = self.clock()
        self.stats.accepted += 1
        return True

    def _allow_unsigned(self, mav: Any, msg_id: int) -> bool:
        """pymavlink asks this for every message that is unsigned or failed the check."""
        failed, self._failed = self._failed, None
        if msg_id in self.accept_unsigned:
            self.stats.unsigned_allowed += 1
            return True
        name = mavlink.mavlink_map[msg_id].msgname if msg_id in mavlink.mavlink_map else f"MSG {msg_id}"
        drop = replace(failed, message=name) if failed is not None else Drop("unsigned", name)
        self.last_drops[drop.reason] = drop  # before the count: a reader of the count finds it
        self.stats.dropped[drop.reason] = self.stats.dropped.get(drop.reason, 0) + 1
        self.stats.dropped_types[name] = self.stats.dropped_types.get(name, 0) + 1
        self.last_drop = f"{name} ({drop.reason})"
        return False
