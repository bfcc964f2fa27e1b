"""A small pymavlink ground station for the tests: the GCS side of the mission protocol
with its own retries, commands with COMMAND_ACK, and waiting for messages."""

from __future__ import annotations

import os
import time
from typing import Any, Callable, Sequence

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from protocol.geodesy import GeoOrigin  # noqa: E402
from protocol.mission import HoverPoint, MissionItem, encode_path, same_mission  # noqa: E402
from protocol.signing import Signer  # noqa: E402
from sim_bridge.vehicle.stored_items import ardupilot_stored  # noqa: E402

M = mavutil.mavlink
TELEMETRY = (
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED, M.MAVLINK_MSG_ID_SYS_STATUS,
    M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_MISSION_CURRENT,
)
"""What a test usually asks an ArduPilot-flavour vehicle to stream (it streams nothing unasked)."""


def as_stored(items: Sequence[MissionItem], flavour: str) -> list[MissionItem]:
    """What the vehicle reads back after an upload of ``items``: ArduPilot's storage
    (frames, whole-second holds, no NaN) with home in item 0; PX4 keeps what was sent."""
    if flavour != "ardupilot":
        return list(items)
    home = items[0]
    return [MissionItem(seq=0, frame=M.MAV_FRAME_GLOBAL, command=M.MAV_CMD_NAV_WAYPOINT, x=home.x, y=home.y,
                        z=home.z)] + [ardupilot_stored(item) for item in items[1:]]


def ten_items(flavour: str = "ardupilot") -> list[MissionItem]:
    """A 10-item mission: (home), takeoff, waypoints with holds, return to launch."""
    count = 8 if flavour == "ardupilot" else 9
    points = [HoverPoint(30.0 + 50.0 * i, 450.0 - 45.0 * i, 60.0 + 5.0 * (i % 3), 4.0 + i) for i in range(count - 1)]
    items = encode_path(points, GeoOrigin(), flavour)
    assert len(items) == 10
    return items


class GcsError(RuntimeError):
    """A ground-station operation failed; says which and how."""


