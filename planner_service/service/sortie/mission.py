"""The mission the vehicle holds, as the service knows it: its items and which item is
which planned hovering point. Pure.

Replacements keep their place: a new plan in flight is uploaded as the items already flown
or being flown, unchanged, then the new points, then return to launch (``replacement``).
An autopilot that keeps its current index across an upload (ArduPilot) then flies on
without a jump: the point it holds at stays the same item, and the item after it is the
new plan's first point. So a sequence number means the same point in the mission before an
upload and after it, for every item up to the one being flown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from protocol import MissionItem
from protocol.autopilot import Autopilot, autopilot_for
from protocol.mission import NAV_RTL, NAV_TAKEOFF, NAV_WAYPOINT, Flavour

from ..planning import PlannedPoint


@dataclass(frozen=True)
class HeldMission:
    """A mission the autopilot accepted: its items and the planned points it flies, by
    item sequence number (points kept from the mission it replaced included)."""

    plan_id: int
    items: tuple[MissionItem, ...]
    points: tuple[tuple[int, PlannedPoint], ...]
    """(seq, point) in seq order."""

    @classmethod
    def fresh(cls, plan_id: int, items: Sequence[MissionItem], points: Sequence[PlannedPoint],
              flavour: Flavour | Autopilot) -> "HeldMission":
        """A mission flown from its start: [home (ArduPilot)], takeoff, the points, RTL."""
        first = autopilot_for(flavour).first_item + (1 if points else 0)
        return cls(plan_id, tuple(items), tuple((first + i, p) for i, p in enumerate(points)))

    @classmethod
    def replacement(cls, plan_id: int, items: Sequence[MissionItem], before: "HeldMission", keep_through: int,
                    points: Sequence[PlannedPoint], pause: bool = False) -> "HeldMission":
        """``before``'s items up to ``keep_through`` kept, then ``points`` from the next seq
        (after a pause item there with ``pause``: ``is_pause``)."""
        kept = tuple((s, p) for s, p in before.points if s <= keep_through)
        first = keep_through + 1 + (1 if pause else 0)
        return cls(plan_id, tuple(items), kept + tuple((first + i, p) for i, p in enumerate(points)))

    def point_at(self, seq: int) -> PlannedPoint | None:
        """The planned point item ``seq`` flies to, or None (home, takeoff, RTL)."""
        for s, p in self.points:
            if s == seq:
                return p
        return None

    def is_pause(self, seq: int) -> bool:
        """Whether item ``seq`` is a pause: a waypoint after the takeoff that is no planned
        point (the vehicle holds where it was while its next point's claim settles)."""
        takeoff = next((i.seq for i in self.items if i.command == NAV_TAKEOFF), None)
        return (takeoff is not None and takeoff < seq < len(self.items) and self.items[seq].command == NAV_WAYPOINT
                and self.point_at(seq) is None)

    def points_after(self, seq: int) -> list[tuple[int, PlannedPoint]]:
        """The points still to fly after item ``seq``, in order."""
        return [(s, p) for s, p in self.points if s > seq]

    @property
    def rtl_seq(self) -> int:
        """The return-to-launch item (the last)."""
        return next((i.seq for i in reversed(self.items) if i.command == NAV_RTL), len(self.items) - 1)

    def served_since(self, accepted_at_s: float, served: Iterable[tuple[str, float]]) -> frozenset[int]:
        """Seqs of this mission's points already judged, from the journal's services (user,
        time) since the mission was accepted: a plan serves each user at most once, so a
        service of the point's user since then is that point's."""
        since = {user for user, t in served if t >= accepted_at_s}
        return frozenset(s for s, p in self.points if p.user_id in since)

    def journal_points(self) -> list[dict[str, Any]]:
        """The points as the journal keeps them (each with its seq)."""
        return [{"seq": s, **p.__dict__} for s, p in self.points]

    @classmethod
    def from_journal(cls, plan_id: int, items: list[dict[str, Any]], points: list[dict[str, Any]],
                     flavour: Flavour | Autopilot) -> "HeldMission":
        """Back from the journal (rows written before seqs were kept are numbered as a fresh
        mission's)."""
        its = [item_from_dict(i) for i in items]
        if points and "seq" not in points[0]:
            return cls.fresh(plan_id, its, [PlannedPoint(**p) for p in points], flavour)
        return cls(plan_id, tuple(its), tuple((int(p["seq"]), PlannedPoint(**{k: v for k, v in p.items() if k != "seq"}))
                                              for p in points))


def item_dict(item: MissionItem) -> dict[str, Any]:
    """A mission item as JSON (NaN as None) for the journal."""
    return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in item.__dict__.items()}


def item_from_dict(data: dict[str, Any]) -> MissionItem:
    return MissionItem(**{k: (math.nan if v is None else v) for k, v in data.items()})

