"""MAVLink 2 signing: the key file, timestamps across restarts (an injected clock that goes
back), and the signature check on real packed bytes."""

from __future__ import annotations

import hashlib
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from protocol.errors import SigningError
from protocol.signing import (RESERVE_TICKS, SLOT_BYTES, Signer, TimestampStore, default_timestamp_path,
                              key_from_passphrase, load_key, read_reservation, timestamp_at, write_key)

REPO = Path(__file__).resolve().parents[2]
KEY = bytes(range(32))
T0 = 1_800_000_000.0
"""A wall-clock time (2027-01-15) for the injected clocks."""


def key_file(tmp_path: Path, text: str, mode: int = 0o600) -> Path:
    path = tmp_path / "key"
    path.write_text(text)
    path.chmod(mode)
    return path


# --- the key file ---------------------------------------------------------------------------------
def test_load_key_reads_64_hex_characters(tmp_path: Path) -> None:
    assert load_key(key_file(tmp_path, KEY.hex() + "\n")) == KEY
    assert load_key(key_file(tmp_path, KEY.hex().upper())) == KEY  # no newline, upper case


@pytest.mark.parametrize("mode", [0o644, 0o640, 0o604, 0o660, 0o602])
def test_load_key_refuses_a_key_others_can_read_or_write(tmp_path: Path, mode: int) -> None:
    path = key_file(tmp_path, KEY.hex(), mode)
    with pytest.raises(SigningError) as err:
        load_key(path)
    assert err.value.path == str(path) and str(path) in str(err.value)
    assert f"{mode:04o}" in err.value.message and "chmod 600" in err.value.message


@pytest.mark.parametrize("text, what", [
    (KEY.hex()[:-2], "64 hex characters"),
    (KEY.hex() + "00", "64 hex characters"),
    ("zz" + KEY.hex()[2:], "hex characters (0-9, a-f)"),
    (KEY.hex() + "\n\n", "64 hex characters"),
    ("", "64 hex characters"),
])
def test_load_key_refuses_malformed_keys(tmp_path: Path, text: str, what: str) -> None:
    path = key_file(tmp_path, text)
    with pytest.raises(SigningError, match=re.escape(what)) as err:
        load_key(path)
    assert err.value.path == str(path)


def test_load_key_names_a_missing_file_and_how_to_make_one(tmp_path: Path) -> None:
    with pytest.raises(SigningError) as err:
        load_key(tmp_path / "nope")
    assert err.value.path == str(tmp_path / "nope") and "keygen" in err.value.message


def test_write_key_is_0600_whatever_the_umask_and_never_overwrites(tmp_path: Path) -> None:
    old = os.umask(0)  # the most permissive umask: the mode must still be exactly 0600
    try:
        key = write_key(tmp_path / "k")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "k").stat().st_mode) == 0o600
    assert len(key) == 32 and load_key(tmp_path / "k") == key
    assert write_key(tmp_path / "k2") != key  # random
    with pytest.raises(SigningError, match="already exists"):
        write_key(tmp_path / "k", KEY)
    assert load_key(tmp_path / "k") == key


def test_keygen_command_writes_0600_and_passphrase_keys_match_mavproxy(tmp_path: Path, python_env) -> None:
    def keygen(*args: str, stdin: str = "") -> subprocess.CompletedProcess[str]:
        return subprocess.run([sys.executable, "-m", "planner_service", "keygen", *args], input=stdin, env=python_env,
                              cwd=REPO, capture_output=True, text=True, timeout=60)

    done = keygen(str(tmp_path / "random.key"))
    assert done.returncode == 0, done.stderr
    assert stat.S_IMODE((tmp_path / "random.key").stat().st_mode) == 0o600
    assert len(load_key(tmp_path / "random.key")) == 32
    again = keygen(str(tmp_path / "random.key"))
    assert again.returncode == 2 and "already exists" in again.stderr and "random.key" in again.stderr
    done = keygen("--passphrase", str(tmp_path / "pass.key"), stdin="abc\n")
    assert done.returncode == 0, done.stderr
    # SHA-256("abc"), the FIPS 180-2 test vector: the key MAVProxy's `signing setup abc` makes.
    assert load_key(tmp_path / "pass.key").hex() == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
    assert key_from_passphrase("abc") == hashlib.sha256(b"abc").digest()
    assert "--passphrase" in keygen("--help").stdout


