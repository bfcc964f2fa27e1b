"""Which planned points of the mission held are done, from MISSION_ITEM_REACHED and from
MISSION_CURRENT, and which were already in the journal when the service restarts."""

from __future__ import annotations

import pytest

from planner_service.service.planning import PlannedPoint
from planner_service.service.progress import HeldMission
from protocol import GeoOrigin, HoverPoint, encode_path


def held(flavour: str, users: list[str]) -> HeldMission:
    points = tuple(PlannedPoint(i, 50.0 + 10 * i, 60.0, 50.0, 5.0, u, 10 + i, 8, 8e6, 1000.0, 0.5)
                   for i, u in enumerate(users))
    items = encode_path([HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in points], GeoOrigin(), flavour)  # type: ignore[arg-type]
    return HeldMission.build(7, items, points, flavour)


@pytest.mark.parametrize("flavour, first", [("ardupilot", 2), ("px4", 1)])
def test_points_done_from_current_and_reached(flavour: str, first: int) -> None:
    # ArduPilot: 0 home, 1 takeoff, 2..4 points, 5 RTL; PX4: 0 takeoff, 1..3 points, 4 RTL.
    h = held(flavour, ["a", "b", "c"])
    assert h.first_point_seq == first
    assert h.points_done(first, set(), including=False) == []  # flying to the first point
    assert h.points_done(first, set(), including=True) == [first]  # MISSION_ITEM_REACHED of it
    assert h.points_done(first + 2, set(), including=False) == [first, first + 1]  # its REACHED was lost
    assert h.points_done(first + 2, {first}, including=False) == [first + 1]
    rtl = first + 3
    assert h.points_done(rtl, {first}, including=False) == [first + 1, first + 2]  # the RTL item: all done
    assert h.points_done(rtl, {first}, including=True) == [first + 1, first + 2]
    assert h.points_done(0, set(), including=True) == []


def test_counted_from_the_journal_after_a_restart() -> None:
    h = held("ardupilot", ["a", "b", "c"])
    # "a" was served before this mission was accepted (at t=100): not this mission's point.
    served = [("a", 90.0), ("b", 120.0), ("x", 130.0)]
    assert h.counted_from(100.0, served) == {3}
    assert h.counted_from(100.0, []) == set()
