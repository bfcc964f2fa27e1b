"""The simulated flight: paths, holds and the energy model, checked by hand."""

from __future__ import annotations

import math

import pytest

from planner_service.model import pack, preset
from planner_service.model.energy import flight_energy_j
from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, encode_path, item_local
from sim_bridge.vehicle.errors import VehicleError
from sim_bridge.vehicle.events import BatteryLow, BatterySwapped, Disarmed, TouchedDown, ItemComplete
from sim_bridge.vehicle.flight import FALL_MPS, Flight
from sim_bridge.vehicle.modes import Mode

ORIGIN = GeoOrigin()


def start(flight: Flight) -> None:
    """Arm, AUTO and (ArduPilot, whose AUTO waits on the ground for it) MISSION_START."""
    assert flight.arm() is None and flight.set_mode(Mode.AUTO) is None
    assert flight.mission_start() is None


def kinds(events: list) -> list[type]:
    return [type(e) for e in events]


def fly(flight: Flight, dt: float = 0.7, limit_s: float = 20_000.0) -> list:
    events = []
    while flight.armed and flight.time_s < limit_s:
        events += flight.step(dt)
    return events


@pytest.mark.parametrize("name", ["field", "paper"])
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_a_mission_costs_what_the_model_says(name: str, flavour: str) -> None:
    scenario = preset(name)
    flight = Flight(scenario, ORIGIN, flavour)
    p = pack(scenario)
    points = [HoverPoint(0.0, 0.0, 100.0, 0.0), HoverPoint(300.0, 400.0, 100.0, 20.0)]
    flight.set_mission(encode_path(points, ORIGIN, flavour))
    start(flight)
    events = fly(flight)
    reached = [e.seq for e in events if isinstance(e, ItemComplete)]
    first = 1 if flavour == "ardupilot" else 0
    assert reached == list(range(first, len(flight.mission)))
    assert flight.landed and not flight.armed and flight.pos == [0.0, 0.0, 0.0]
    # Legs: climb 100 m (takeoff), none to the first point (over home), about 500 m out and
    # back (the far point as its 1e-7 degree coordinates place it), 100 m down.
    far = item_local(flight.mission[-2], ORIGIN)
    out = math.hypot(far[0], far[1])
    assert out == pytest.approx(500.0, abs=0.01)
    expected_flight = 2 * flight_energy_j(p, 100.0) + 2 * flight_energy_j(p, out)
    assert flight.flight_j == pytest.approx(expected_flight, rel=1e-9)
    assert flight.hover_j == pytest.approx(scenario.hover_power_w * 20.0, rel=1e-9)
    assert flight.compute_j > 0.0
    assert flight.energy_j == pytest.approx(scenario.battery_j - flight.flight_j - flight.hover_j - flight.compute_j)
    # Time: 100 m at 5 m/s up and down, 1000 m at the cruise speed, 20 s of hold.
    assert flight.time_s == pytest.approx(40.0 + 1000.0 / scenario.speed_mps + 20.0, abs=0.75)


def test_step_size_does_not_change_the_result() -> None:
    results = []
    for dt in (0.05, 3.0, 500.0):
        flight = Flight(preset("field"), ORIGIN, "px4")
        flight.set_mission(encode_path([HoverPoint(250.0, 250.0, 80.0, 33.3)], ORIGIN, "px4"))
        start(flight)
        fly(flight, dt)
        results.append((flight.energy_j, flight.time_s if dt < 1 else None))
    assert results[0][0] == pytest.approx(results[1][0], rel=1e-9)
    assert results[0][0] == pytest.approx(results[2][0], rel=1e-9)


def test_battery_threshold_returns_home_and_lands() -> None:
    scenario = preset("field").replace(battery_j=60_000.0)
    flight = Flight(scenario, ORIGIN, "ardupilot")
    flight.set_mission(encode_path([HoverPoint(400.0, 300.0, 50.0, 3000.0)], ORIGIN, "ardupilot"))
    start(flight)
    events = kinds(fly(flight))
    assert BatteryLow in events and events.index(BatteryLow) < events.index(TouchedDown)
    assert flight.mode is Mode.RTL and flight.landed and flight.pos == [0.0, 0.0, 0.0]
    floor = scenario.battery_threshold * scenario.battery_j
    # It turned back at the threshold; the flight home costs what the model says.
    home_leg = flight_energy_j(pack(scenario), 500.0) + flight_energy_j(pack(scenario), 50.0)
    # The failsafe is checked every sub-step (0.7 s here): it may turn home up to one
    # sub-step of hovering below the threshold, never above it.
    overshoot = 0.7 * scenario.hover_power_w * 1.01
    assert floor - home_leg - overshoot <= flight.energy_j <= floor - home_leg + 1e-6
    assert flight.arm() is not None, "arming below the threshold is refused"


