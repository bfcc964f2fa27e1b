"""How the simulated aircraft runs a mission that changes under it, per autopilot (pure, no
sockets): ArduPilot's change detector and set-current, PX4's mission replacement, the
position estimate's stages, auto-disarm, and a waypoint at ground level that used to stall."""

from __future__ import annotations

import math
import time

import pytest

from planner_service.model import preset
from protocol.geodesy import GeoOrigin
from protocol.mission import NAV_WAYPOINT, HoverPoint, MissionItem, encode_path, item_local
from sim_bridge.vehicle.estimator import Stage
from sim_bridge.vehicle.events import (
    CurrentChanged, Disarmed, GpsFix, HomeSet, MissionDone, MissionRestarted, MissionRestartFailed, OriginSet,
    ItemComplete, UsingGps,
)
from sim_bridge.vehicle.flight import Flight, MissionState
from sim_bridge.vehicle.modes import Mode
from sim_bridge.vehicle.stored_items import ardupilot_stored

ORIGIN = GeoOrigin()
POINTS = [HoverPoint(100.0, 0.0, 30.0, 20.0), HoverPoint(100.0, 100.0, 30.0, 30.0), HoverPoint(0.0, 100.0, 30.0, 5.0)]


def stored(items: list[MissionItem]) -> list[MissionItem]:
    return [ardupilot_stored(i) for i in items]


def flying(flavour: str, points: list[HoverPoint] = POINTS) -> Flight:
    flight = Flight(preset("field"), ORIGIN, flavour)
    items = encode_path(points, ORIGIN, flavour)
    flight.set_mission(stored(items) if flavour == "ardupilot" else items)
    assert flight.arm() is None and flight.set_mode(Mode.AUTO) is None and flight.mission_start() is None
    flight.drain()
    return flight


def until(flight: Flight, condition, limit_s: float = 2000.0, dt: float = 0.5) -> list:
    events: list = []
    while not condition(flight, events):
        assert flight.time_s < limit_s, "never happened"
        events += flight.step(dt)
    return events


def at(flight: Flight, seq: int) -> bool:
    """Holding at item ``seq``."""
    return flight.current == seq and flight.hold_left is not None and flight.hold_left > 0


def of(events: list, kind: type) -> list:
    return [e for e in events if isinstance(e, kind)]


def test_ardupilot_an_upload_during_a_hold_restarts_it_even_unchanged() -> None:
    flight = flying("ardupilot")
    until(flight, lambda f, _: at(f, 3))  # the 30 s hold at the second point
    flight.step(10.0)
    restart_at = flight.time_s
    flight.set_mission(list(flight.mission))  # the same mission again, every item written
    events = flight.drain()
    assert of(events, MissionRestarted) and all(e.seq == 3 for e in of(events, MissionRestarted))
    assert flight.current == 3 and flight.hold_left is None
    events = until(flight, lambda f, ev: bool(of(ev, ItemComplete)))
    assert of(events, ItemComplete)[0].seq == 3
    assert flight.time_s - restart_at == pytest.approx(30.0, abs=0.6)  # the whole hold again


def test_ardupilot_a_moved_current_item_is_flown_to_at_the_same_index() -> None:
    flight = flying("ardupilot")
    until(flight, lambda f, _: f.current == 3)
    moved = encode_path([POINTS[0], HoverPoint(150.0, 150.0, 30.0, 30.0), POINTS[2]], ORIGIN, "ardupilot")
    flight.set_mission(stored(moved))
    assert flight.current == 3 and of(flight.drain(), MissionRestarted)
    until(flight, lambda f, _: at(f, 3))
    assert flight.pos[:2] == pytest.approx(list(item_local(moved[3], ORIGIN)[:2]), abs=1e-6)


