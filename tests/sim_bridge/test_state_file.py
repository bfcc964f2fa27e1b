"""The vehicle restarts where it was (``--state-file``): the flight's snapshot, the file, and
a stub process started on a saved state as after a reboot in the air."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from planner_service.model import preset
from protocol.geodesy import GeoOrigin, global_to_local
from protocol.mission import HoverPoint, encode_path
from sim_bridge.vehicle.errors import VehicleError
from sim_bridge.vehicle.events import ItemComplete
from sim_bridge.vehicle.flight import Flight
from sim_bridge.vehicle.modes import Mode
from sim_bridge.vehicle.state_file import load_state, parse_state, save_state
from tests.support.gcs import M, GroundStation

ORIGIN = GeoOrigin()


def airborne_flight(flavour: str = "ardupilot") -> Flight:
    """A flight on its way to a far point, 60 simulated seconds after starting."""
    flight = Flight(preset("field"), ORIGIN, flavour)
    flight.set_mission(encode_path([HoverPoint(400.0, 300.0, 50.0, 30.0)], ORIGIN, flavour))
    assert flight.arm() is None and flight.set_mode(Mode.AUTO) is None and flight.mission_start() is None
    for _ in range(60):
        flight.step(1.0)
    assert not flight.landed and flight.mode is Mode.AUTO
    return flight


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_resume_in_the_air_holds_where_it_was_with_its_mission_lost(flavour: str) -> None:
    before = airborne_flight(flavour)
    snap = before.snapshot()
    after = Flight(preset("field"), ORIGIN, flavour)
    after.resume(snap)
    assert after.pos == before.pos and after.energy_j == before.energy_j and after.home == before.home
    assert after.armed and not after.landed and after.mode is Mode.HOLD
    assert after.mission == [] and not after.started
    assert after.time_s == pytest.approx(60.0) and after.since_boot_s == 0.0  # time_boot_ms restarts
    energy = after.energy_j
    after.step(10.0)
    # Holding: no movement, hover power only (10 s at hover_power_w, no computation).
    assert after.pos == before.pos
    assert energy - after.energy_j == pytest.approx(10.0 * after.scenario.hover_power_w, rel=1e-9)
    assert after.since_boot_s == pytest.approx(10.0)
    # A new mission and AUTO: it flies again, from the mission's first item.
    after.set_mission(encode_path([HoverPoint(100.0, 100.0, 50.0, 0.0)], ORIGIN, flavour))
    after.drain()
    assert after.set_mode(Mode.AUTO) is None
    events = []
    while after.armed and after.time_s < 2000:
        events += after.step(1.0)
    assert after.landed and after.pos == [0.0, 0.0, 0.0]
    assert [e.seq for e in events if isinstance(e, ItemComplete)] == list(range(after.first_item, len(after.mission)))


def test_resume_on_the_ground_is_disarmed() -> None:
    flight = Flight(preset("field"), ORIGIN, "ardupilot")
    flight.energy_j -= 1234.0
    again = Flight(preset("field"), ORIGIN, "ardupilot")
    again.resume(flight.snapshot())
    assert again.landed and not again.armed and again.energy_j == flight.energy_j
    assert again.mode is Mode.MANUAL


def test_file_round_trip_and_refusals(tmp_path: Path) -> None:
    path = tmp_path / "vehicle-state.json"
    assert load_state(path) is None
    snap = airborne_flight().snapshot()
    save_state(path, snap)
    assert load_state(path) == snap
    assert [p.name for p in tmp_path.iterdir()] == ["vehicle-state.json"]  # no temporary file left

    data = json.loads(path.read_text())
    for key, value, said in [("energy_j", -1.0, "energy_j"), ("pos", [1, 2], "pos"), ("mode", "FLYING", "mode"),
                             ("armed", "yes", "armed"), ("version", 7, "version")]:
        with pytest.raises(VehicleError, match=said):
            parse_state({**data, key: value})
    with pytest.raises(VehicleError, match="missing 'landed'"):
        parse_state({k: v for k, v in data.items() if k != "landed"})
    path.write_text("{not json")
    with pytest.raises(VehicleError, match="is not JSON"):
        load_state(path)
    with pytest.raises(VehicleError, match="px4"):
        Flight(preset("field"), ORIGIN, "px4").resume(snap)


@pytest.mark.timeout(30)
def test_a_stub_started_on_a_saved_flight_comes_back_holding_in_the_air(vehicle, tmp_path: Path) -> None:
    path = tmp_path / "state.json"
    before = airborne_flight()
    save_state(path, before.snapshot())
    process, port = vehicle("--state-file", str(path))
    assert "restarted from" in process.log() and "airborne" in process.log()
    gcs = GroundStation(f"udpout:127.0.0.1:{port}")
    try:
        hb = gcs.wait_vehicle()
        gcs.ask([M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE])
        assert hb.custom_mode == 5 and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED  # LOITER, armed
        pos = gcs.recv(["GLOBAL_POSITION_INT"], 2.0)
        assert pos is not None and pos.time_boot_ms < 10_000  # a fresh boot's clock
        x, y, _ = global_to_local(ORIGIN, pos.lat / 1e7, pos.lon / 1e7, 0.0)
        assert (x, y) == pytest.approx((before.pos[0], before.pos[1]), abs=0.05)
        state = gcs.recv(["EXTENDED_SYS_STATE"], 2.0)
        assert state is not None and state.landed_state == M.MAV_LANDED_STATE_IN_AIR
        held = gcs.download()
        assert [(i.seq, i.frame) for i in held] == [(0, M.MAV_FRAME_GLOBAL)]  # the mission was lost: home alone
        # The state file keeps being written: the flight time goes on from where it was.
        time.sleep(0.5)
        assert load_state(path).time_s >= before.time_s
    finally:
        gcs.close()