def test_commands() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot")
    assert flight.takeoff(10.0).reasons == ("not armed",)
    flight.arm()
    flight.drain()
    assert flight.takeoff(10.0).reasons == ("takeoff needs GUIDED mode",)
    flight.set_mode(Mode.GUIDED)
    assert flight.takeoff(10.0) is None
    flight.step(5.0)
    assert flight.pos[2] == pytest.approx(10.0) and not flight.landed
    assert flight.disarm() is not None
    flight.set_mode(Mode.LAND)
    events = flight.step(5.0)
    assert kinds(events) == [TouchedDown, Disarmed] and events[1].why == "landed"
    assert math.isclose(flight.pos[2], 0.0)


def test_a_vehicle_disarmed_in_the_air_falls_and_lands() -> None:
    # Before, a forced disarming left the stub hovering at its height, disarmed: no landing
    # ever came, where SITL's copter falls.
    flight = Flight(preset("field"), ORIGIN, "ardupilot")
    flight.arm()
    flight.set_mode(Mode.GUIDED)
    assert flight.takeoff(30.0) is None
    flight.step(20.0)
    flight.drain()
    energy = flight.energy_j
    assert flight.disarm(force=True) is None and not flight.armed
    events = flight.step(1.0)
    assert flight.pos[2] == pytest.approx(30.0 - FALL_MPS) and not flight.landed and TouchedDown not in kinds(events)
    events = flight.step(5.0)
    assert TouchedDown in kinds(events) and flight.landed and flight.pos[2] == 0.0
    assert flight.energy_j == energy, "the motors are off"


def test_battery_swap_after_landing_and_disarming() -> None:
    scenario = preset("field").replace(battery_j=60_000.0)
    flight = Flight(scenario, ORIGIN, "px4", recharge_s=120.0)
    flight.set_mission(encode_path([HoverPoint(400.0, 300.0, 50.0, 3000.0)], ORIGIN, "px4"))
    start(flight)
    events = fly(flight)  # the failsafe brings it home below the threshold
    assert BatteryLow in kinds(events) and flight.landed and not flight.armed
    drained = flight.energy_j
    assert flight.arm() is not None and flight.failsafe
    # no swap before 120 s on the ground, disarmed; the swap at 120 s, to exactly full
    assert flight.step(119.0) == [] and flight.energy_j == drained
    events = flight.step(1.5)
    assert kinds(events) == [BatterySwapped]
    assert flight.energy_j == scenario.battery_j and flight.swaps == 1 and not flight.failsafe
    assert flight.step(500.0) == [] and flight.swaps == 1  # a full battery is not swapped again
    # and it flies the next sortie
    flight.set_mission(encode_path([HoverPoint(100.0, 100.0, 50.0, 10.0)], ORIGIN, "px4"))
    start(flight)
    assert TouchedDown in kinds(fly(flight))
    assert flight.energy_j < scenario.battery_j


def test_arming_restarts_the_swap_wait_and_none_never_swaps() -> None:
    scenario = preset("field")
    flight = Flight(scenario, ORIGIN, "ardupilot", recharge_s=60.0)
    flight.energy_j = 50_000.0  # a used battery on the ground
    flight.step(50.0)
    assert flight.arm() is None and flight.disarm() is None  # armed on the ground: the wait restarts
    flight.drain()
    assert flight.step(50.0) == [] and flight.energy_j == 50_000.0
    assert kinds(flight.step(10.0)) == [BatterySwapped]
    never = Flight(scenario, ORIGIN, "ardupilot")
    never.energy_j = 50_000.0
    never.drain()  # the estimator's start-up events (a position from the start here)
    assert never.step(1e6) == [] and never.energy_j == 50_000.0
    with pytest.raises(VehicleError, match="recharge_s"):
        Flight(scenario, ORIGIN, "ardupilot", recharge_s=-1.0)
