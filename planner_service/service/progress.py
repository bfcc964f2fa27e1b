"""The mission the vehicle holds and where the vehicle is in it: which item sequence
number is which planned point, and whether the vehicle is holding over one (a re-plan then
would cut a user's upload short). Pure."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

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


def item_dict(item: MissionItem) -> dict[str, Any]:
    """A mission item as JSON (NaN as None) for the journal."""
    out: dict[str, Any] = {}
    for key, value in item.__dict__.items():
        out[key] = None if isinstance(value, float) and math.isnan(value) else value
    return out


def item_from_dict(data: dict[str, Any]) -> MissionItem:
    return MissionItem(**{k: (math.nan if v is None else v) for k, v in data.items()})
