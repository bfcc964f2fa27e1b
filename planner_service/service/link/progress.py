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


CURRENT_CONFIRM_S = 0.2
"""Wall seconds after a first report of another item by which a second one confirms it:
two messages of one datagram arrive together, the vehicle's stream (2 Hz asked, about 1 Hz
from ArduPilot's and PX4's own streams) repeats the item flown."""


class CurrentWatch:
    """Which MISSION_CURRENT to believe (issue 34, finding 8). Unsigned, anyone on the
    network can send one from the autopilot's ids; believed, a forged item far ahead ended
    the hold being flown ("item N flown next") and marked every planned point before it
    skipped. A report is believed at once when it names the item already believed or one
    the service asked for (its upload's current item, a set_current) or the one after an item
    the vehicle reported reached; another item is believed when the next report names it
    too, at least ``confirm_s`` later. The vehicle's
    stream names the item it flies in every report, so a forged one is contradicted by the
    next and forgotten, and a real advance is believed one report later (0.5-1 s). A report
    naming no item (``NO_ITEM``, read as -1) is passed on as before: it names no point."""

    def __init__(self, confirm_s: float = CURRENT_CONFIRM_S) -> None:
        self.confirm_s = confirm_s
        self.believed: int | None = None
        """The item the vehicle's stream agrees it flies; None: none yet (or since a restart)."""
        self._expected: set[int] = set()
        self._pending: tuple[int, float] | None = None
        """(item, wall time) of the first report of an item not yet believed."""

    def expect(self, seq: int) -> None:
        """The service asked the vehicle to fly ``seq``: its first report of it is believed."""
        self._expected.add(seq)

    def reached(self, seq: int) -> None:
        """The vehicle reported item ``seq`` reached (MISSION_ITEM_REACHED): where that is the
        item believed, the next one is news at its first report (no lag on a real advance; a
        forged pair moves on one item at most, never past points ahead)."""
        if seq == self.believed:
            self._expected.add(seq + 1)

    def observe(self, seq: int, now: float) -> bool:
        """A MISSION_CURRENT naming ``seq`` (-1: none) at wall time ``now``: believe it?"""
        if seq < 0:
            return True
        if seq == self.believed or seq in self._expected:
            return self._believe(seq)
        pending = self._pending
        if pending is not None and pending[0] == seq:
            if now - pending[1] >= self.confirm_s:
                return self._believe(seq)
            return False
        self._pending = (seq, now)
        return False

    def _believe(self, seq: int) -> bool:
        self.believed, self._pending = seq, None
        self._expected.discard(seq)  # asked for and come: the next time it needs the stream's word
        return True

    def reset(self) -> None:
        """The vehicle restarted: nothing it said of its mission before holds."""
        self.believed, self._pending = None, None
        self._expected.clear()
