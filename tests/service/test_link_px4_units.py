"""What the link learnt from PX4 SITL, in milliseconds: PX4's unasked streams stopped first
on every (re)connection, and the several messages PX4 packs into one UDP datagram all
handed on at once (docs/VEHICLE.md, "The link against PX4 SITL")."""

from __future__ import annotations

import os
import socket
import time

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner_service.harness.processes import free_port  # noqa: E402
from planner_service.service.link.mavlink_link import _buffered  # noqa: E402
from planner_service.service.link.streams import QUIET_INTERVAL_US, Streams, quiet_plan, stream_plan  # noqa: E402

M = mavutil.mavlink


def test_px4s_unused_streams_are_stopped_before_anything_is_asked_and_ardupilots_are_none() -> None:
    requests = Streams(stream_plan("px4"), quiet=quiet_plan("px4")).begin()
    kinds = [r.kind for r in requests]
    quiet = [r.spec.name for r in requests if r.kind == "quiet"]
    assert kinds == sorted(kinds, key=lambda k: k != "quiet"), kinds  # stopped first
    assert {"ATTITUDE", "HIGHRES_IMU", "ATTITUDE_QUATERNION", "LOCAL_POSITION_NED"} <= set(quiet), quiet
    assert not set(quiet) & {s.name for s in stream_plan("px4")}  # nothing the link reads
    assert all(r.spec.interval_s * 1e6 == QUIET_INTERVAL_US == -1 for r in requests if r.kind == "quiet")
    assert [r.kind for r in Streams(stream_plan("ardupilot"), quiet=quiet_plan("ardupilot")).begin()] == [
        "interval"] * len(stream_plan("ardupilot"))


def test_every_message_of_a_datagram_is_taken_at_once() -> None:
    """PX4 sends several messages per datagram; pymavlink parses one per read."""
    port = free_port(socket.SOCK_DGRAM)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    sender = mavutil.mavlink.MAVLink(None, srcSystem=2, srcComponent=1)
    datagram = b"".join(sender.heartbeat_encode(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_PX4, 0, 0, 0).pack(sender)
                        for _ in range(3)) + sender.mission_ack_encode(255, 190, 0).pack(sender)
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        out.sendto(datagram, ("127.0.0.1", port))
        deadline = time.monotonic() + 5.0
        first = None
        while first is None and time.monotonic() < deadline:
            first = conn.recv_match(blocking=True, timeout=0.1)
        assert first is not None and first.get_type() == "HEARTBEAT"
        rest = _buffered(conn)
        assert [m.get_type() for m in rest] == ["HEARTBEAT", "HEARTBEAT", "MISSION_ACK"]
        assert _buffered(conn) == []
    finally:
        out.close()
        conn.close()


def test_a_repeated_mission_item_reached_is_news_once() -> None:
    from planner_service.service.link.state import VehicleState

    state = VehicleState("px4", lambda ev: None)
    assert [state.new_reach(1, 0), state.new_reach(1, 0), state.new_reach(1, 1), state.new_reach(1, 1)] == [
        True, False, True, False]
    assert not state.new_reach(2, 1)  # a repeat sorted to the next mission (sent after its ACK)
    assert state.new_reach(2, 0) and state.new_reach(2, 1)  # flown again after another item