def test_ardupilot_an_index_that_is_gone_fails_to_restart_and_the_command_goes_on() -> None:
    flight = flying("ardupilot")
    until(flight, lambda f, _: at(f, 3))
    target = list(flight.pos)
    flight.mission_changed(stored(encode_path([], ORIGIN, "ardupilot"))[:2], frozenset())  # truncated to 2
    assert of(flight.drain(), MissionRestartFailed)
    # Only a changed count fires again: the items written after it do not.
    flight.mission_changed(list(flight.mission), frozenset({1}))
    assert flight.drain() == []
    events = until(flight, lambda f, ev: bool(of(ev, MissionDone)))
    assert of(events, ItemComplete)[0].seq == 3 and flight.pos == target  # its hold ended where it was
    assert flight.state is MissionState.COMPLETE and flight.mode is Mode.AUTO and not flight.landed
    flight.step(100.0)
    assert flight.pos == target  # hovering in AUTO after the end


def test_ardupilot_an_empty_mission_in_flight_never_completes_the_command() -> None:
    flight = flying("ardupilot")
    until(flight, lambda f, _: at(f, 2))
    flight.mission_changed([], frozenset())
    events = flight.step(200.0)
    assert not of(events, ItemComplete) and flight.current == 2 and flight.state is MissionState.RUNNING


def test_ardupilot_set_current_goes_now_when_running_and_only_moves_the_index_otherwise() -> None:
    flight = flying("ardupilot")
    flight.set_mission(flight.mission[:-1])  # no return to launch: it hovers after the last point
    until(flight, lambda f, _: at(f, 2))
    assert flight.set_current(4)
    assert flight.current == 4 and flight.loaded is not None and flight.loaded.seq == 4
    until(flight, lambda f, ev: bool(of(ev, MissionDone)))
    here = list(flight.pos)
    assert not flight.set_current(9) and not flight.set_current(-1)
    assert flight.set_current(2) and flight.state is MissionState.STOPPED and flight.loaded is None
    flight.step(30.0)
    assert flight.pos == here, "a stopped mission does not move"
    assert flight.mission_start() is None  # resumes at the index set
    until(flight, lambda f, _: at(f, 2))


def test_ardupilot_auto_on_the_ground_needs_a_takeoff_item_and_mission_start() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot")
    no_takeoff = encode_path(POINTS, ORIGIN, "ardupilot", takeoff=False)
    flight.set_mission(stored(no_takeoff))
    assert flight.arm() is None
    refusal = flight.set_mode(Mode.AUTO)
    assert refusal is not None and refusal.notes == ("Auto: Missing Takeoff Cmd",)
    flight.set_mission(stored(encode_path(POINTS, ORIGIN, "ardupilot")))
    assert flight.set_mode(Mode.AUTO) is None
    flight.step(5.0)
    assert flight.landed, "AUTO on the ground waits for MISSION_START"
    assert flight.mission_start() is None
    flight.step(5.0)
    assert not flight.landed


def test_px4_a_new_mission_starts_at_the_marked_item_or_keeps_the_index() -> None:
    flight = flying("px4")
    until(flight, lambda f, _: at(f, 2))
    same = list(flight.mission)
    flight.replace_mission(same)
    assert flight.drain() == [] and flight.hold_left is not None, "the same mission (CRC) changes nothing"
    unmarked = [MissionItem(**{**i.__dict__, "current": 0}) for i in encode_path(
        [POINTS[0], HoverPoint(120.0, 120.0, 30.0, 30.0), POINTS[2]], ORIGIN, "px4")]
    flight.replace_mission(unmarked)
    assert flight.current == 2 and of(flight.drain(), CurrentChanged)  # the old index, started anew
    marked = encode_path(POINTS, ORIGIN, "px4")  # item 0 marked current, as encode_path does
    flight.replace_mission(marked)
    assert flight.current == 0 and flight.loaded == marked[0]


