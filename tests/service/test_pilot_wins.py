"""The pilot always wins, with real processes on loopback: mid-sortie a pilot on a second
ground station switches the vehicle to LOITER. The service's authority ends at once (an
``authority_revoked`` event naming the mode, status ``revoked``), and from then on it
commands no mode and no arming while the users go on asking; the pilot lands; the battery
is swapped, the next sortie begins without authority, and the vehicle is never armed again. The vehicle's own log
is the judge (its mode changes and arming, its track against the services recorded); the
same test on ArduCopter SITL is in ``test_sortie_sitl.py``."""

from __future__ import annotations

import re
import time
from contextlib import contextmanager
from dataclasses import replace
from typing import Callable, Iterator

import pytest

from planner_service.harness.processes import Child
from planner_service.service.config import load_config
from protocol import Event, GeoOrigin, HoverPoint, MissionItem, encode_path
from tests.support.gcs import M, GroundStation
from tests.support.sortie_checks import HOLD_RADIUS_M, TOLERANCE_S
from tests.support.stack import Stack
from tests.support.truth import false_services, recorded_services, stub_track

SPEEDUP = "25"
LOITER, LAND = 5, 9
"""ArduCopter's custom modes (the stub's ArduPilot flavour)."""
MODE = re.compile(r"\bmode (\w+)")
"""The stub's mode: logged on each change and after each command it accepts."""
COMMAND = re.compile(r"command (\d+) (?:accepted|refused)")
ARMED = re.compile(r"(?<!dis)armed at t=")


def flight_commands(text: str) -> list[str]:
    """The commands the stub took, but the telemetry requests a link sends on every
    connection (SET_MESSAGE_INTERVAL 511, REQUEST_MESSAGE 512)."""
    return [c for c in COMMAND.findall(text) if c not in ("511", "512")]


def flying(stack: Stack, *vehicle: str, **service: str) -> tuple[Child, Child]:
    """The stub (a fresh battery 30 s after landing), the service under the configuration's
    authority and ten users, until a first service: the vehicle and the service."""
    stub = stack.vehicle("--speedup", SPEEDUP, "--recharge-s", "30", *vehicle)
    child = stack.service(**{"mavlink__start_mission": "true", "planner__min_requests": "5", **service})
    stack.users("--count", "10", "--speedup", SPEEDUP, "--seed", "1")
    stack.wait_event(lambda e: e.event == "user_served", 90.0, "a first service")
    return stub, child


@contextmanager
def second_station(stack: Stack) -> Iterator[GroundStation]:
    """A pilot's ground station beside the service's link, once it hears the vehicle."""
    gcs = GroundStation(f"udpout:127.0.0.1:{stack.mav_port}")
    try:
        gcs.wait_vehicle()
        yield gcs
    finally:
        gcs.close()


def their_mission_ends_the_authority(stack: Stack,
                                     theirs_of: Callable[[GroundStation], list[MissionItem]]) -> list[MissionItem]:
    """A second station uploads its own mission (``theirs_of`` makes it, and may read ours
    first), the vehicle accepts it, and the service ends its authority within 20 s, finding
    the mission not its own: their mission."""
    with second_station(stack) as gcs:
        theirs = theirs_of(gcs)
        uploaded_at = time.time()
        assert gcs.upload(theirs) == M.MAV_MISSION_ACCEPTED
    revoked: Event = stack.wait_event(lambda e: e.event == "authority_revoked" and e.time_s >= uploaded_at, 20.0,
                                      "the end of the authority")
    assert "not ours" in revoked.detail and f"{len(theirs)} items" in revoked.detail, revoked.detail
    return theirs


def the_next_sortie_waits(stack: Stack) -> None:
    """Wait for the next sortie (once the battery is swapped), then three seconds in which
    the users go on asking: the vehicle's log after that shows any arming or command."""
    deadline = time.monotonic() + 20.0
    while not stack.rows("SELECT number FROM sorties WHERE number = 2"):
        assert time.monotonic() < deadline, "the next sortie never began"
        time.sleep(0.1)
    time.sleep(3.0)


@pytest.mark.timeout(180)
@pytest.mark.parametrize("backend", ["pymavlink", "mavsdk"])
def test_a_pilots_loiter_ends_the_authority_and_after_the_pilots_landing_nothing_arms(stack: Stack,
                                                                                       backend: str) -> None:
    vehicle, _ = flying(stack, mavlink__backend=backend)
    client = stack.client
    assert client is not None
    assert client.state().status.authority == "operator"

    with second_station(stack) as gcs:
        assert gcs.set_mode(LOITER) == M.MAV_RESULT_ACCEPTED
        revoked = stack.wait_event(lambda e: e.event == "authority_revoked", 10.0, "the end of the authority")
        assert "LOITER" in revoked.detail and "not commanded by the service" in revoked.detail, revoked.detail
        assert client.state().status.authority == "revoked"
        time.sleep(3.0)  # 75 s of the vehicle's time: the users go on asking, the service goes on planning
        assert gcs.set_mode(LAND) == M.MAV_RESULT_ACCEPTED
    landed = stack.wait_event(lambda e: e.event == "landed", 60.0, "the pilot's landing")
    assert "sortie 1" in landed.detail, landed.detail
    the_next_sortie_waits(stack)

    log = vehicle.log()
    after = log[log.rindex("command 176 accepted; mode LOITER"):]  # the pilot's
    assert flight_commands(after) == ["176", "176"], after[-3000:]  # the pilot's LOITER and LAND, no other
    assert MODE.findall(after) == ["LOITER", "LAND"], after[-3000:]
    assert re.search(r"disarmed \(\w+\) at", after), after[-3000:]
    assert not ARMED.search(after), after[-3000:]
    # The next sortie began without authority: it waits for the operator.
    status = client.state().status
    assert status.authority == "none" and "the operator's start is awaited" in status.authority_detail, status
    assert not status.armed, status

    # What was recorded before the pilot took over was flown, the hold the LOITER cut included.
    recorded = recorded_services(stack.journal_path)
    assert recorded
    scenario = load_config(stack.tmp / "planner.toml").scenario()
    false = false_services(recorded, stub_track(stack.track), scenario, HOLD_RADIUS_M, TOLERANCE_S)
    assert not false, "\n".join(false)