# --- timestamps -------------------------------------------------------------------------------------
def test_timestamp_units() -> None:
    assert timestamp_at(1420070400.0) == 0  # 2015-01-01 UTC
    assert timestamp_at(1420070401.5) == 150_000  # 10 µs units
    assert timestamp_at(0.0) == 0  # a clock before 2015 never gives a negative timestamp


def test_a_restart_never_reuses_a_timestamp_even_when_the_clock_goes_back(tmp_path: Path) -> None:
    path = tmp_path / "ts"
    now = [T0]
    store = TimestampStore(path, clock=lambda: now[0])
    start = store.open()
    assert start == timestamp_at(T0)
    assert read_reservation(path) == start + RESERVE_TICKS  # reserved before anything is used
    used = start + 5000  # 5000 messages signed
    now[0] += 10.0
    current = store.advance(used)
    assert current == timestamp_at(T0 + 10.0)  # raised to the clock
    store.close(current + 7)

    now[0] = T0 - 3600.0  # the clock went back an hour
    again = TimestampStore(path, clock=lambda: now[0])
    assert again.open() == current + 8
    again.close(current + 8)

    now[0] = T0 + 86400.0  # and forward a day: the clock wins
    later = TimestampStore(path, clock=lambda: now[0])
    assert later.open() == timestamp_at(T0 + 86400.0)
    later.close(timestamp_at(T0 + 86400.0))


def test_the_reservation_covers_a_crash(tmp_path: Path, python_env) -> None:
    """A process killed without ``close`` used timestamps up to its reservation at most; the
    next start is above it, even with the clock an hour back."""
    path = tmp_path / "ts"
    child = (f"import os; from protocol.signing import TimestampStore\n"
             f"s = TimestampStore({str(path)!r}, clock=lambda: {T0})\n"
             f"start = s.open(); print(start, s.advance(start + 1000), flush=True)\n"
             f"os._exit(0)  # no close: a crash\n")
    out = subprocess.run([sys.executable, "-c", child], env=python_env, cwd=REPO, capture_output=True, text=True,
                         timeout=60, check=True).stdout.split()
    start, used = int(out[0]), int(out[1])
    restarted = TimestampStore(path, clock=lambda: T0 - 3600.0)
    begin = restarted.open()
    assert begin > used and begin == start + RESERVE_TICKS + 1
    assert begin - timestamp_at(T0) <= RESERVE_TICKS + 1  # at most the reservation ahead of the old clock
    restarted.close(begin)


def test_the_reservation_moves_ahead_before_it_is_reached(tmp_path: Path) -> None:
    now = [T0]
    store = TimestampStore(tmp_path / "ts", clock=lambda: now[0])
    start = store.open()
    for step in range(1, 200):
        now[0] = T0 + step  # one second per tick, 200 s in all
        current = store.advance(start)
        assert store.reserved >= current + RESERVE_TICKS // 2  # always half a reservation of margin
        assert read_reservation(tmp_path / "ts") == store.reserved
    store.close(current)


def test_one_timestamp_file_per_process(tmp_path: Path) -> None:
    first = TimestampStore(tmp_path / "ts")
    first.open()
    with pytest.raises(SigningError, match=f"in use by pid {os.getpid()}"):
        TimestampStore(tmp_path / "ts").open()
    first.close(timestamp_at(T0))
    second = TimestampStore(tmp_path / "ts")  # free again once closed
    second.close(second.open())
    assert default_timestamp_path("/etc/k.key", "service") == Path("/etc/k.key.service-timestamp")
    assert default_timestamp_path("k", "vehicle") != default_timestamp_path("k", "service")


