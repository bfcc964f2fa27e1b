"""Garbage for a MAVLink link, reproducible from a seed: random bytes, truncated frames,
frames with a flipped CRC or payload byte, MAVLink 1 frames, frames for another system,
oversized datagrams, and valid read-only frames with garbage between them.

The spoiled frames are of messages that would change a vehicle's state if they got
through (arm, take off, set mode, clear or replace the mission), so "no state change"
after them is a real test of the parser's checks, not of harmless noise.
"""

from __future__ import annotations

import os
import random
from typing import Any, Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v10 import common as v1  # noqa: E402
from pymavlink.dialects.v20 import common as v2  # noqa: E402

MAX_UDP_PAYLOAD = 65507
"""The largest datagram IPv4 carries."""
OTHER_SYSTEM = 42


def _frame(msg: Any, dialect: Any, system: int = 255, component: int = 190) -> bytes:
    return bytes(msg.pack(dialect.MAVLink(None, srcSystem=system, srcComponent=component)))


def state_changing(dialect: Any, target: int, target_component: int = 1) -> list[Any]:
    """Messages that would arm, move, re-mode or re-mission the vehicle ``target``."""
    m = dialect
    t, c = target, target_component
    messages = [
        m.MAVLink_command_long_message(t, c, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 21196, 0, 0, 0, 0, 0),
        m.MAVLink_command_long_message(t, c, m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 30),
        m.MAVLink_command_long_message(t, c, m.MAV_CMD_DO_SET_MODE, 0, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 0,
                                       0, 0, 0, 0),
        m.MAVLink_set_mode_message(t, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6),
        m.MAVLink_mission_set_current_message(t, c, 2),
    ]
    if dialect is v2:
        messages += [
            m.MAVLink_mission_clear_all_message(t, c, m.MAV_MISSION_TYPE_MISSION),
            m.MAVLink_mission_count_message(t, c, 2, m.MAV_MISSION_TYPE_MISSION),
        ]
    else:
        messages += [m.MAVLink_mission_clear_all_message(t, c), m.MAVLink_mission_count_message(t, c, 2)]
    return messages


def telemetry_changing(system: int = 1) -> list[bytes]:
    """Frames from the autopilot ``system`` that would change what a ground station shows:
    armed in AUTO, airborne, elsewhere, battery low, at another mission item."""
    m = v2
    frames = [
        m.MAVLink_heartbeat_message(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                    m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | m.MAV_MODE_FLAG_SAFETY_ARMED, 3,
                                    m.MAV_STATE_ACTIVE, 3),
        m.MAVLink_global_position_int_message(5000, 473990000, 85480000, 588000, 100000, 100, 0, 0, 0),
        m.MAVLink_extended_sys_state_message(0, m.MAV_LANDED_STATE_IN_AIR),
        m.MAVLink_sys_status_message(0, 0, 0, 500, 14000, -1, 5, 0, 0, 0, 0, 0, 0),
        m.MAVLink_battery_status_message(0, 0, 0, 2000, [3500] * 10, -1, 500, -1, 5),
        m.MAVLink_mission_current_message(4, 9),
        m.MAVLink_mission_item_reached_message(3),
        m.MAVLink_statustext_message(m.MAV_SEVERITY_CRITICAL, b"garbage got through"),
    ]
    return [_frame(msg, v2, system, 1) for msg in frames]


def read_only_frames() -> list[bytes]:
    """Valid MAVLink 2 frames a ground station may send that change nothing."""
    return [
        _frame(v2.MAVLink_heartbeat_message(v2.MAV_TYPE_GCS, v2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3), v2),
        _frame(v2.MAVLink_mission_request_list_message(1, 1, v2.MAV_MISSION_TYPE_MISSION), v2),
        _frame(v2.MAVLink_param_request_list_message(1, 1), v2),
    ]


def _flip(rng: random.Random, frame: bytes, lo: int, hi: int) -> bytes:
    i = rng.randrange(lo, hi)
    return frame[:i] + bytes([frame[i] ^ (1 << rng.randrange(8))]) + frame[i + 1:]


def chunks(seed: int, target: int = 1, spoil: list[bytes] | None = None) -> Iterator[tuple[str, bytes]]:
    """(what, bytes) pieces of garbage for the vehicle ``target``, each to be sent alone
    (a datagram) or concatenated (a TCP stream). The frames spoiled are ``spoil``
    (default: commands and mission messages to ``target``)."""
    rng = random.Random(seed)
    ours = spoil if spoil is not None else [_frame(msg, v2) for msg in state_changing(v2, target)]
    for size in (0, 1, 2, 7, 11, 12, 280, 281, 1500, 4096):
        yield "random", rng.randbytes(size)
    yield "start bytes", bytes(rng.choice((0xFD, 0xFE)) for _ in range(600))
    yield "lying length", b"\xfd\xff" + rng.randbytes(40)
    for frame in ours:
        for cut in range(1, len(frame)):
            yield "truncated", frame[:cut]
        yield "crc flipped", _flip(rng, frame, len(frame) - 2, len(frame))
        yield "payload flipped", _flip(rng, frame, 10, len(frame) - 2)
        yield "header flipped", _flip(rng, frame, 1, 10)
    for frame in read_only_frames():  # a stray start byte before a valid frame: resync
        yield "doubled start", b"\xfd" + frame
    # MAVLink 1: valid frames for another system, spoiled frames for ours, a GCS heartbeat.
    for msg in state_changing(v1, OTHER_SYSTEM):
        yield "v1 other system", _frame(msg, v1)
    for msg in state_changing(v1, target):
        frame = _frame(msg, v1)
        yield "v1 crc flipped", _flip(rng, frame, len(frame) - 2, len(frame))
        yield "v1 truncated", frame[:rng.randrange(1, len(frame))]
    yield "v1 heartbeat", _frame(v1.MAVLink_heartbeat_message(v1.MAV_TYPE_GCS, v1.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3), v1)
    # Valid MAVLink 2 for another system: must be ignored, not obeyed.
    for msg in state_changing(v2, OTHER_SYSTEM):
        yield "v2 other system", _frame(msg, v2)
    yield "oversized", rng.randbytes(MAX_UDP_PAYLOAD)
    yield "oversized frames", b"".join(_flip(rng, f, len(f) - 2, len(f)) for f in ours * 400)[:MAX_UDP_PAYLOAD]
    valid = read_only_frames()
    mixed = b"".join(rng.choice(valid) + rng.randbytes(rng.randrange(0, 40)) + _flip(rng, rng.choice(ours), 1, 10)
                     for _ in range(50))
    yield "valid between garbage", mixed


def random_frames(seed: int, count: int, target: int = 1, spoil: list[bytes] | None = None) -> Iterator[bytes]:
    """``count`` spoiled copies of state-changing frames (``spoil``, as in ``chunks``), each
    with 1-3 random byte edits (the CRC covers every byte after the start byte)."""
    rng = random.Random(seed)
    ours = spoil if spoil is not None else [_frame(msg, v2) for msg in state_changing(v2, target)]
    for _ in range(count):
        frame = bytearray(rng.choice(ours))
        for _ in range(rng.randint(1, 3)):
            i = rng.randrange(len(frame))
            frame[i] = (frame[i] + rng.randrange(1, 256)) % 256
        yield bytes(frame)
