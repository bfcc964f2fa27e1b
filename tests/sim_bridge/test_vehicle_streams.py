"""What the stub sends and to whom, as a real process over UDP on loopback: ArduPilot's
per-link streams (nothing until asked, SET_MESSAGE_INTERVAL per message, REQUEST_DATA_STREAM
per group), PX4's default set, the position estimate's messages, parameters and the
geofence bits of SYS_STATUS."""

from __future__ import annotations

import time

import pytest

from tests.support.gcs import M, GroundStation

EKF_STATUS_REPORT = 193


def counts(gcs: GroundStation, seconds: float) -> dict[str, int]:
    """Message types received (from the vehicle) in ``seconds``, with heartbeats sent."""
    out: dict[str, int] = {}
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        gcs.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        while (msg := gcs.recv(None, min(0.2, max(end - time.monotonic(), 0.0)))) is not None:
            if msg.get_srcSystem() == 1:
                out[msg.get_type()] = out.get(msg.get_type(), 0) + 1
    return out


@pytest.mark.timeout(60)
def test_ardupilot_streams_per_peer_and_per_group(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "0")
    a = gcs_factory(f"udpout:127.0.0.1:{port}")
    b = gcs_factory(f"udpout:127.0.0.1:{port}")
    a.wait_vehicle()
    b.wait_vehicle()
    # Unasked: heartbeats, TIMESYNC, STATUSTEXT, and home once when it is set.
    assert counts(a, 1.0).keys() <= {"HEARTBEAT", "TIMESYNC", "STATUSTEXT", "HOME_POSITION", "GPS_GLOBAL_ORIGIN"}
    assert a.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000) == M.MAV_RESULT_ACCEPTED
    got_a, got_b = counts(a, 1.0), counts(b, 0.5)
    assert got_a.get("GLOBAL_POSITION_INT", 0) >= 10, got_a
    assert "GLOBAL_POSITION_INT" not in got_b, "a rate set on one link applies to that link"
    # Interval 0: the default rate, that of its stream group, which is 0 on Copter.
    assert a.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0) == M.MAV_RESULT_ACCEPTED
    counts(a, 0.3)
    assert "GLOBAL_POSITION_INT" not in counts(a, 0.8)
    groups = {
        M.MAV_DATA_STREAM_EXTENDED_STATUS: {"SYS_STATUS", "MISSION_CURRENT", "GPS_RAW_INT"},
        M.MAV_DATA_STREAM_POSITION: {"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"},
        M.MAV_DATA_STREAM_EXTRA1: {"ATTITUDE"},
        M.MAV_DATA_STREAM_EXTRA2: {"VFR_HUD"},
        M.MAV_DATA_STREAM_EXTRA3: {"SYSTEM_TIME", "BATTERY_STATUS", "EKF_STATUS_REPORT"},
    }
    for group, expected in groups.items():
        b.conn.mav.request_data_stream_send(1, 1, group, 10, 1)
        got = counts(b, 0.8).keys() - {"HEARTBEAT", "TIMESYNC", "STATUSTEXT"}
        b.conn.mav.request_data_stream_send(1, 1, group, 0, 0)
        counts(b, 0.3)
        assert got == expected, f"group {group}: {got}"
    assert counts(b, 0.8).keys() <= {"HEARTBEAT", "TIMESYNC"}, "start_stop 0 stops the group"
    # A group's rate is then the default of its messages.
    b.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_POSITION, 5, 1)
    assert b.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, -1) == M.MAV_RESULT_ACCEPTED
    assert b.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0) == M.MAV_RESULT_ACCEPTED
    assert counts(b, 1.0).get("GLOBAL_POSITION_INT", 0) >= 3
    # EXTENDED_SYS_STATE: in no group, only by SET_MESSAGE_INTERVAL; the heartbeat's rate too.
    b.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 10, 1)
    assert "EXTENDED_SYS_STATE" not in counts(b, 0.8)
    assert b.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HEARTBEAT, 100_000) == M.MAV_RESULT_ACCEPTED
    assert counts(b, 1.0).get("HEARTBEAT", 0) >= 8


