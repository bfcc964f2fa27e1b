"""The fleet's joint rules audited from a finished sortie's records, apart from the
environment that enforces them: a check that does not trust the code it checks."""

from __future__ import annotations

from typing import Iterable, NamedTuple

from ..interval import AT_BASE, NO_USER


class Hold(NamedTuple):
    """One interval of one UAV: it held ``point`` and served ``user`` over [start_s, end_s)."""

    uav: int
    point: int
    user: int
    start_s: float
    end_s: float


def overlaps(holds: Iterable[Hold]) -> tuple[int, int]:
    """(double services, double holds): pairs of intervals of two different UAVs that
    overlap in time (half-open: one ending when the other starts does not) and serve the
    same user, or hold the same hovering point."""
    items = sorted(holds, key=lambda h: h.start_s)
    users = points = 0
    for a, first in enumerate(items):
        for second in items[a + 1:]:
            if second.start_s >= first.end_s:
                break
            if second.uav == first.uav:
                continue
            users += first.user != NO_USER and first.user == second.user
            points += first.point != AT_BASE and first.point == second.point
    return users, points