def test_the_lock_is_the_kernels_on_the_file_itself(tmp_path: Path, python_env) -> None:
    """Another process holds the file: a second is refused in one line naming the file and
    the holder, whatever side files are deleted (the lock was a ``ts.lock`` beside the file:
    deleting it let a second process in, both signing with the same timestamps); killed, the
    holder leaves nothing stale, and the next start is above what it reserved."""
    path = tmp_path / "ts"
    child = (f"import sys; from protocol.signing import TimestampStore\n"
             f"s = TimestampStore({str(path)!r}, clock=lambda: {T0})\n"
             f"print(s.open(), s.reserved, flush=True); sys.stdin.read()\n")
    holder = subprocess.Popen([sys.executable, "-c", child], env=python_env, cwd=REPO, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None
        start, reserved = map(int, holder.stdout.readline().split())
        for side in tmp_path.iterdir():
            if side != path:
                side.unlink()  # a ts.lock, a ts.tmp: whatever stands beside the file
        with pytest.raises(SigningError) as err:
            TimestampStore(path, clock=lambda: T0).open()
        assert str(err.value) == (f"{path}: is in use by pid {holder.pid}: each process signing with a key needs "
                                  f"its own timestamp file")
        assert "\n" not in str(err.value)
    finally:
        holder.kill()  # SIGKILL: no close, no unlock but the kernel's
        holder.wait(10)
    after = TimestampStore(path, clock=lambda: T0 - 60.0)
    begin = after.open()
    assert begin == reserved + 1 > start
    after.close(begin)


def test_a_store_removed_under_its_holder_says_so(tmp_path: Path) -> None:
    """Removing the file itself lets another process create a new one; the holder notices
    at its next write (it cannot keep its reservation there any more) and says so."""
    now = [T0]
    store = TimestampStore(tmp_path / "ts", clock=lambda: now[0])
    start = store.open()
    (tmp_path / "ts").unlink()
    other = TimestampStore(tmp_path / "ts", clock=lambda: now[0])
    other.close(other.open())
    now[0] += RESERVE_TICKS / 100_000
    with pytest.raises(SigningError, match="was removed or replaced while this process used it"):
        store.advance(start)


def test_a_write_cut_by_a_crash_leaves_the_reservation_before_it(tmp_path: Path) -> None:
    """The two slots: a crash in the middle of a write spoils only the slot being written,
    whose value was not in use yet; the other still holds the reservation before it."""
    path = tmp_path / "ts"
    now = [T0]
    store = TimestampStore(path, clock=lambda: now[0])
    start = store.open()
    first = store.reserved
    now[0] += 20.0
    store.advance(start)
    second = store.reserved
    assert second > first and read_reservation(path) == second
    store._unlock()  # the process dies with the lock released by the kernel
    raw = bytearray(path.read_bytes())
    slot = raw.index(f"{second:015d}".encode())  # the slot written last
    raw[slot + 3:slot + 9] = b"999999"  # the new value half written: its checksum fails
    path.write_bytes(bytes(raw))
    assert read_reservation(path) == first
    again = TimestampStore(path, clock=lambda: T0)
    assert again.open() == first + 1
    again.close(first + 1)
    assert len(path.read_bytes()) == 2 * SLOT_BYTES


def test_a_timestamp_file_of_the_older_layout_is_read(tmp_path: Path) -> None:
    path = tmp_path / "ts"
    path.write_text(f"{timestamp_at(T0 + 100.0)}\n")  # one bare number, as written before the slots
    store = TimestampStore(path, clock=lambda: T0)
    assert store.open() == timestamp_at(T0 + 100.0) + 1
    store.close(timestamp_at(T0 + 100.0) + 1)
    assert read_reservation(path) == timestamp_at(T0 + 100.0) + 1


def test_a_malformed_timestamp_file_is_refused_by_name(tmp_path: Path) -> None:
    (tmp_path / "ts").write_text("yesterday\n")
    with pytest.raises(SigningError) as err:
        TimestampStore(tmp_path / "ts").open()
    assert err.value.path == str(tmp_path / "ts") and "not a signing timestamp" in err.value.message
    TimestampStore(tmp_path / "ts2").open()  # the failed one released its lock: unrelated files still open


# --- signing real bytes -----------------------------------------------------------------------------
def sender(signer: Signer | None, system: int = 255, component: int = 190) -> M.MAVLink:
    mav = M.MAVLink(None, srcSystem=system, srcComponent=component)
    if signer is not None:
        signer.attach(mav)
    return mav


def arm_bytes(mav: M.MAVLink) -> bytes:
    return M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0).pack(mav)


