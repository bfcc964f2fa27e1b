"""The same scripted checks against the vehicle stub and against ArduCopter SITL (marker
``sitl``), so the stub is held to what the real autopilot does.

A pymavlink ground station over TCP checks: nothing is streamed before it asks;
SET_MESSAGE_INTERVAL is acknowledged and obeyed; EXTENDED_SYS_STATE comes only on request;
there is no position at first and arming in a position mode is refused then; an upload
reads back as ArduPilot stores it (frames, whole-second holds, home at item 0); an upload
in flight keeps the current index and restarts the command there.

SITL comes from the shared harness (``tests/support/sitl.py``: ``ARDUPILOT_SITL`` or the
shared binary, its own temporary folder, SIGTERM at the end; skipped without the binary) on
this file's instance numbers 22-29; the ground station uses its SERIAL1 (the harness keeps
SERIAL0). Rates are not compared: SITL's are simulated time (ten times faster at
``--speedup 10``), the stub's wall time (docs/VEHICLE.md).
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import pytest

from planner_service.harness.processes import free_port
from protocol.geodesy import GeoOrigin
from protocol.mission import MissionItem
from tests.support.gcs import M, GroundStation
from tests.support.sitl import Sitl, free_instance

REPO = Path(__file__).resolve().parents[2]
ORIGIN = GeoOrigin()
SPEEDUP = 10
SITL_INSTANCES = range(22, 30)
"""This file's SITL instance numbers (ports 5980-6050): the first free one is used."""
TARGETS = ["stub", pytest.param("sitl", marks=pytest.mark.sitl)]
STREAMED = {"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "SYS_STATUS", "ATTITUDE", "GPS_RAW_INT",
            "EXTENDED_SYS_STATE", "MISSION_CURRENT", "BATTERY_STATUS", "VFR_HUD", "EKF_STATUS_REPORT"}
DLAT = 1e7 / 111_132.0
DLON = 1e7 / (111_320.0 * math.cos(math.radians(ORIGIN.lat_deg)))
LAT, LON = round(ORIGIN.lat_deg * 1e7), round(ORIGIN.lon_deg * 1e7)


@dataclass
class Autopilot:
    kind: str
    url: str
    stop: Callable[[], None]


def start_stub(tmp: Path) -> Autopilot:
    port = free_port()
    log_path = tmp / "stub.log"
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    with open(log_path, "w") as log:
        proc = subprocess.Popen([sys.executable, "-m", "sim_bridge", "vehicle", "--mavlink", f"tcpin:127.0.0.1:{port}",
                                 "--speedup", str(SPEEDUP)], cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=log)
    deadline = time.monotonic() + 20
    while "listening" not in log_path.read_text():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the stub did not start:\n{log_path.read_text()}")
        time.sleep(0.05)

    def stop() -> None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)

    return Autopilot("stub", f"tcp:127.0.0.1:{port}", stop)


def start_sitl(make_sitl: Callable[..., Sitl], speedup: int) -> Autopilot:
    """SITL from the shared harness (tests/support/sitl.py: its own folder, SIGTERM at the
    end), on one of this file's instance numbers; the ground station uses SERIAL1."""
    sitl = make_sitl(instance=free_instance(SITL_INSTANCES), speedup=speedup)
    return Autopilot("sitl", sitl.url(1), lambda: None)  # make_sitl stops it


@pytest.fixture(params=TARGETS)
def autopilot(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Autopilot]:
    if request.param == "sitl":
        # SITL starts its clock when the harness connects: a slower one leaves time to see
        # its first seconds without a position.
        speedup = 2 if "no_position" in request.node.name else SPEEDUP
        yield start_sitl(request.getfixturevalue("make_sitl"), speedup)
        return
    target = start_stub(tmp_path)
    try:
        yield target
    finally:
        target.stop()


