"""pymavlink as a ground station against the vehicle stub running as a real process."""

from __future__ import annotations

import os
import socket

import pytest

from planner_service.harness.processes import free_port
from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, MissionItem, encode_path, same_items
from tests.support.gcs import M, as_stored, ten_items

ORIGIN = GeoOrigin()


@pytest.mark.timeout(60)
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_upload_download_fly_and_land(vehicle, gcs_factory, flavour: str) -> None:
    process, port = vehicle("--flavour", flavour, "--speedup", "300", "--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    hb = gcs.wait_vehicle()
    assert hb.get_srcSystem() == 1 and hb.get_srcComponent() == 1
    assert hb.type == M.MAV_TYPE_QUADROTOR
    assert hb.autopilot == (M.MAV_AUTOPILOT_ARDUPILOTMEGA if flavour == "ardupilot" else M.MAV_AUTOPILOT_PX4)
    gcs.ask()

    items = ten_items(flavour)
    assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
    assert same_items(gcs.download(), as_stored(items, flavour))

    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    assert gcs.start_mission(flavour) == M.MAV_RESULT_ACCEPTED
    first = 1 if flavour == "ardupilot" else 0
    reached: list[int] = []
    while len(reached) < len(items) - first:
        msg = gcs.recv(["MISSION_ITEM_REACHED"], 20.0)
        assert msg is not None, f"no MISSION_ITEM_REACHED after {reached}"
        reached.append(msg.seq)
    assert reached == list(range(first, len(items)))
    landed = gcs.recv(["EXTENDED_SYS_STATE"], 5.0, lambda m: m.landed_state == M.MAV_LANDED_STATE_ON_GROUND)
    assert landed is not None
    disarmed = gcs.recv(["HEARTBEAT"], 5.0, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert disarmed is not None
    home = gcs.recv(["GLOBAL_POSITION_INT"], 5.0)
    assert home.relative_alt == 0
    assert abs(home.lat - round(ORIGIN.lat_deg * 1e7)) <= 1 and abs(home.lon - round(ORIGIN.lon_deg * 1e7)) <= 1
    battery = gcs.recv(["BATTERY_STATUS"], 5.0)
    assert 0 < battery.battery_remaining < 100, "the flight must have drained the battery"


@pytest.mark.timeout(30)
def test_telemetry_and_capabilities(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask()
    needed = {"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "SYS_STATUS", "BATTERY_STATUS", "HEARTBEAT"}
    seen: set[str] = set()
    while not needed <= seen:
        msg = gcs.recv(None, 3.0)
        assert msg is not None, f"missing {needed - seen}"
        seen.add(msg.get_type())
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == M.MAV_RESULT_ACCEPTED
    version = gcs.recv(["AUTOPILOT_VERSION"], 2.0)
    assert version is not None and version.capabilities & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    assert gcs.command(12345) == M.MAV_RESULT_UNSUPPORTED


@pytest.mark.timeout(30)
def test_failed_upload_keeps_the_old_mission_on_px4_and_what_was_written_on_ardupilot(vehicle, gcs_factory) -> None:
    for flavour in ("px4", "ardupilot"):
        _, port = vehicle("--flavour", flavour, "--gps-delay-s", "0")
        gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
        gcs.wait_vehicle()
        good = ten_items(flavour)
        assert gcs.upload(good) == M.MAV_MISSION_ACCEPTED
        # A waypoint 5 km away is outside the vehicle's geofence (the stub's, per item).
        far = encode_path([HoverPoint(100.0, 100.0, 50.0), HoverPoint(5000.0, 100.0, 50.0)], ORIGIN, flavour)
        assert gcs.upload(far) == M.MAV_MISSION_INVALID_PARAM5_X
        held = gcs.download()
        if flavour == "px4":
            assert same_items(held, good)
        else:
            # ArduPilot truncated to the new count and kept the items written before the refusal.
            bad = 3  # home, takeoff, the near point, the far one (refused), return
            assert len(held) == len(far) and same_items(held[1:bad], as_stored(far, flavour)[1:bad])
            assert same_items(held[bad:], as_stored(good, flavour)[bad:len(far)])
        unsupported = list(good)
        unsupported[3] = MissionItem(**{**good[3].__dict__, "command": 31000})
        assert gcs.upload(unsupported) == M.MAV_MISSION_UNSUPPORTED
        assert gcs.upload([]) == M.MAV_MISSION_ACCEPTED
        assert gcs.download() == []  # ArduPilot too: home comes back as item 0 at the next arming


@pytest.mark.timeout(30)
def test_legacy_mission_request_is_answered_with_mission_item(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    items = ten_items()
    assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
    gcs.conn.mav.mission_request_send(1, 1, 2, M.MAV_MISSION_TYPE_MISSION)
    legacy = gcs.recv(["MISSION_ITEM"], 2.0)
    assert legacy is not None and legacy.seq == 2
    back = MissionItem.from_message(legacy)
    stored = as_stored(items, "ardupilot")[2]
    # MISSION_ITEM carries degrees as float32: one ulp at 47 degrees is 3.8e-6 degrees, 38
    # units of 1e-7 (why MISSION_ITEM_INT exists). Everything else comes back exact.
    assert abs(back.x - stored.x) <= 38 and abs(back.y - stored.y) <= 10
    assert MissionItem(**{**back.__dict__, "x": stored.x, "y": stored.y}).same_as(stored)


@pytest.mark.timeout(40)
def test_commands_takeoff_rtl_land(vehicle, gcs_factory) -> None:
    _, port = vehicle("--speedup", "50", "--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask([M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT])
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20) == M.MAV_RESULT_FAILED  # not armed
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    assert gcs.set_mode(4) == M.MAV_RESULT_ACCEPTED  # GUIDED
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20) == M.MAV_RESULT_ACCEPTED
    up = gcs.recv(["GLOBAL_POSITION_INT"], 10.0, lambda m: m.relative_alt >= 19_900)
    assert up is not None
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_FAILED  # in the air (ArduPilot: FAILED)
    assert gcs.command(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
    hb = gcs.recv(["HEARTBEAT"], 2.0, lambda m: m.custom_mode == 9)
    assert hb is not None
    down = gcs.recv(["HEARTBEAT"], 10.0, lambda m: not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert down is not None


@pytest.mark.timeout(40)
def test_battery_threshold_sends_it_home(vehicle, gcs_factory) -> None:
    # 40 kJ with a 10 % threshold: the 168 W hover drains to 4 kJ well before the holds end.
    _, port = vehicle("--speedup", "400", "--set", "battery_j=40000", "--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask()
    points = [HoverPoint(400.0, 400.0, 50.0, 600.0), HoverPoint(450.0, 100.0, 50.0, 600.0)]
    assert gcs.upload(encode_path(points, ORIGIN, "ardupilot")) == M.MAV_MISSION_ACCEPTED
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    assert gcs.start_mission() == M.MAV_RESULT_ACCEPTED
    warning = gcs.recv(["STATUSTEXT"], 20.0, lambda m: "returning" in m.text)
    assert warning is not None
    rtl = gcs.recv(["HEARTBEAT"], 2.0, lambda m: m.custom_mode == 6)
    assert rtl is not None
    landed = gcs.recv(["EXTENDED_SYS_STATE"], 20.0, lambda m: m.landed_state == M.MAV_LANDED_STATE_ON_GROUND)
    assert landed is not None
    pos = gcs.recv(["LOCAL_POSITION_NED"], 2.0)
    assert abs(pos.x) < 0.01 and abs(pos.y) < 0.01 and abs(pos.z) < 0.01, "it lands at home"
    status = gcs.recv(["SYS_STATUS"], 2.0)
    assert status.battery_remaining <= 10


@pytest.mark.timeout(30)
def test_garbage_does_not_stop_the_vehicle(vehicle, gcs_factory) -> None:
    process, port = vehicle()
    rng = __import__("random").Random(7)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for size in (1, 7, 280, 1500):
            sock.sendto(bytes(rng.randrange(256) for _ in range(size)), ("127.0.0.1", port))
        # A MAVLink 2 start byte followed by a lying length and junk.
        sock.sendto(b"\xfd\xff" + os.urandom(40), ("127.0.0.1", port))
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    assert gcs.upload(ten_items()) == M.MAV_MISSION_ACCEPTED
    assert process.proc.poll() is None
    assert "Traceback" not in process.log()


@pytest.mark.timeout(30)
def test_tcp_link(spawn, gcs_factory) -> None:
    port = free_port()
    spawn(["vehicle", "--mavlink", f"tcpin:127.0.0.1:{port}", "--gps-delay-s", "0"], "listening")
    gcs = gcs_factory(f"tcp:127.0.0.1:{port}")
    gcs.wait_vehicle()
    items = ten_items()
    assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
    assert same_items(gcs.download(), as_stored(items, "ardupilot"))
