"""Whose mission the vehicle flies: the evidence the autopilot gives, judged against the
mission the service holds. Pure.

Each signal that can betray another station's mission, in the order judged:

- MISSION_CURRENT's count of items (ArduPilot counts without home, PX4 with: either is
  ours); a count a read-back showed to go with our mission doubts nothing again;
- MISSION_CURRENT's ``mission_id`` (PX4: a CRC32 of the items) against the id the autopilot
  gave our upload (MISSION_ACK ``opaque_id``); an id the link could not learn is read back
  once, then known;
- the item flown: one our mission lacks, or a step back nothing the service commanded
  explains (a mission's items are flown forward);
- the vehicle's track against the leg it flies, from where it began the item to our point:
  a mission of the same length has the same items at other places, and the vehicle heads
  off the leg before any count or id says so;
- and, under authority in flight, a read-back every ``readback_interval_s``: ArduPilot names
  no mission, and theirs may leave every report as it was.

A disagreement is a reason to read the mission back (``Doubt``), never a verdict: the
read-back decides (``SortieLogic._read_back``), and a false alarm costs one read-back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..link.modes import MISSION_MODES
from .inputs import VehicleSnapshot
from .mission import HeldMission

LEG_REPORTS = 3
"""Position reports in a row off the leg that read the mission back (one stray report, a
gust, is no evidence)."""


@dataclass(frozen=True)
class Doubt:
    """Why the mission should be read back; ``periodic``: only because it is time to."""

    why: str
    periodic: bool = False


@dataclass(frozen=True)
class Evidence:
    """What the service has seen of the mission the vehicle flies since it last knew it held
    ours (an upload accepted, a read-back)."""

    count_at_doubt: int | None = None
    """The count of items that raised the last doubt."""
    count_explained: int | None = None
    """A count of items a read-back showed to go with the mission held."""
    mission_id: int = 0
    """The autopilot's id of the mission held (MISSION_ACK ``opaque_id``); 0: not said."""
    id_at_doubt: int = 0
    """The MISSION_CURRENT ``mission_id`` that raised the last doubt."""
    id_explained: int = 0
    """A ``mission_id`` a read-back showed to go with the mission held."""
    checked_at: float = -math.inf
    """When the vehicle was last known to hold the mission (accepted or read back)."""
    top_seq: int = -1
    """The highest item seen flown since then, or since the service last commanded an item."""
    leg: tuple[int, float, float, float] | None = None
    """The leg being flown: its item, where the vehicle was (x, y) when it began it, and the
    vehicle's clock of the last report judged."""
    off_leg: int = 0
    """Reports in a row off that leg."""

    def known(self, now: float, mission_id: int, *, read_back: bool) -> "Evidence":
        """The vehicle was just seen to hold the mission: its id as the autopilot gave it
        (a read-back that says none explains the id that raised the doubt), and the checks
        of the item flown and the leg start afresh."""
        if read_back:
            return replace(self, mission_id=mission_id or self.mission_id, id_at_doubt=0, checked_at=now,
                           id_explained=self.id_at_doubt if mission_id == 0 else 0, top_seq=-1, leg=None,
                           off_leg=0)
        return replace(self, mission_id=mission_id, id_explained=0, id_at_doubt=0, checked_at=now, top_seq=-1, leg=None,
                       off_leg=0)

    def no_mission(self) -> "Evidence":
        """The service holds no mission: no id of it."""
        return replace(self, mission_id=0, id_explained=0)

    def commanded(self) -> "Evidence":
        """The service commanded an item or a mode: the item flown and the leg start afresh."""
        return replace(self, top_seq=-1, leg=None, off_leg=0)

    def explained(self) -> "Evidence":
        """A read-back showed the vehicle holds ours: the count that raised the doubt is ours."""
        return replace(self, count_explained=self.count_at_doubt)

    def lost(self) -> "Evidence":
        """The vehicle does not hold ours: no count is explained."""
        return replace(self, count_explained=None)


@dataclass(frozen=True)
class Settled:
    """What the checks need to know of the service's own state."""

    over: bool
    """The sortie is over (the count is still judged: a mission lost shows there)."""
    commanding: bool
    """A command is in flight: the item flown may change under it."""
    granted: bool
    """The service has the authority (the periodic read-back is only under it)."""


