"""What an autopilot keeps of an uploaded mission item, and which items it refuses.

ArduPilot converts each MISSION_ITEM_INT into its own storage format and converts it back
on a download (``libraries/AP_Mission/AP_Mission.cpp``: ``sanity_check_params``,
``mavlink_int_to_mission_cmd``, ``mission_cmd_to_mavlink_int``), so a read-back differs
from the upload: a relative frame comes back as MAV_FRAME_GLOBAL_RELATIVE_ALT (3), an
absolute one as MAV_FRAME_GLOBAL (0), a command without a position in frame 0 with x, y, z
0; Copter keeps a waypoint's param1 (the hold) as a uint16, so 46.117 s is stored, flown
and read back as 46 s, and drops its param2..4 (NaN comes back as 0); the altitude is kept
in whole centimetres. Checked on ArduCopter SITL V4.7.0-dev (docs/VEHICLE.md).

PX4 keeps what was sent (``src/modules/mavlink/mavlink_mission.cpp``: the item is stored
with its own frame and read back with ``format_mavlink_mission_item``).
"""

from __future__ import annotations

import math
import struct

from pymavlink.dialects.v20 import common as mavlink

from protocol.mission import MissionItem, f32

M = mavlink
Problem = tuple[int, str]
"""(MAV_MISSION_RESULT, why) for an item the autopilot refuses."""

FLOWN = frozenset({
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND,
    M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_CMD_NAV_DELAY,
})
"""Commands the stub flies."""
NO_OPS = frozenset({
    M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_DO_SET_ROI_NONE, M.MAV_CMD_DO_SET_ROI_LOCATION,
    M.MAV_CMD_DO_MOUNT_CONTROL, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
    M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_CMD_IMAGE_STOP_CAPTURE,
    M.MAV_CMD_VIDEO_START_CAPTURE, M.MAV_CMD_VIDEO_STOP_CAPTURE,
    M.MAV_CMD_DO_SET_CAM_TRIGG_DIST, M.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL,
})
"""Accepted and completed at once: they change a camera, gimbal or speed, not the path."""
SUPPORTED_COMMANDS = FLOWN | NO_OPS

# Commands whose x, y, z are a position (AP_Mission::stored_in_location).
LOCATED = frozenset({
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LAND,
    M.MAV_CMD_DO_SET_ROI_LOCATION,
})
NAV_COMMANDS = FLOWN
"""Navigation commands (ArduPilot's ``is_nav_cmd``: ids up to MAV_CMD_NAV_LAST, 95)."""

RELATIVE = frozenset({M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT})
ABSOLUTE = frozenset({M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_MISSION})
PX4_FRAMES = frozenset(RELATIVE | {M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_MISSION})
LOCATION_ALT_MAX_M = 83_000.0
"""ArduPilot refuses |z| at or above this (AP_Common Location: 24-bit centimetres)."""
_PARAM_RESULTS = (M.MAV_MISSION_INVALID_PARAM1, M.MAV_MISSION_INVALID_PARAM2,
                  M.MAV_MISSION_INVALID_PARAM3, M.MAV_MISSION_INVALID_PARAM4)
_NAN_PARAM4_OK = frozenset({M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_TAKEOFF})


def _lat_lon_problem(item: MissionItem) -> Problem | None:
    if not -900_000_000 <= item.x <= 900_000_000:
        return M.MAV_MISSION_INVALID_PARAM5_X, "latitude out of range"
    if not -1_800_000_000 <= item.y <= 1_800_000_000:
        return M.MAV_MISSION_INVALID_PARAM6_Y, "longitude out of range"
    return None


def ardupilot_problem(item: MissionItem) -> Problem | None:
    """ArduPilot's refusal of one item, as AP_Mission answers it (None: accepted)."""
    if item.command not in SUPPORTED_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED, f"command {item.command} is not supported"
    params = (item.param1, item.param2, item.param3, item.param4)
    for i, (value, result) in enumerate(zip(params, _PARAM_RESULTS)):
        nan_ok = i == 3 and item.command in _NAN_PARAM4_OK
        if math.isinf(value) or (math.isnan(value) and not nan_ok):
            return result, f"param{i + 1} is {value}"
    if item.command in LOCATED:
        problem = _lat_lon_problem(item)
        if problem is not None:
            return problem
        if math.isnan(item.z) or abs(item.z) >= LOCATION_ALT_MAX_M:
            return M.MAV_MISSION_INVALID_PARAM7, f"altitude {item.z} is not valid"
        if item.frame not in RELATIVE | ABSOLUTE:
            return M.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {item.frame} is not supported"
    return None