def receive(receiver: M.MAVLink, data: bytes) -> list[str]:
    return [m.get_type() for m in receiver.parse_buffer(data) or []]


def test_signed_accepted_unsigned_wrong_key_and_replays_dropped() -> None:
    vehicle = Signer(KEY, clock=lambda: T0)
    rx = sender(vehicle, 1, 1)
    rx.robust_parsing = True
    good = sender(Signer(KEY, clock=lambda: T0))
    packet = arm_bytes(good)
    assert packet[2] & M.MAVLINK_IFLAG_SIGNED  # incompat_flags: a 13-byte signature follows
    assert receive(rx, packet) == ["COMMAND_LONG"]
    assert receive(rx, packet) == ["BAD_DATA"]  # the same bytes again: a replay
    assert receive(rx, arm_bytes(sender(None))) == ["BAD_DATA"]  # unsigned
    assert receive(rx, arm_bytes(sender(Signer(bytes(32), clock=lambda: T0)))) == ["BAD_DATA"]  # another key
    radio = M.MAVLink_radio_status_message(200, 190, 100, 20, 10, 0, 0).pack(sender(None))
    assert receive(rx, radio) == ["RADIO_STATUS"]  # the one unsigned message a vehicle takes
    assert receive(rx, arm_bytes(good)) == ["COMMAND_LONG"]  # the real sender carries on
    s = vehicle.stats
    assert (s.accepted, s.unsigned_allowed) == (2, 1)
    assert s.dropped == {"replayed": 1, "unsigned": 1, "bad signature": 1}
    assert s.dropped_types == {"COMMAND_LONG": 3}
    assert vehicle.last_drop == "COMMAND_LONG (bad signature)"


def test_each_drop_says_what_it_is() -> None:
    """A replay is a replay (not a key problem), a bad signature in the name of a sender
    whose signed messages pass is a forgery, one from a sender never heard points to the key."""
    now = [T0]
    vehicle = Signer(KEY, clock=lambda: now[0])
    rx = sender(vehicle, 1, 1)
    rx.robust_parsing = True
    good = sender(Signer(KEY, clock=lambda: T0), 255, 190)
    packet = arm_bytes(good)
    receive(rx, packet)
    later = arm_bytes(good)  # 1 tick later on the same stream
    receive(rx, later)
    receive(rx, packet)  # captured bytes sent again
    replay = vehicle.last_drops["replayed"]
    assert (replay.stream, replay.reference - replay.timestamp) == ((0, 255, 190), 1)
    assert replay.describe() == ("COMMAND_LONG from system 255 component 190 (link id 0): its timestamp is 0.00 s "
                                 "behind the last one heard on that stream: a replay of captured packets (not a key "
                                 "problem)")
    receive(rx, arm_bytes(sender(Signer(bytes(32), clock=lambda: T0), 255, 190)))
    assert "forged" in vehicle.last_drops["bad signature"].describe()
    now[0] += 11.0  # that sender not heard for longer than HEARD_S
    receive(rx, arm_bytes(sender(Signer(bytes(32), clock=lambda: T0), 255, 190)))
    assert vehicle.last_drops["bad signature"].describe().endswith("the sender signs with another key (or it is forged)")
    receive(rx, arm_bytes(sender(Signer(KEY, link_id=4, clock=lambda: T0 - 120.0))))
    assert "opens a stream 120 s behind our timestamp" in vehicle.last_drops["stale stream"].describe()
    receive(rx, arm_bytes(sender(None)))
    assert vehicle.last_drops["unsigned"].describe() == "COMMAND_LONG unsigned: the sender does not sign"
    assert vehicle.stats.dropped == {"replayed": 1, "bad signature": 2, "stale stream": 1, "unsigned": 1}


