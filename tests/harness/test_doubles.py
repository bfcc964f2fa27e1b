"""What two UAVs did at once (planner_service/harness/doubles.py): holds over one point from
the positions side by side, services of one user whose holds overlapped."""

from __future__ import annotations

from planner_service.harness.doubles import served_at_once, stacked_holds
from protocol import Event, Status


def at(vehicle: str, t: float, x: float, armed: bool = True) -> Status:
    return Status(vehicle=vehicle, time_s=t, armed=armed, x_m=x, y_m=0.0, z_m=50.0)


def test_two_holding_over_one_point_for_a_second_are_stacked_and_a_crossing_is_not() -> None:
    over_one = [at(v, t / 2, 100.0 + (0.5 if v == "uav2" else 0.0)) for t in range(6) for v in ("uav1", "uav2")]
    assert stacked_holds(over_one, 10.0) == ["uav1-uav2 11 rounds"]
    # uav2 crosses over uav1 at 25 m/s (two layers apart): close in one round only
    crossing = [s for t in range(6) for s in (at("uav1", t / 2, 100.0), at("uav2", t / 2 + 0.1, 100.0 + 12.5 * (t - 3)))]
    assert stacked_holds(crossing, 10.0) == []
    # a vehicle on the ground (disarmed) under one holding is no hold of two
    assert stacked_holds([at("uav1", t / 2, 100.0) for t in range(6)] + [at("uav2", t / 2, 100.0, armed=False)
                                                                        for t in range(6)], 10.0) == []


def test_a_leg_flown_slowly_over_a_hold_is_near_it_but_no_hold_of_two() -> None:
    """Found at 20 UAVs (x2.5): a vehicle flying a leg over another's hold, on its own layer,
    slowing down for its own point near by, was within 10 m of it for 1-2 s and counted as a
    hold of two. Both hovering is a hold of two; one flying past is only near it."""
    # uav2 flies over uav1's point at 4 m/s of its own time (x2.5: 10 m a wall second)
    passing = [s for t in range(12) for s in (at("uav1", t / 2, 100.0), at("uav2", t / 2 + 0.1, 70.0 + 5.0 * t))]
    assert stacked_holds(passing, 10.0) == ["uav1-uav2 6 rounds"]
    assert stacked_holds(passing, 10.0, hovering_mps=2.0, speedup=2.5) == []
    over_one = [at(v, t / 2, 100.0 + (0.5 if v == "uav2" else 0.0)) for t in range(6) for v in ("uav1", "uav2")]
    assert stacked_holds(over_one, 10.0, hovering_mps=2.0, speedup=2.5) == ["uav1-uav2 9 rounds"]


def served(vehicle: str, user: str, end_s: float, held_s: float) -> tuple[str, Event]:
    return vehicle, Event(event="user_served", time_s=end_s, user_id=user,
                          detail=f"10 tasks at point 3; held {held_s:.1f} s")


def test_services_of_one_user_by_two_overlapping_in_time_are_at_once_one_after_the_other_are_not() -> None:
    # at x10: uav1 held user-1 from 100 to 105 s (wall), uav2 from 103 to 106: at once
    events = [served("uav1", "user-1", 105.0, 50.0), served("uav2", "user-1", 106.0, 30.0),
              # user-2: uav1 until 110, then uav2 from 111: a second service, no fault
              served("uav1", "user-2", 110.0, 20.0), served("uav2", "user-2", 115.0, 40.0),
              # one UAV twice is never two
              served("uav3", "user-3", 120.0, 50.0), served("uav3", "user-3", 121.0, 50.0)]
    assert served_at_once(events, 10.0) == ["user-1 uav1+uav2"]


def test_a_service_recorded_after_its_hold_is_placed_at_its_hold() -> None:
    """A fleet member records once its binding has settled, seconds after the hold: the
    event says how long after, and the hold is placed where it was flown."""
    late = (served("uav2", "user-1", 112.0, 30.0)[0],
            Event(event="user_served", time_s=112.0, user_id="user-1",
                  detail="10 tasks at point 3; held 30.0 s; recorded 6.0 s after the hold"))
    # uav1 held user-1 from 100 to 105 s, uav2 from 103 to 106 (recorded at 112): at once
    assert served_at_once([served("uav1", "user-1", 105.0, 50.0), late], 10.0) == ["user-1 uav1+uav2"]
    # uav1 from 107 to 112: after uav2's hold, though the two events are at one moment
    assert served_at_once([served("uav1", "user-1", 112.0, 50.0), late], 10.0) == []
