"""MAVLink 2 extension fields the pymavlink dialect in use does not know: read from the
message's payload bytes. pymavlink 2.4.50's dialects stop MISSION_CURRENT at
``mission_mode`` and MISSION_ACK/MISSION_COUNT at ``mission_type``, but keep the frame, and
a MAVLink 2 sender trims only trailing zeros, so a field the frame does not reach is 0."""

from __future__ import annotations

from typing import Any

MISSION_CURRENT_ID_OFFSET = 6
"""``mission_id`` (uint32) in MISSION_CURRENT's payload: after seq, total (uint16 each),
mission_state, mission_mode (uint8 each)."""
MISSION_ACK_ID_OFFSET = 4
"""``opaque_id`` (uint32) in MISSION_ACK's payload: after target_system, target_component,
type, mission_type (uint8 each)."""
MISSION_COUNT_ID_OFFSET = 5
"""``opaque_id`` (uint32) in MISSION_COUNT's payload: after count (uint16), target_system,
target_component, mission_type (uint8 each)."""


def extension_u32(msg: Any, name: str, offset: int) -> int:
    """Field ``name`` of ``msg``: pymavlink's own when its dialect knows it, else the
    little-endian uint32 at ``offset`` of the payload (0 where the frame ends before it)."""
    known = getattr(msg, name, None)
    if known is not None:
        return int(known)
    buf = bytes(msg.get_msgbuf() or b"")
    if len(buf) < 10 or buf[0] != 0xFD:  # MAVLink 1 has no extensions
        return 0
    payload = buf[10:10 + buf[1]]
    return int.from_bytes(payload[offset:offset + 4].ljust(4, b"\0"), "little")
