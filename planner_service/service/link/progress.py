"""MISSION_CURRENT's ``seq`` and ``total`` as the service reads them, for both backends.

A ``seq`` of UINT16_MAX names no item. PX4 sends one after an upload that marks no item
current: its mission manager holds ``_current_seq`` -1 from the upload
(``MavlinkMissionManager::handle_mission_item_both``) until the navigator settles on an
index, and a MISSION_CURRENT from its 1 Hz stream can fall between (seen once in a CI run
of PX4 SITL 1.18, an upload in flight: 65535, then 2, 2, ...). Read as an item it is past
every mission's end: a hold would end as "item 65535 flown next" and every point still to
fly would count as skipped. It is read as -1, not said, and answers nobody waiting for the
vehicle's index (docs/VEHICLE.md, "MISSION_CURRENT naming no item"). The service marks an
item current in each upload of its own, so it meets this after another station's upload.
"""

from __future__ import annotations

from typing import Any

NO_ITEM = 0xFFFF
"""MISSION_CURRENT.seq naming no item (PX4's -1 as a uint16)."""


def mission_progress(msg: Any) -> tuple[int, int]:
    """(seq, total) of a MISSION_CURRENT: ``seq`` -1 when it names no item; ``total`` -1
    when the autopilot does not say (0 on the wire), 0 when it holds no mission
    (UINT16_MAX, MAVLink)."""
    seq = int(msg.seq)
    raw = int(getattr(msg, "total", 0) or 0)
    total = -1 if raw == 0 else 0 if raw == 0xFFFF else raw
    return (-1 if seq == NO_ITEM else seq), total
