"""The fleet's signatures (``protocol.fleet_signing``) on their own, in milliseconds: the key
files and the roster, a message signed by one vehicle read only as that vehicle's on that
key, and the replay rule (fresh, never twice, never older than the last on its key)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from protocol.errors import SigningError
from protocol.fleet_signing import (CLOCK_WINDOW_S, FUTURE_S, FleetSigner, FleetVerifier, Unverified, load_private_key,
                                    make_vehicle_key, read_roster)

KEY = "pfx/fleet/served/uav1"


@pytest.fixture
def fleet(tmp_path: Path) -> tuple[FleetSigner, FleetVerifier, Path]:
    roster = tmp_path / "roster"
    for v in ("uav1", "uav2"):
        make_vehicle_key(tmp_path / f"{v}.key", roster, v)
    return FleetSigner("uav1", load_private_key(tmp_path / "uav1.key")), FleetVerifier(read_roster(roster)), tmp_path


def test_a_message_reads_back_only_as_its_vehicles_on_its_key(fleet: tuple[FleetSigner, FleetVerifier, Path]) -> None:
    signer, verifier, folder = fleet
    sealed = signer.seal(KEY, b'{"x": 1}', 1000.0)
    assert verifier.open(KEY, "uav1", sealed, 1000.5, 60.0, latest_wins=False) == (b'{"x": 1}', 1000.0)
    for key, vehicle, why in (("pfx/fleet/served/uav2", "uav2", "signed as 'uav1'"),
                              ("pfx/fleet/intentions/uav1", "uav1", "bad signature")):
        with pytest.raises(Unverified) as err:
            verifier.open(key, vehicle, signer.seal(KEY, b"{}", 1000.0), 1000.0, 60.0)
        assert why in err.value.why
    thief = FleetSigner("uav1", load_private_key(folder / "uav2.key"))  # uav2's key speaking as uav1
    with pytest.raises(Unverified, match="bad signature"):
        verifier.open(KEY, "uav1", thief.seal(KEY, b"{}", 1000.0), 1000.0, 60.0)
    with pytest.raises(Unverified, match="not enrolled"):
        verifier.open("pfx/fleet/served/ghost", "ghost", b"{}", 1000.0, 60.0)
    with pytest.raises(Unverified, match="not a signed fleet message"):
        verifier.open(KEY, "uav1", b'{"kind": "fleet_served"}', 1000.0, 60.0)
    tampered = sealed.replace(b'{\\"x\\": 1}', b'{\\"x\\": 2}')
    assert tampered != sealed
    with pytest.raises(Unverified, match="bad signature"):
        verifier.open(KEY, "uav1", tampered, 1000.0, 60.0)
    assert verifier.ignored == 6


def test_the_replay_rule(fleet: tuple[FleetSigner, FleetVerifier, Path]) -> None:
    signer, verifier, _ = fleet
    first, second = signer.seal(KEY, b"{}", 1000.0), signer.seal(KEY, b"{}", 1001.0)
    verifier.open(KEY, "uav1", second, 1001.0, 60.0)
    with pytest.raises(Unverified, match="replayed"):  # the same message again
        verifier.open(KEY, "uav1", second, 1001.0, 60.0)
    with pytest.raises(Unverified, match="older than the last"):  # latest wins: an older one is a replay
        verifier.open(KEY, "uav1", first, 1001.0, 60.0)
    verifier.open(KEY, "uav1", first, 1001.0, 60.0, latest_wins=False)  # an event stream takes it, once
    with pytest.raises(Unverified, match="stale"):
        verifier.open(KEY, "uav1", signer.seal(KEY, b"{}", 900.0), 1001.0, 60.0)
    with pytest.raises(Unverified, match="future"):
        verifier.open(KEY, "uav1", signer.seal(KEY, b"{}", 1001.0 + FUTURE_S + 1), 1001.0, 60.0)
    reboot = FleetSigner("uav1", signer._key)  # a restarted service: a new boot, its seq from 1 again
    verifier.open(KEY, "uav1", reboot.seal(KEY, b"{}", 1002.0), 1002.0, 60.0)


def test_key_files_and_the_roster(tmp_path: Path) -> None:
    roster = tmp_path / "roster"
    line = make_vehicle_key(tmp_path / "a.key", roster, "uav1")
    assert line.startswith("uav1 ") and os.stat(tmp_path / "a.key").st_mode & 0o777 == 0o600
    with pytest.raises(SigningError, match="already enrolled"):
        make_vehicle_key(tmp_path / "b.key", roster, "uav1")
    with pytest.raises(SigningError, match="already exists"):
        make_vehicle_key(tmp_path / "a.key", roster, "uav2")
    with pytest.raises(SigningError, match="not a vehicle id"):
        make_vehicle_key(tmp_path / "c.key", roster, "uav/2")
    os.chmod(tmp_path / "a.key", 0o640)
    with pytest.raises(SigningError, match="too open"):
        load_private_key(tmp_path / "a.key")
    bad = tmp_path / "bad"
    bad.write_text("# the fleet\nuav1 zz\n")
    with pytest.raises(SigningError, match="bad:2"):
        read_roster(bad)
    twice = tmp_path / "twice"
    twice.write_text(roster.read_text() * 2)
    with pytest.raises(SigningError, match="enrolled twice"):
        read_roster(twice)
    with pytest.raises(SigningError, match="no such fleet roster"):
        read_roster(tmp_path / "none")


def test_a_reader_without_the_roster_may_peek_but_nothing_else_passes(
        fleet: tuple[FleetSigner, FleetVerifier, Path]) -> None:
    """``unverified_body`` (a simulated user counting its backlog down) unwraps an envelope;
    a plain message is no envelope."""
    from protocol.fleet_signing import unverified_body

    signer, _, _ = fleet
    assert unverified_body(signer.seal(KEY, b'{"x": 1}', 1.0)) == b'{"x": 1}'
    with pytest.raises(Unverified):
        unverified_body(b'{"kind": "fleet_served"}')


def test_a_members_clock_offset_is_read_from_what_its_key_signed(fleet: tuple[FleetSigner, FleetVerifier, Path]) -> None:
    """The freshest message signed within the window tells how far ahead a member's clock
    reads, refused or not for its time; an old one replayed cannot raise it, a forged one
    (not its key) says nothing."""
    signer, verifier, folder = fleet
    assert verifier.clock_offset("uav1", 1000.0) is None
    with pytest.raises(Unverified, match="future"):  # 7 s ahead: refused, and measured
        verifier.open(KEY, "uav1", signer.seal(KEY, b"{}", 1007.0), 1000.0, 60.0)
    assert verifier.clock_offset("uav1", 1000.0) == pytest.approx(7.0)
    with pytest.raises(Unverified, match="stale"):
        verifier.open(KEY, "uav1", signer.seal(KEY, b"{}", 900.0), 1001.0, 60.0)
    assert verifier.clock_offset("uav1", 1001.0) == pytest.approx(7.0)  # the freshest tells
    thief = FleetSigner("uav1", load_private_key(folder / "uav2.key"))
    with pytest.raises(Unverified, match="bad signature"):
        verifier.open(KEY, "uav1", thief.seal(KEY, b"{}", 1100.0), 1001.0, 60.0)
    assert verifier.clock_offset("uav1", 1001.0) == pytest.approx(7.0)
    assert verifier.clock_offset("uav1", 1000.0 + CLOCK_WINDOW_S + 1) is None  # heard too long ago
    verifier.open(KEY, "uav1", signer.seal(KEY, b"{}", 1019.0), 1020.0, 60.0)
    assert verifier.clock_offset("uav1", 1020.0) == pytest.approx(-1.0)