def px4_problem(item: MissionItem) -> Problem | None:
    """PX4's refusal of one item (parse_mavlink_mission_item): frames and commands; NaN is
    accepted where MAVLink gives it a meaning."""
    if item.frame not in PX4_FRAMES:
        return M.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {item.frame} is not supported"
    if item.command not in SUPPORTED_COMMANDS:
        return M.MAV_MISSION_UNSUPPORTED, f"command {item.command} is not supported"
    for i, (value, result) in enumerate(zip((item.param1, item.param2, item.param3), _PARAM_RESULTS)):
        if math.isinf(value):
            return result, f"param{i + 1} is infinite"
    positional = item.command in FLOWN - {M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_CMD_NAV_DELAY}
    if math.isinf(item.z) or (positional and math.isnan(item.z)):
        return M.MAV_MISSION_INVALID_PARAM7, "z is not finite"
    if item.frame != M.MAV_FRAME_MISSION:
        problem = _lat_lon_problem(item)
        if problem is not None:
            return problem
    if item.command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_TIME) and item.param1 < 0:
        return M.MAV_MISSION_INVALID_PARAM1, "hold time is negative"
    return None


def _uint16(value: float) -> int:
    """C's float -> uint16_t as ArduPilot's ``cmd.p1 = packet.param1`` does it on the
    usual targets: truncation toward zero, then the low 16 bits."""
    if not math.isfinite(value):
        return 0
    return int(value) & 0xFFFF


def _uint8(value: float) -> int:
    return int(value) & 0xFF if math.isfinite(value) else 0


def _centimetres(z: float) -> float:
    """An altitude through ArduPilot's int32 centimetres: ``alt = z * 100.0f`` (truncated),
    read back as ``alt * 0.01f``."""
    cm = int(f32(f32(z) * 100.0))
    return f32(cm * f32(0.01))


def ardupilot_stored(item: MissionItem) -> MissionItem:
    """``item`` as ArduCopter reads it back (call only on an item it accepted)."""
    command = item.command
    p1 = p2 = p3 = p4 = 0.0
    if command in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF):
        p1 = float(_uint16(item.param1))
    elif command == M.MAV_CMD_NAV_LOITER_TIME:
        p1 = float(_uint16(item.param1))
        p3 = -1.0 if item.param3 < 0 else 1.0
        p4 = 1.0 if item.param4 > 0 else 0.0
    elif command == M.MAV_CMD_NAV_LAND:
        p1 = float(_uint16(item.param1))
        # Read back as the yaw direction: -1 if param4 was negative, 1 otherwise (NaN too).
        p4 = -1.0 if (math.isfinite(item.param4) and item.param4 < 0) else 1.0
    elif command == M.MAV_CMD_NAV_DELAY:
        p1 = f32(item.param1)
        p2, p3, p4 = float(_uint8(item.param2)), float(_uint8(item.param3)), float(_uint8(item.param4))
    elif command == M.MAV_CMD_DO_CHANGE_SPEED:
        p1, p2, p3 = float(_uint8(item.param1)), f32(item.param2), float(_uint8(item.param3))
    elif command not in (M.MAV_CMD_NAV_RETURN_TO_LAUNCH,):
        p1, p2, p3, p4 = (f32(v) if math.isfinite(v) else 0.0
                          for v in (item.param1, item.param2, item.param3, item.param4))
    if command in LOCATED:
        frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT if item.frame in RELATIVE else M.MAV_FRAME_GLOBAL
        x, y, z = item.x, item.y, _centimetres(item.z)
    else:
        frame, x, y, z = M.MAV_FRAME_GLOBAL, 0, 0, 0.0
    return MissionItem(seq=item.seq, frame=frame, command=command, current=0, autocontinue=1,
                       param1=p1, param2=p2, param3=p3, param4=p4, x=x, y=y, z=z)


def crc_of(items: list[MissionItem]) -> int:
    """A fingerprint of a whole mission (PX4 updates its active mission only when the CRC of
    an upload differs from the one it holds)."""
    import zlib

    crc = 0
    for item in items:
        values = [item.param1, item.param2, item.param3, item.param4, item.z]
        crc = zlib.crc32(struct.pack("<3H5f2i", item.command, item.frame, item.autocontinue,
                                     *(math.nan if math.isnan(v) else f32(v) for v in values),
                                     item.x, item.y), crc)
    return crc