@pytest.mark.timeout(180)
def test_a_second_stations_mission_ends_the_authority_and_is_left_to_fly(stack: Stack) -> None:
    """Another ground station uploads its own mission (takeoff, two waypoints, return)
    while the vehicle flies ours in AUTO: ArduPilot tells only the uploading station, but
    MISSION_CURRENT's count changes; the service reads the mission back, finds it is not
    its own, ends its authority and neither replaces that mission nor commands anything;
    the vehicle flies it home, and the next sortie begins without authority."""
    vehicle, _ = flying(stack)
    client = stack.client
    assert client is not None
    theirs = their_mission_ends_the_authority(stack, lambda gcs: encode_path(
        [HoverPoint(400.0, 100.0, 60.0, 2.0), HoverPoint(450.0, 50.0, 60.0, 2.0)], GeoOrigin(), "ardupilot"))
    landed = stack.wait_event(lambda e: e.event == "landed", 90.0, "the landing at the end of their mission")
    assert "sortie 1" in landed.detail, landed.detail
    the_next_sortie_waits(stack)

    log = vehicle.log()
    # theirs: the last mission the vehicle took before the landing (sortie 2's plans may come
    # after it, of the same length: a clean-clone run found one)
    landing = log.rindex("landed at")
    start = log.rindex(f"mission of {len(theirs)} items accepted", 0, landing)
    after = log[start:]
    flown = log[start + len("mission of"):landing]
    assert "mission of" not in flown, "the service replaced their mission in flight:\n" + after[-3000:]
    assert flight_commands(after) == [], after[-3000:]
    assert not ARMED.search(after), after[-3000:]
    status = client.state().status
    assert status.authority == "none" and not status.armed, status


@pytest.mark.timeout(180)
def test_a_pilots_disarming_in_the_air_ends_the_authority_and_nothing_arms_again(stack: Stack) -> None:
    """The pilot's emergency stop (a forced disarming in the air, from a second station):
    the mode stays AUTO, so before only the mode was judged and the fall's landing counted
    as the service's own. Now the disarming ends the authority, the vehicle comes down, and
    the next sortie waits for the operator: the vehicle is never armed again."""
    vehicle, _ = flying(stack)
    client = stack.client
    assert client is not None
    with second_station(stack) as gcs:
        assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 21196) == M.MAV_RESULT_ACCEPTED
    revoked = stack.wait_event(lambda e: e.event == "authority_revoked", 10.0, "the end of the authority")
    assert "disarmed (not commanded by the service)" in revoked.detail, revoked.detail
    stack.wait_event(lambda e: e.event == "landed", 30.0, "the fall's landing")
    the_next_sortie_waits(stack)

    log = vehicle.log()
    after = log[log.rindex("disarmed (command)"):]
    assert flight_commands(after) == [], after[-3000:]
    assert not ARMED.search(after), after[-3000:]
    status = client.state().status
    assert status.authority == "none" and not status.armed, status


@pytest.mark.timeout(180)
@pytest.mark.parametrize("found_by, backend, flavour, settings", [
    ("the periodic check", "pymavlink", "ardupilot", {"sortie__readback_interval_s": "2", "sortie__leg_tolerance_m": "0"}),
    ("off its leg", "pymavlink", "ardupilot", {"sortie__readback_interval_s": "0"}),
    ("names its mission", "pymavlink", "px4", {"sortie__readback_interval_s": "0", "sortie__leg_tolerance_m": "0"}),
    ("names its mission", "mavsdk", "px4", {"sortie__readback_interval_s": "0", "sortie__leg_tolerance_m": "0"}),
])
def test_a_second_stations_mission_of_the_same_length_ends_the_authority(
        stack: Stack, found_by: str, backend: str, flavour: str, settings: dict[str, str]) -> None:
    """As above, but their mission has as many items as ours (ours read back, each point
    moved 55 m north): MISSION_CURRENT's count says nothing, so before the periodic
    read-back (here every 2 s), the check of the vehicle's track against the leg it flies
    and PX4's ``mission_id`` (each alone here) the service flew it as its own."""
    _, service = flying(stack, "--flavour", flavour, mavlink__backend=backend, mavlink__flavour=flavour, **settings)
    their_mission_ends_the_authority(stack, lambda gcs: [replace(i, x=i.x + 5000) if i.seq > 0 and i.x else i
                                                         for i in gcs.download()])  # ours, moved
    stack.wait_log(service, found_by, 5.0)