class GroundStation:
    """pymavlink as a ground station (system 255, component 190); with ``signer`` every
    message it sends is signed and only correctly signed ones are received."""

    def __init__(self, url: str, timeout_s: float = 0.3, retries: int = 30, signer: Signer | None = None) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=255, source_component=190)
        if signer is not None:
            signer.attach(self.conn.mav)
        self.timeout_s = timeout_s
        self.retries = retries
        self.target = (1, 1)
        self.flavour = "ardupilot"
        """The vehicle's autopilot, from its HEARTBEAT (``wait_vehicle``)."""
        self.seen: list[Any] = []
        """Every message received, in order (for assertions on telemetry)."""

    def close(self) -> None:
        self.conn.close()

    def recv(self, types: Sequence[str] | None, timeout_s: float,
             where: Callable[[Any], bool] = lambda m: True) -> Any | None:
        """The next message of one of ``types`` passing ``where``, or None after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.05))
            if msg is None:
                continue
            if msg.get_type() == "BAD_DATA":
                continue
            self.seen.append(msg)
            if (types is None or msg.get_type() in types) and where(msg):
                return msg

    def wait_vehicle(self, timeout_s: float = 10.0) -> Any:
        """Send heartbeats until the vehicle answers with its own."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            hb = self.recv(["HEARTBEAT"], 0.2)
            if hb is not None:
                self.target = (hb.get_srcSystem(), hb.get_srcComponent())
                self.flavour = "px4" if hb.autopilot == M.MAV_AUTOPILOT_PX4 else "ardupilot"
                return hb
        raise GcsError("no heartbeat from the vehicle")

    def ask(self, msg_ids: Sequence[int] = TELEMETRY, interval_s: float = 0.1) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL for each message (an ArduPilot link streams nothing
        until asked)."""
        for msg_id in msg_ids:
            result = self.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_s * 1e6)
            if result != M.MAV_RESULT_ACCEPTED:
                raise GcsError(f"SET_MESSAGE_INTERVAL {msg_id}: result {result}")

    def start_mission(self, flavour: str = "ardupilot") -> int:
        """AUTO, then MAV_CMD_MISSION_START (ArduPilot's AUTO waits for it on the ground)."""
        result = self.set_mode(3) if flavour == "ardupilot" else self.set_mode(4, 4)
        if result != M.MAV_RESULT_ACCEPTED:
            return result
        return self.command(M.MAV_CMD_MISSION_START, 0, 0)

    # --- mission protocol ---------------------------------------------------------------------
    def upload(self, items: Sequence[MissionItem]) -> int:
        """Upload ``items``; returns the MISSION_ACK result. Retries on silence. Where the
        last item had to be sent again (its ACK lost, or the item) and the answer is not
        ACCEPTED, the outcome is not known from the answer: ArduPilot answers an item after
        the upload ended with MAV_MISSION_ERROR whether or not it took the mission. The
        mission is then read back: ACCEPTED if the vehicle holds ``items``."""
        sys_id, comp_id = self.target
        count = len(items)
        self.conn.mav.mission_count_send(sys_id, comp_id, count, M.MAV_MISSION_TYPE_MISSION)
        last_sent: int | None = None
        last_again = False
        silent = 0
        while silent <= self.retries:
            msg = self.recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], self.timeout_s)
            if msg is None:
                silent += 1
                if last_sent is None:
                    self.conn.mav.mission_count_send(sys_id, comp_id, count, M.MAV_MISSION_TYPE_MISSION)
                else:
                    self.conn.mav.send(items[last_sent].to_message(sys_id, comp_id))
                    last_again = last_sent == count - 1
                continue
            if msg.get_type() == "MISSION_ACK":
                if last_sent is None and msg.type == M.MAV_MISSION_ACCEPTED and count:
                    continue  # a stale ACK of an earlier operation
                if msg.type == M.MAV_MISSION_INVALID_SEQUENCE and last_sent is not None:
                    # ArduPilot's answer to an item sent twice (our repeat crossed its
                    # request): the upload goes on (MissionItemProtocol::handle_mission_item).
                    continue
                if last_again and msg.type != M.MAV_MISSION_ACCEPTED:
                    return M.MAV_MISSION_ACCEPTED if same_mission(self.download(), items, self.flavour) else int(msg.type)
                return int(msg.type)
            if not 0 <= msg.seq < count:
                raise GcsError(f"vehicle requested item {msg.seq} of {count}")
            silent = 0
            self.conn.mav.send(items[msg.seq].to_message(sys_id, comp_id))
            last_sent = msg.seq
        raise GcsError(f"upload: no answer after {self.retries} retries (last item sent {last_sent})")

    def download(self) -> list[MissionItem]:
        sys_id, comp_id = self.target
        count_msg = None
        for _ in range(self.retries):
            self.conn.mav.mission_request_list_send(sys_id, comp_id, M.MAV_MISSION_TYPE_MISSION)
            count_msg = self.recv(["MISSION_COUNT"], self.timeout_s)
            if count_msg is not None:
                break
        if count_msg is None:
            raise GcsError("download: no MISSION_COUNT")
        items: list[MissionItem] = []
        for seq in range(count_msg.count):
            for _ in range(self.retries):
                self.conn.mav.mission_request_int_send(sys_id, comp_id, seq, M.MAV_MISSION_TYPE_MISSION)
                msg = self.recv(["MISSION_ITEM_INT"], self.timeout_s, lambda m, s=seq: m.seq == s)
                if msg is not None:
                    items.append(MissionItem.from_message(msg))
                    break
            else:
                raise GcsError(f"download: no item {seq}")
        self.conn.mav.mission_ack_send(sys_id, comp_id, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
        return items

    # --- commands ---------------------------------------------------------------------------------
    def command(self, command: int, *params: float) -> int:
        """COMMAND_LONG with retries (confirmation counts up); returns the COMMAND_ACK result."""
        sys_id, comp_id = self.target
        p = list(params) + [0.0] * (7 - len(params))
        for confirmation in range(self.retries):
            self.conn.mav.command_long_send(sys_id, comp_id, command, confirmation, *p)
            ack = self.recv(["COMMAND_ACK"], self.timeout_s, lambda m: m.command == command)
            if ack is not None:
                return int(ack.result)
        raise GcsError(f"command {command}: no COMMAND_ACK")

    def set_mode(self, custom_mode: int, sub_mode: int = 0) -> int:
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom_mode, sub_mode)

    def arm(self) -> int:
        return self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)