def test_a_forged_future_timestamp_does_not_lock_the_real_sender_out() -> None:
    """pymavlink's own check records a stream's timestamp before verifying the signature;
    a forger with a wrong key and a far-future timestamp would make every later real packet
    'old'. The check here verifies first."""
    rx = sender(Signer(KEY, clock=lambda: T0), 1, 1)
    rx.robust_parsing = True
    forger = Signer(bytes(32), clock=lambda: T0)
    forger.state.timestamp = (1 << 48) - 10
    assert receive(rx, arm_bytes(sender(forger))) == ["BAD_DATA"]
    assert receive(rx, arm_bytes(sender(Signer(KEY, clock=lambda: T0)))) == ["COMMAND_LONG"]


def test_a_stream_is_per_link_system_component_and_a_new_one_must_be_recent() -> None:
    vehicle = Signer(KEY, clock=lambda: T0)
    rx = sender(vehicle, 1, 1)
    rx.robust_parsing = True
    a = Signer(KEY, clock=lambda: T0)
    b = Signer(KEY, link_id=1, clock=lambda: T0 - 30.0)  # another link, its clock 30 s behind: accepted
    assert receive(rx, arm_bytes(sender(a))) == ["COMMAND_LONG"]
    assert receive(rx, arm_bytes(sender(b))) == ["COMMAND_LONG"]
    old = Signer(KEY, link_id=2, clock=lambda: T0 - 61.0)  # a new stream over a minute old: refused
    assert receive(rx, arm_bytes(sender(old))) == ["BAD_DATA"]
    assert vehicle.stats.dropped == {"stale stream": 1}


def test_a_restarted_sender_is_heard_only_with_its_stored_timestamp(tmp_path: Path) -> None:
    """Real bytes across a sender's restart with the clock an hour back: with the timestamp
    file its packets are still new to the vehicle; from the clock alone they are replays."""
    rx = sender(Signer(KEY, clock=lambda: T0), 1, 1)
    rx.robust_parsing = True
    first = Signer(KEY, TimestampStore(tmp_path / "ts", clock=lambda: T0))
    tx = sender(first)
    assert [receive(rx, arm_bytes(tx)) for _ in range(3)] == [["COMMAND_LONG"]] * 3
    first.close()

    restarted = Signer(KEY, TimestampStore(tmp_path / "ts", clock=lambda: T0 - 3600.0))
    assert receive(rx, arm_bytes(sender(restarted))) == ["COMMAND_LONG"]
    restarted.close()
    clock_only = Signer(KEY, clock=lambda: T0 - 3600.0)
    assert receive(rx, arm_bytes(sender(clock_only))) == ["BAD_DATA"]


def test_tick_follows_the_clock_and_the_highest_timestamp_heard(tmp_path: Path) -> None:
    now = [T0]
    me = Signer(KEY, TimestampStore(tmp_path / "ts", clock=lambda: now[0]))
    rx = sender(me, 1, 1)
    ahead = Signer(KEY, clock=lambda: T0 + 20.0)  # a peer 20 s ahead
    receive(rx, arm_bytes(sender(ahead)))
    assert me.timestamp == timestamp_at(T0)  # the reader never writes our timestamp
    me.tick()
    assert me.timestamp == timestamp_at(T0 + 20.0)  # spec: raised to a correctly signed message's timestamp
    now[0] = T0 + 100.0
    me.tick()
    assert me.timestamp == timestamp_at(T0 + 100.0)
    me.close()
    assert read_reservation(tmp_path / "ts") == timestamp_at(T0 + 100.0)
