"""The mission held: which item is which planned point, in a fresh mission and across an
index-preserving replacement; the points already judged when the service restarts."""

from __future__ import annotations

import pytest

from planner_service.service.planning import PlannedPoint
from planner_service.service.sortie import HeldMission
from protocol import GeoOrigin, HoverPoint, encode_path, replacement_items


def points(users: list[str], first: int = 0) -> tuple[PlannedPoint, ...]:
    return tuple(PlannedPoint(first + i, 50.0 + 10 * i, 60.0, 50.0, 5.0, u, 10 + i, 8, 8e6, 1000.0, 0.5)
                 for i, u in enumerate(users))


def hover(pts: tuple[PlannedPoint, ...]) -> list[HoverPoint]:
    return [HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in pts]


@pytest.mark.parametrize("flavour, first", [("ardupilot", 2), ("px4", 1)])
def test_fresh_and_replaced_missions_keep_their_seqs(flavour: str, first: int) -> None:
    # ArduPilot: 0 home, 1 takeoff, 2..4 points, 5 RTL; PX4: 0 takeoff, 1..3 points, 4 RTL.
    pts = points(["a", "b", "c"])
    held = HeldMission.fresh(7, encode_path(hover(pts), GeoOrigin(), flavour), pts, flavour)  # type: ignore[arg-type]
    assert [s for s, _ in held.points] == [first, first + 1, first + 2] and held.rtl_seq == first + 3
    assert held.point_at(first + 1) is pts[1] and held.point_at(0) is None
    # Holding at b: a and b kept where they were, the new decision after them.
    new = points(["d", "e"], first=10)
    items, nxt = replacement_items(held.items, first + 1, hover(new), GeoOrigin(), flavour)  # type: ignore[arg-type]
    replaced = HeldMission.replacement(8, items, held, first + 1, new)
    assert nxt == first + 2
    assert [(s, p.user_id) for s, p in replaced.points] == [(first, "a"), (first + 1, "b"), (first + 2, "d"),
                                                            (first + 3, "e")]
    assert replaced.rtl_seq == first + 4 and [p.user_id for _, p in replaced.points_after(first + 1)] == ["d", "e"]
    back = HeldMission.from_journal(8, [i.__dict__ for i in items], replaced.journal_points(), flavour)
    assert back.points == replaced.points


def test_points_already_served_after_a_restart() -> None:
    pts = points(["a", "b", "c"])
    held = HeldMission.fresh(7, encode_path(hover(pts), GeoOrigin()), pts, "ardupilot")
    # "a" was served before this mission was accepted (at t=100): not this mission's point.
    served = [("a", 90.0), ("b", 120.0), ("x", 130.0)]
    assert held.served_since(100.0, served) == {3}
    assert held.served_since(100.0, []) == set()
