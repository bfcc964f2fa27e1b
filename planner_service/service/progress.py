"""The mission the vehicle holds and where the vehicle is in it: which item sequence
number is which planned point, which points are done, and whether the vehicle is holding
over one (a re-plan then would cut a user's upload short). Pure.

A point is done when the vehicle reports it reached (MISSION_ITEM_REACHED, sent once and
lost one time in five on a 20 % lossy link) or when the vehicle flies a later item
(MISSION_CURRENT, streamed): items are flown in order, from the start of the mission on
each upload."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import AbstractSet, Any, Iterable

from protocol import MissionItem

from .planning import PlannedPoint

HOLD_RADIUS_M = 2.0
"""The vehicle counts as over a point within this distance of it."""


@dataclass(frozen=True)
class HeldMission:
    """A mission the autopilot accepted: its items and the planned points it flies."""

    plan_id: int
    items: tuple[MissionItem, ...]
    points: tuple[PlannedPoint, ...]
    first_point_seq: int
    """Sequence number of the first hovering point (after home and takeoff)."""

    @classmethod
    def build(cls, plan_id: int, items: list[MissionItem], points: tuple[PlannedPoint, ...], flavour: str) -> "HeldMission":
        offset = 1 if flavour == "ardupilot" else 0
        takeoff = 1 if points else 0
        return cls(plan_id, tuple(items), points, offset + takeoff)

    def point_at(self, seq: int) -> PlannedPoint | None:
        """The planned point item ``seq`` flies to, or None (home, takeoff, RTL)."""
        i = seq - self.first_point_seq
        return self.points[i] if 0 <= i < len(self.points) else None

    def points_done(self, seq: int, counted: AbstractSet[int], *, including: bool) -> list[int]:
        """Item seqs of the points done, judging from item ``seq`` (MISSION_CURRENT: the
        vehicle flies it, every point before is done; MISSION_ITEM_REACHED, ``including``:
        it too), less those already ``counted``, in order."""
        last = min(seq if including else seq - 1, self.first_point_seq + len(self.points) - 1)
        return [s for s in range(self.first_point_seq, last + 1) if s not in counted]

    def counted_from(self, accepted_at_s: float, served: Iterable[tuple[str, float]]) -> set[int]:
        """Item seqs of this mission's points already recorded, from the journal's services
        (user, time) after the mission was accepted at ``accepted_at_s``: a path serves each
        user at most once, so a service of the point's user since then is that point's."""
        since = {user for user, t in served if t >= accepted_at_s}
        return {self.first_point_seq + i for i, p in enumerate(self.points) if p.user_id in since}


def item_dict(item: MissionItem) -> dict[str, Any]:
    """A mission item as JSON (NaN as None) for the journal."""
    out: dict[str, Any] = {}
    for key, value in item.__dict__.items():
        out[key] = None if isinstance(value, float) and math.isnan(value) else value
    return out


def item_from_dict(data: dict[str, Any]) -> MissionItem:
    return MissionItem(**{k: (math.nan if v is None else v) for k, v in data.items()})