def test_the_estimator_stages_and_arming() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot", gps_delay_s=40.0)
    assert flight.stage is Stage.NO_GPS and not flight.home_set
    assert flight.set_mode(Mode.GUIDED) is None  # any mode while disarmed
    assert flight.arm().reasons == ("AHRS: waiting for home",)
    events = flight.step(10.0)
    assert of(events, GpsFix) and flight.stage is Stage.GPS
    events = flight.step(10.0)
    assert of(events, OriginSet) and of(events, HomeSet) and flight.home_set
    assert flight.arm().reasons == ("Need Position Estimate",)
    flight.set_mode(Mode.MANUAL)
    assert flight.arm() is None, "STABILIZE arms without a position"
    refusal = flight.set_mode(Mode.AUTO)
    assert refusal is not None and refusal.reasons == ("requires position",)
    assert flight.disarm() is None
    events = flight.step(21.0)
    assert of(events, UsingGps) and flight.position_ok
    flight.set_mode(Mode.GUIDED)
    assert flight.arm() is None
    px4 = Flight(preset("field"), ORIGIN, "px4", gps_delay_s=40.0)
    # PX4 SITL 1.18's STATUSTEXT (TEMPORARILY_REJECTED): the navigation error goes as an event.
    assert px4.arm().reasons == ("Arming denied: Resolve system health failures first",)
    # ... and a mode is taken disarmed without a position (PX4 checks it at arming).
    assert px4.set_mode(Mode.RTL) is None and px4.set_mode(Mode.HOLD) is None


def test_px4_mission_start_arms_and_starts_a_mission_it_has() -> None:
    px4 = Flight(preset("field"), ORIGIN, "px4", gps_delay_s=0.0)
    px4.step(0.1)
    refusal = px4.mission_start()
    assert refusal is not None and refusal.reasons == ("No valid mission available",) and not px4.armed
    px4.mission = [MissionItem(seq=0, frame=6, command=16, current=1, x=round(ORIGIN.lat_deg * 1e7), y=round(ORIGIN.lon_deg * 1e7), z=10.0)]
    assert px4.mission_start() is None
    assert px4.armed and px4.mode is Mode.AUTO


def test_armed_on_the_ground_too_long_the_motors_stop() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot", disarm_delay_s=10.0)
    assert flight.arm() is None
    flight.drain()
    assert flight.step(9.0) == [] and flight.armed
    events = flight.step(2.0)
    assert [(type(e), e.why) for e in events if isinstance(e, Disarmed)] == [(Disarmed, "auto")]
    assert not flight.armed


@pytest.mark.parametrize("flavour", ["px4", "ardupilot"])
def test_a_first_waypoint_at_ground_level_does_not_stall(flavour: str) -> None:
    """MAVProxy's ``wp load`` of a WPL whose first item is a waypoint at 0 m: the stub spun
    through its sub-steps at 100 % CPU without moving. PX4 takes off to MIS_TAKEOFF_ALT
    first; ArduPilot refuses AUTO on the ground without a takeoff item."""
    flight = Flight(preset("field"), ORIGIN, flavour)
    items = encode_path([HoverPoint(50.0, 50.0, 0.0, 1.0), HoverPoint(80.0, 80.0, 20.0, 1.0)], ORIGIN, flavour,
                        takeoff=False)
    flight.set_mission(stored(items) if flavour == "ardupilot" else items)
    assert flight.arm() is None
    if flavour == "ardupilot":
        assert flight.set_mode(Mode.AUTO) is not None
        return
    assert flight.set_mode(Mode.AUTO) is None
    started = time.process_time()
    events = until(flight, lambda f, ev: not f.armed, limit_s=600.0, dt=1.0)
    assert time.process_time() - started < 2.0
    assert [e.seq for e in of(events, ItemComplete)] == list(range(len(items)))
    assert flight.landed and flight.pos == [0.0, 0.0, 0.0]


def test_ardupilot_reads_back_whole_seconds_and_flies_them() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot")
    items = encode_path([HoverPoint(50.0, 0.0, 20.0, 46.0)], ORIGIN, "ardupilot")
    items[2] = MissionItem(**{**items[2].__dict__, "param1": 46.117})  # as a ground station may send it
    flight.set_mission(stored(items))
    assert flight.arm() is None and flight.set_mode(Mode.AUTO) is None and flight.mission_start() is None
    assert flight.mission[2].param1 == 46.0 and flight.mission[2].command == NAV_WAYPOINT
    until(flight, lambda f, _: at(f, 2))
    started = flight.time_s
    events = until(flight, lambda f, ev: bool(of(ev, ItemComplete)), dt=0.25)
    assert flight.time_s - started == pytest.approx(46.0, abs=0.3)
    assert math.isfinite(flight.energy_j) and of(events, ItemComplete)[0].seq == 2