def judge(e: Evidence, held: HeldMission, v: VehicleSnapshot, now: float, state: Settled, *,
          leg_tolerance_m: float, readback_interval_s: float) -> tuple[Evidence, Doubt | None]:
    """The evidence after the vehicle's latest report, and the first reason to read the
    mission back (None: none). Only while the vehicle is known to hold ``held`` and nothing
    the service does now changes it (the caller's part)."""
    e, doubt = _count(e, held, v)
    if doubt is not None or state.over:
        return e, doubt
    for check in (_mission_id, _item_flown, _leg):
        e, doubt = check(e, held, v, state, leg_tolerance_m)
        if doubt is not None:
            return e, doubt
    if (readback_interval_s > 0 and state.granted and v.airborne and now - e.checked_at >= readback_interval_s):
        return e, Doubt(f"the periodic check of plan {held.plan_id} (every {readback_interval_s:g} s)", periodic=True)
    return e, None


def _count(e: Evidence, held: HeldMission, v: VehicleSnapshot) -> tuple[Evidence, Doubt | None]:
    """MISSION_CURRENT's count of items: another station's upload shows there first
    (ArduPilot tells only the uploading station that it took a plan), as does a mission
    lost."""
    if v.mission_total < 0 or v.mission_total == e.count_explained:
        return e, None
    if v.mission_total in (len(held.items), len(held.items) - 1):  # with or without home
        return e, None
    return replace(e, count_at_doubt=v.mission_total), Doubt(
        f"the vehicle counts {v.mission_total} mission items, plan {held.plan_id} has {len(held.items)}")


def _mission_id(e: Evidence, held: HeldMission, v: VehicleSnapshot, state: Settled,
                _tolerance: float) -> tuple[Evidence, Doubt | None]:
    if v.mission_id == 0 or v.mission_id in (e.mission_id, e.id_explained):
        return e, None
    said = f"{e.mission_id:#010x}" if e.mission_id else "not said"
    return replace(e, id_at_doubt=v.mission_id), Doubt(
        f"the vehicle names its mission {v.mission_id:#010x}, plan {held.plan_id}'s id is {said}")


def _item_flown(e: Evidence, held: HeldMission, v: VehicleSnapshot, state: Settled,
                _tolerance: float) -> tuple[Evidence, Doubt | None]:
    if not v.airborne or v.seq < 0 or state.commanding:
        return e, None
    if v.seq >= len(held.items):
        return e, Doubt(f"the vehicle flies item {v.seq}, plan {held.plan_id} has {len(held.items)}")
    if v.seq < e.top_seq:
        return replace(e, top_seq=-1), Doubt(f"the vehicle went back from item {e.top_seq} to {v.seq} of plan "
                                             f"{held.plan_id}, not commanded by the service")
    return (replace(e, top_seq=v.seq) if v.seq > e.top_seq else e), None


def _leg(e: Evidence, held: HeldMission, v: VehicleSnapshot, state: Settled,
         tolerance: float) -> tuple[Evidence, Doubt | None]:
    point = held.point_at(v.seq)
    if (tolerance <= 0 or point is None or not v.airborne or not v.position_ok or v.mode not in MISSION_MODES
            or state.commanding or math.isnan(v.boot_s)):
        return (replace(e, leg=None, off_leg=0) if e.leg is not None else e), None
    x, y = v.xyz[0], v.xyz[1]
    if e.leg is None or e.leg[0] != v.seq:
        return replace(e, leg=(v.seq, x, y, v.boot_s), off_leg=0), None
    if v.boot_s == e.leg[3]:
        return e, None  # the same report again
    seq, x0, y0, _ = e.leg
    e = replace(e, leg=(seq, x0, y0, v.boot_s))
    off = off_segment_m((x0, y0), (point.x_m, point.y_m), (x, y))
    if off <= tolerance:
        return (replace(e, off_leg=0) if e.off_leg else e), None
    if e.off_leg + 1 < LEG_REPORTS:
        return replace(e, off_leg=e.off_leg + 1), None
    return replace(e, leg=None, off_leg=0), Doubt(
        f"the vehicle is {off:.0f} m off its leg to point {point.hover_index} (item {seq} of plan {held.plan_id})")


def off_segment_m(a: tuple[float, float], b: tuple[float, float], p: tuple[float, float]) -> float:
    """The horizontal distance (m) from ``p`` to the segment from ``a`` to ``b``."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length2 = dx * dx + dy * dy
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / length2))
    return math.hypot(p[0] - (a[0] + t * dx), p[1] - (a[1] + t * dy))
