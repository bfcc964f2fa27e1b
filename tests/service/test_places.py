"""Every user's place in a plan and its estimated service time, computed by hand; the
``user_place`` messages built from the journal's backlogs."""

from __future__ import annotations

import pytest

from planner_service.service.errors import PlanningError
from planner_service.service.rows import UserBacklog
from planner_service.service.places import Place, plan_places, user_places
from protocol import PlanPoint, UserPlace, decode, encode


def test_places_and_times_follow_the_flight_and_the_holds() -> None:
    points = [
        PlanPoint(0.0, 300.0, 100.0, 20.0, "a"),   # 300 m from (0, 0, 100): 30 s at 10 m/s
        PlanPoint(400.0, 300.0, 100.0, 15.0, "b"),  # 400 m further: 40 s, after a's 20 s hold
        PlanPoint(400.0, 300.0, 70.0, 5.0, None),  # 30 m down: 3 s, no user
        PlanPoint(400.0, 0.0, 70.0, 10.0, "a"),  # a planned again keeps its first place
        PlanPoint(400.0, 0.0, 70.0, 0.0, "c"),
    ]
    places = plan_places(points, (0.0, 0.0, 100.0), 10.0)
    assert places == {"a": Place(1, 30.0), "b": Place(2, 90.0),
                      "c": Place(3, pytest.approx(30 + 20 + 40 + 15 + 3 + 5 + 30 + 10))}
    busy = plan_places(points[:1], (0.0, 300.0, 100.0), 10.0, busy_s=7.5)  # finishing a hold first
    assert busy == {"a": Place(1, 7.5)}
    assert plan_places([], (0.0, 0.0, 0.0), 10.0) == {}


@pytest.mark.parametrize("speed, busy, what", [(0.0, 0.0, "speed_mps"), (float("nan"), 0.0, "speed_mps"),
                                               (5.0, -1.0, "busy_s")])
def test_bad_inputs_are_named(speed: float, busy: float, what: str) -> None:
    with pytest.raises(PlanningError) as err:
        plan_places([], (0.0, 0.0, 0.0), speed, busy)
    assert err.value.check == what
    with pytest.raises(PlanningError, match="point 0"):
        plan_places([PlanPoint(float("inf"), 0.0, 0.0)], (0.0, 0.0, 0.0), 5.0)


def test_user_place_messages_for_every_user_of_the_sortie() -> None:
    backlogs = [UserBacklog("a", 7, 12, 1, 8), UserBacklog("z", 9, 0, 0, 0)]
    messages = user_places(backlogs, {"a": Place(2, 61.25), "b": Place(1, 3.0)}, sortie=3, plan_id=11, time_s=500.0)
    assert messages == [
        UserPlace(user_id="a", sortie=3, plan_id=11, time_s=500.0, place=2, eta_s=61.25, request_id=7, backlog=12,
                  served_tasks=8, services=1),
        UserPlace(user_id="z", sortie=3, plan_id=11, time_s=500.0, place=None, eta_s=None, request_id=9, backlog=0,
                  served_tasks=0, services=0),
    ]
    assert all(decode(encode(m), UserPlace) == m for m in messages)