@pytest.mark.timeout(60)
def test_px4_streams_its_default_set_unasked_and_ignores_request_data_stream(vehicle, gcs_factory) -> None:
    _, port = vehicle("--flavour", "px4", "--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    got = counts(gcs, 2.5)
    assert {"GLOBAL_POSITION_INT", "EXTENDED_SYS_STATE", "SYS_STATUS", "ATTITUDE", "GPS_RAW_INT",
            "HOME_POSITION", "BATTERY_STATUS", "MISSION_CURRENT"} <= got.keys(), got
    # PX4 SITL's onboard link: 50, 30 and 5 Hz (ATTITUDE's 100 Hz capped at --max-stream-hz 50).
    assert got["GLOBAL_POSITION_INT"] > got["LOCAL_POSITION_NED"] > got["SYS_STATUS"] > got["MISSION_CURRENT"]
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE, -1) == M.MAV_RESULT_ACCEPTED
    counts(gcs, 0.3)
    assert "ATTITUDE" not in counts(gcs, 1.0)
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_EXTRA1, 10, 1)
    assert "ATTITUDE" not in counts(gcs, 1.0), "PX4 has no REQUEST_DATA_STREAM"
    current = gcs.recv(["MISSION_CURRENT"], 2.0)
    assert current.total == 0xFFFF  # PX4: UINT16_MAX with no mission


@pytest.mark.timeout(60)
def test_the_estimator_stages_as_sitl_reports_them(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "40", "--speedup", "10")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask([M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_GPS_RAW_INT, EKF_STATUS_REPORT,
             M.MAVLINK_MSG_ID_SYS_STATUS])
    first = gcs.recv(["EKF_STATUS_REPORT"], 2.0)
    assert first is not None and first.flags == 0xA7
    status = gcs.recv(["SYS_STATUS"], 2.0)
    assert not status.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK
    home = gcs.recv(["HOME_POSITION"], 5.0)  # unasked, once, when the estimator has an origin
    assert home is not None and any(m.get_type() == "GPS_GLOBAL_ORIGIN" for m in gcs.seen)
    using = gcs.recv(["STATUSTEXT"], 5.0, lambda m: m.text == "EKF3 IMU0 is using GPS")
    assert using is not None
    assert gcs.recv(["EKF_STATUS_REPORT"], 2.0, lambda m: m.flags == 0x33F) is not None
    texts = [m.text for m in gcs.seen if m.get_type() == "STATUSTEXT"]
    for said in ("GPS 1: detected u-blox", "EKF3 IMU0 origin set", "EKF3 IMU0 is using GPS"):
        assert said in texts, texts


