"""PX4's mission id, and the MAVLink 2 extension fields that carry it, for the stub's PX4
flavour. pymavlink 2.4.50's dialect stops MISSION_CURRENT at ``mission_mode`` and
MISSION_ACK/MISSION_COUNT at ``mission_type``: the messages here append the uint32 id.

PX4 (``MavlinkMissionManager::crc32_for_mission_item``) chains ``crc32part`` (the reflected
CRC-32 table, initial value 0, no final XOR) over each received item packed as frame
(uint8), command (uint16), autocontinue (uint8), param1-4, x, y, z (7 x 4 bytes: in
MISSION_ITEM_INT x and y are the int32 bytes), 32 bytes without padding. Confirmed on the
shipped PX4 SITL (1.18.0-dev): a 3-item upload got MISSION_ACK opaque_id 2102974779 =
MISSION_CURRENT.mission_id, which this function gives; the padded layout does not."""

from __future__ import annotations

import struct
import zlib
from typing import Any, Sequence

from pymavlink.dialects.v20 import common as mavlink

from protocol import MissionItem


def px4_mission_id(items: Sequence[MissionItem]) -> int:
    """The id PX4 gives a mission of ``items``; 0 for none (PX4's id of no mission)."""
    crc = 0
    for i in items:
        raw = struct.pack("<BHB4fiif", i.frame, i.command, i.autocontinue, i.param1, i.param2, i.param3, i.param4,
                          i.x, i.y, i.z)
        crc = zlib.crc32(raw, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF  # crc32part: zlib's CRC without its pre/post XOR
    return crc


class MissionCurrent(mavlink.MAVLink_mission_current_message):
    def __init__(self, seq: int, total: int, state: int, mode: int, mission_id: int) -> None:
        super().__init__(seq, total, state, mode)
        self.mission_id = mission_id

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.seq, self.total, self.mission_state, self.mission_mode)
        return self._pack(mav, self.crc_extra, payload + struct.pack("<III", self.mission_id, 0, 0),
                          force_mavlink1=force_mavlink1)


class MissionAck(mavlink.MAVLink_mission_ack_message):
    def __init__(self, target_system: int, target_component: int, result: int, mission_type: int,
                 opaque_id: int) -> None:
        super().__init__(target_system, target_component, result, mission_type)
        self.opaque_id = opaque_id

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.target_system, self.target_component, self.type, self.mission_type)
        return self._pack(mav, self.crc_extra, payload + struct.pack("<I", self.opaque_id),
                          force_mavlink1=force_mavlink1)


class MissionCount(mavlink.MAVLink_mission_count_message):
    def __init__(self, target_system: int, target_component: int, count: int, mission_type: int,
                 opaque_id: int) -> None:
        super().__init__(target_system, target_component, count, mission_type)
        self.opaque_id = opaque_id

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(self.count, self.target_system, self.target_component, self.mission_type)
        return self._pack(mav, self.crc_extra, payload + struct.pack("<I", self.opaque_id),
                          force_mavlink1=force_mavlink1)