@pytest.fixture
def gcs(autopilot: Autopilot) -> Iterator[GroundStation]:
    deadline = time.monotonic() + 10
    while True:
        try:
            station = GroundStation(autopilot.url, timeout_s=0.5, retries=10)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
    try:
        station.wait_vehicle()
        yield station
    finally:
        station.close()


def beat(gcs: GroundStation, seconds: float, types: set[str] | None = None) -> dict[str, int]:
    """Heartbeats for ``seconds``; the count of each message type received (or of ``types``)."""
    counts: dict[str, int] = {}
    end = time.monotonic() + seconds
    next_beat = 0.0
    while time.monotonic() < end:
        if time.monotonic() >= next_beat:
            gcs.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            next_beat = time.monotonic() + 0.5
        msg = gcs.recv(None, min(0.1, max(end - time.monotonic(), 0.0)))
        if msg is not None and msg.get_srcSystem() == 1 and (types is None or msg.get_type() in types):
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    return counts


def wait_text(gcs: GroundStation, fragment: str, seconds: float) -> str | None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        for msg in gcs.seen:
            if msg.get_type() == "STATUSTEXT" and fragment in msg.text:
                return msg.text
        gcs.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        gcs.recv(["STATUSTEXT"], 0.3, lambda m: fragment in m.text)
    return None


def texts_since(gcs: GroundStation, start: int) -> list[str]:
    return [m.text for m in gcs.seen[start:] if m.get_type() == "STATUSTEXT"]


def item(seq: int, frame: int, command: int, *, p1: float = 0.0, p4: float = 0.0, north_m: float = 0.0,
         east_m: float = 0.0, z: float = 0.0) -> MissionItem:
    return MissionItem(seq=seq, frame=frame, command=command, current=int(seq == 0), param1=p1, param4=p4,
                       x=round(LAT + north_m * DLAT), y=round(LON + east_m * DLON), z=z)


def waypoints(*points: tuple[float, float, float]) -> list[MissionItem]:
    """Home placeholder, takeoff to 20 m, waypoints (north, east, hold), return to launch."""
    r6 = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    items = [item(0, r6, M.MAV_CMD_NAV_WAYPOINT), item(1, r6, M.MAV_CMD_NAV_TAKEOFF, p4=math.nan, z=20.0)]
    for north, east, hold in points:
        items.append(item(len(items), r6, M.MAV_CMD_NAV_WAYPOINT, p1=hold, p4=math.nan, north_m=north, east_m=east,
                          z=20.0))
    items.append(item(len(items), M.MAV_FRAME_MISSION, M.MAV_CMD_NAV_RETURN_TO_LAUNCH))
    return items


def wait_for_position(gcs: GroundStation) -> None:
    assert wait_text(gcs, "EKF3 IMU0 is using GPS", 40.0), "no position estimate"


# --- the checks ---------------------------------------------------------------------------------

@pytest.mark.timeout(60)
def test_nothing_is_streamed_until_asked(autopilot: Autopilot, gcs: GroundStation) -> None:
    counts = beat(gcs, 3.0)
    assert counts.get("HEARTBEAT", 0) >= 2
    assert not STREAMED & counts.keys(), f"streamed unasked: {counts}"
    # What comes unasked: heartbeats, TIMESYNC, STATUSTEXT, and HOME_POSITION with
    # GPS_GLOBAL_ORIGIN once when home is set (SITL also sends PARAM_VALUE when it saves one).
    assert counts.keys() <= {"HEARTBEAT", "TIMESYNC", "STATUSTEXT", "HOME_POSITION", "GPS_GLOBAL_ORIGIN",
                             "PARAM_VALUE"}, counts