@pytest.mark.timeout(60)
def test_arming_and_mode_refusals_say_what_sitl_says(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "200", "--speedup", "40", "--disarm-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    assert gcs.recv(["STATUSTEXT"], 5.0, lambda m: m.text == "EKF3 IMU0 origin set") is not None
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED  # STABILIZE needs no position
    assert gcs.set_mode(3) == M.MAV_RESULT_FAILED
    assert gcs.recv(["STATUSTEXT"], 2.0, lambda m: m.text == "Mode change to AUTO failed: requires position")
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED
    assert gcs.set_mode(3) == M.MAV_RESULT_ACCEPTED  # disarmed: any mode
    assert gcs.arm() == M.MAV_RESULT_FAILED
    said = [m.text for m in gcs.seen if m.get_type() == "STATUSTEXT"] + [
        m.text for m in iter(lambda: gcs.recv(["STATUSTEXT"], 0.5), None)]
    assert "Arm: Need Position Estimate" in said and "Arm: Mode requires mission" in said, said


@pytest.mark.timeout(30)
def test_parameters_and_fence_bits(vehicle, gcs_factory) -> None:
    _, port = vehicle("--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.conn.mav.param_request_read_send(1, 1, b"WPNAV_SPEED", -1)
    by_name = gcs.recv(["PARAM_VALUE"], 2.0)
    assert by_name.param_id == "WPNAV_SPEED" and by_name.param_index == 65535 and by_name.param_value > 0
    gcs.conn.mav.param_request_read_send(1, 1, b"", 0)
    by_index = gcs.recv(["PARAM_VALUE"], 2.0)
    assert by_index.param_id == "SYSID_THISMAV" and by_index.param_index == 0 and by_index.param_value == 1
    gcs.conn.mav.param_request_read_send(1, 1, b"NO_SUCH_PARAM", -1)
    assert gcs.recv(["PARAM_VALUE"], 0.5) is None  # unknown: no answer, as on ArduPilot
    gcs.conn.mav.param_request_list_send(1, 1)
    first = gcs.recv(["PARAM_VALUE"], 2.0)
    names = [first.param_id] + [m.param_id for m in iter(lambda: gcs.recv(["PARAM_VALUE"], 0.5), None)]
    assert len(names) == first.param_count and "MIS_TOTAL" in names
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_SYS_STATUS) == M.MAV_RESULT_ACCEPTED
    status = gcs.recv(["SYS_STATUS"], 2.0)
    fence = M.MAV_SYS_STATUS_GEOFENCE
    # Present and healthy but not enabled (FENCE_ENABLE 0), as on SITL: no "fence breach".
    assert status.onboard_control_sensors_present & fence and status.onboard_control_sensors_health & fence
    assert not status.onboard_control_sensors_enabled & fence


def test_failing_prearm_checks_are_reported_every_30_s() -> None:
    from sim_bridge.vehicle import Mode, Vehicle, VehicleConfig

    now = [100.0]
    vehicle = Vehicle(VehicleConfig(url="udpin:127.0.0.1:0", gps_delay_s=400.0), clock=lambda: now[0])
    sent: list = []
    vehicle._send_to = lambda message, peer: sent.append(message)  # type: ignore[method-assign]
    try:
        assert vehicle.flight.set_mode(Mode.GUIDED) is None
        for _ in range(2):
            now[0] += 29.0
            vehicle.tick()
            texts = [m.text for m in sent if m.get_type() == "STATUSTEXT"]
            assert not any(t.startswith("PreArm") for t in texts)
            now[0] += 1.5
            vehicle.tick()
            texts = [m.text for m in sent if m.get_type() == "STATUSTEXT"]
            assert texts.count("PreArm: AHRS: waiting for home") == 1
            sent.clear()
    finally:
        vehicle.link.close()


def test_px4_rates_are_simulated_time_scaled_by_the_speedup_and_capped() -> None:
    from sim_bridge.vehicle.streams import PeerStreams

    # PX4 SITL at speed 5 sends SYS_STATUS (5 Hz of its time) 25 times a wall second.
    fast = PeerStreams("px4", speedup=5.0, max_hz=50.0)
    assert fast.intervals[M.MAVLINK_MSG_ID_SYS_STATUS] == pytest.approx(1 / 25)
    assert fast.intervals[M.MAVLINK_MSG_ID_HEARTBEAT] == pytest.approx(1 / 5)
    assert fast.intervals[M.MAVLINK_MSG_ID_ATTITUDE] == pytest.approx(1 / 50)  # 500 Hz, capped
    assert fast.set_interval(M.MAVLINK_MSG_ID_BATTERY_STATUS, 1_000_000)  # 1 s of its time
    assert fast.intervals[M.MAVLINK_MSG_ID_BATTERY_STATUS] == pytest.approx(0.2)
    # ArduPilot's stay in wall time.
    ap = PeerStreams("ardupilot", speedup=5.0, max_hz=50.0)
    assert ap.set_interval(M.MAVLINK_MSG_ID_BATTERY_STATUS, 1_000_000)
    assert ap.intervals[M.MAVLINK_MSG_ID_BATTERY_STATUS] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="max_hz"):
        PeerStreams("px4", speedup=5.0, max_hz=0.0)
