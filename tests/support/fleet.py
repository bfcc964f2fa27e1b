"""What the fleet membership tests share: a member's announcement at the tests' origin, the
fleet's enrolment (every test vehicle's signing key and the roster, made once per test run in
a private temporary folder), members and signed positions made with it, and a wait on a
condition with a deadline (polled: zenoh calls back on its own threads)."""

from __future__ import annotations

import atexit
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Iterable

from planner_service.service.fleet.presence import FleetPresence, compact_position
from protocol import FleetKeys, Status, encode
from protocol.fleet_signing import FleetSigner, FleetVerifier, load_private_key, make_vehicle_key, read_roster
from protocol.messages import FleetMember

VEHICLES = tuple(f"uav{i}" for i in range(1, 10))
"""The vehicles enrolled for the tests (``ENROLMENT``); any other is a stranger."""


def member(vehicle: str, layer_m: float, gap_m: float = 10.0) -> FleetMember:
    return FleetMember(vehicle=vehicle, layer_m=layer_m, min_gap_m=gap_m, origin_lat_deg=47.397742,
                       origin_lon_deg=8.545594, origin_alt_m=488.0)


def enrol(folder: Path, vehicles: Iterable[str] = VEHICLES) -> Path:
    """Each vehicle's key ``folder/{vehicle}.key`` and the roster ``folder/roster``, as
    ``python -m planner_service fleet-key`` makes them; returns the roster's path."""
    folder.mkdir(parents=True, exist_ok=True)
    roster = folder / "roster"
    for vehicle in vehicles:
        make_vehicle_key(folder / f"{vehicle}.key", roster, vehicle)
    return roster


ENROLMENT = Path(tempfile.mkdtemp(prefix="fleet-keys-"))
"""The tests' keys and roster (``enrol``), removed at the end of the run."""
ROSTER = enrol(ENROLMENT)
atexit.register(shutil.rmtree, ENROLMENT, True)
_signers: dict[str, FleetSigner] = {}


def fleet_settings(roster: Path = ROSTER, vehicle: str = "uav1") -> dict[str, str]:
    """A service's ``[fleet]`` enrolment settings (``--set`` text) for ``vehicle``."""
    return {"fleet.key_file": str(roster.parent / f"{vehicle}.key"), "fleet.roster_file": str(roster)}


def signer(vehicle: str) -> FleetSigner:
    """``vehicle``'s signer (one per test run: its sequence numbers rise across the tests)."""
    if vehicle not in _signers:
        _signers[vehicle] = FleetSigner(vehicle, load_private_key(ENROLMENT / f"{vehicle}.key"))
    return _signers[vehicle]


def verifier() -> FleetVerifier:
    return FleetVerifier(read_roster(ROSTER))


def presence(keys: FleetKeys, own: FleetMember, **kw: Any) -> FleetPresence:
    """A member enrolled in the tests' fleet, signing as its vehicle, its own verifier."""
    return FleetPresence(keys, own, FleetSigner(own.vehicle, load_private_key(ENROLMENT / f"{own.vehicle}.key")),
                         verifier(), **kw)


def put_position(session: Any, keys: FleetKeys, status: Status) -> None:
    """``status``'s position put as its vehicle's, signed (as its service does with each status)."""
    key = keys.position(status.vehicle)
    session.put(key, signer(status.vehicle).seal(key, encode(compact_position(status)), time.time()))


def wait_until(check: Callable[[], bool], timeout_s: float, what: str | Callable[[], str]) -> None:
    """Until ``check()``, or fail naming ``what`` (a callable: said as it stands at the end)."""
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"not within {timeout_s} s: {what() if callable(what) else what}"
        time.sleep(0.02)