@pytest.mark.timeout(60)
def test_set_message_interval_is_acknowledged_and_obeyed(autopilot: Autopilot, gcs: GroundStation) -> None:
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 200_000) == \
        M.MAV_RESULT_ACCEPTED
    assert beat(gcs, 2.0, {"GLOBAL_POSITION_INT"}).get("GLOBAL_POSITION_INT", 0) >= 5
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, -1) == M.MAV_RESULT_ACCEPTED
    beat(gcs, 0.3)
    assert beat(gcs, 1.5, {"GLOBAL_POSITION_INT"}) == {}, "-1 stops the message"
    # A message the autopilot cannot send is refused.
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, 12345, 100_000) == M.MAV_RESULT_DENIED
    # One message on request: the ACK, then the message.
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_SYS_STATUS) == M.MAV_RESULT_ACCEPTED
    assert gcs.recv(["SYS_STATUS"], 2.0) is not None


@pytest.mark.timeout(60)
def test_extended_sys_state_only_on_request(autopilot: Autopilot, gcs: GroundStation) -> None:
    gcs.conn.mav.request_data_stream_send(1, 1, M.MAV_DATA_STREAM_ALL, 4, 1)
    counts = beat(gcs, 2.0)
    assert {"GLOBAL_POSITION_INT", "SYS_STATUS", "ATTITUDE"} <= counts.keys(), counts
    assert "EXTENDED_SYS_STATE" not in counts, "EXTENDED_SYS_STATE is in no stream group"
    assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 200_000) == \
        M.MAV_RESULT_ACCEPTED
    state = gcs.recv(["EXTENDED_SYS_STATE"], 2.0)
    assert state is not None and state.landed_state == M.MAV_LANDED_STATE_ON_GROUND


@pytest.mark.timeout(90)
def test_no_position_at_first_and_arming_refused_until_the_estimator_uses_gps(autopilot: Autopilot,
                                                                               gcs: GroundStation) -> None:
    for msg_id in (M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT):
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 100_000) == M.MAV_RESULT_ACCEPTED
    gps = gcs.recv(["GPS_RAW_INT"], 2.0)
    assert gps is not None and gps.fix_type < M.GPS_FIX_TYPE_3D_FIX and gps.lat == 0
    pos = gcs.recv(["GLOBAL_POSITION_INT"], 2.0)
    assert pos is not None and (pos.lat, pos.lon) == (0, 0)
    for msg_id in (M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT):
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, -1) == M.MAV_RESULT_ACCEPTED
    assert gcs.set_mode(4) == M.MAV_RESULT_ACCEPTED  # GUIDED: any mode while disarmed
    start = len(gcs.seen)
    assert gcs.arm() == M.MAV_RESULT_FAILED
    gcs.recv(["STATUSTEXT"], 1.0)
    refusals = [t for t in texts_since(gcs, start) if t.startswith("Arm: ")]
    assert refusals, f"no 'Arm: ' reason: {texts_since(gcs, start)}"

    wait_for_position(gcs)
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT) == M.MAV_RESULT_ACCEPTED
    pos = gcs.recv(["GLOBAL_POSITION_INT"], 2.0)
    assert pos is not None and abs(pos.lat - LAT) < 100 and abs(pos.lon - LON) < 100
    assert gcs.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_HOME_POSITION) == M.MAV_RESULT_ACCEPTED
    home = gcs.recv(["HOME_POSITION"], 2.0)
    assert home is not None and abs(home.latitude - LAT) < 100
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED


@pytest.mark.timeout(90)
def test_upload_reads_back_as_ardupilot_stores_it(autopilot: Autopilot, gcs: GroundStation) -> None:
    wait_text(gcs, "origin set", 15.0)
    beat(gcs, 0.5)
    held = gcs.download()
    assert len(held) == 1 and held[0].x != 0, "an empty mission holds home as item 0"
    r6, g5 = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_INT
    sent = [
        item(0, r6, M.MAV_CMD_NAV_WAYPOINT),
        item(1, r6, M.MAV_CMD_NAV_TAKEOFF, p4=math.nan, z=20.0),
        item(2, r6, M.MAV_CMD_NAV_WAYPOINT, p1=46.117, p4=math.nan, north_m=30.0, east_m=30.0, z=30.0),
        item(3, g5, M.MAV_CMD_NAV_WAYPOINT, p1=2.7, p4=math.nan, north_m=60.0, z=ORIGIN.alt_m + 30.0),
        item(4, M.MAV_FRAME_MISSION, M.MAV_CMD_NAV_RETURN_TO_LAUNCH),
    ]
    assert gcs.upload(sent) == M.MAV_MISSION_ACCEPTED
    back = gcs.download()
    assert len(back) == len(sent)
    assert [i.frame for i in back] == [0, 3, 3, 0, 0]
    assert [i.param1 for i in back] == [0.0, 0.0, 46.0, 2.0, 0.0]  # whole seconds, truncated
    assert all(i.param4 == 0.0 for i in back)  # NaN is kept as 0
    assert (back[0].x, back[0].y) == (held[0].x, held[0].y)  # item 0 is home, whatever was sent
    assert (back[4].x, back[4].y, back[4].z) == (0, 0, 0.0)
    assert gcs.upload([]) == M.MAV_MISSION_ACCEPTED
    assert gcs.download() == []


@pytest.mark.timeout(150)
def test_an_upload_in_flight_keeps_the_index_and_restarts_the_command(autopilot: Autopilot,
                                                                        gcs: GroundStation) -> None:
    wait_for_position(gcs)
    for msg_id in (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_MISSION_CURRENT):
        assert gcs.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 200_000) == M.MAV_RESULT_ACCEPTED
    mission = waypoints((40.0, 0.0, 5.0), (40.0, 40.0, 60.0), (0.0, 40.0, 5.0))
    assert gcs.upload(mission) == M.MAV_MISSION_ACCEPTED
    assert gcs.set_mode(4) == M.MAV_RESULT_ACCEPTED  # GUIDED
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20) == M.MAV_RESULT_ACCEPTED
    assert gcs.recv(["GLOBAL_POSITION_INT"], 30.0, lambda m: m.relative_alt > 18_000) is not None
    assert gcs.set_mode(3) == M.MAV_RESULT_ACCEPTED  # AUTO
    # Holding 60 s at item 3 (40 m north, 40 m east).
    assert gcs.recv(["MISSION_CURRENT"], 30.0, lambda m: m.seq == 3) is not None
    arrived = gcs.recv(["GLOBAL_POSITION_INT"], 30.0, lambda m: abs(m.lat - (LAT + 40 * DLAT)) < 30
                       and abs(m.lon - (LON + 40 * DLON)) < 30 and abs(m.vx) + abs(m.vy) < 30)
    assert arrived is not None

    start = len(gcs.seen)
    moved = waypoints((40.0, 0.0, 5.0), (60.0, 60.0, 60.0), (0.0, 40.0, 5.0))
    assert gcs.upload(moved) == M.MAV_MISSION_ACCEPTED
    assert wait_text(gcs, "Auto mission changed, restarted command", 3.0)
    current = gcs.recv(["MISSION_CURRENT"], 3.0)
    assert current is not None and current.seq == 3, "the index is kept, not reset to the first item"
    there = gcs.recv(["GLOBAL_POSITION_INT"], 30.0, lambda m: abs(m.lat - (LAT + 60 * DLAT)) < 30
                     and abs(m.lon - (LON + 60 * DLON)) < 30)
    assert there is not None, "it flies to the new item 3"
    assert "Auto mission changed but failed to restart command" not in texts_since(gcs, start)

    start = len(gcs.seen)
    assert gcs.upload(waypoints()) == M.MAV_MISSION_ACCEPTED  # home, takeoff, return: item 3 is gone
    assert wait_text(gcs, "Auto mission changed but failed to restart command", 3.0)
    assert "Auto mission changed, restarted command" not in texts_since(gcs, start)
    assert gcs.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH) == M.MAV_RESULT_ACCEPTED
