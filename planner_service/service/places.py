"""Where each user stands in the plan: its place in the planned order and when its service
is expected, for the ack and the per-user ``user_place`` publications. Pure: numbers in,
numbers out; the loop calls it on every re-plan and publishes the result.

The estimate is the model's flight: straight lines at the cruise speed from the vehicle's
position through the points in order, each held for its planned hold. It is vehicle time
(the stub may run faster than the wall clock) from the moment of the position given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping, Protocol, Sequence

from protocol import UserPlace

from .errors import PlanningError
from .rows import UserBacklog


class Stop(Protocol):
    """A point of a plan as ``plan_places`` reads it (``protocol.PlanPoint`` and
    ``planning.PlannedPoint`` both are)."""

    @property
    def x_m(self) -> float: ...
    @property
    def y_m(self) -> float: ...
    @property
    def z_m(self) -> float: ...
    @property
    def hold_s(self) -> float: ...
    @property
    def user_id(self) -> str | None: ...


@dataclass(frozen=True)
class Place:
    """A user's place in a plan: 1 is the next user served (or the one being served);
    ``eta_s`` the vehicle seconds until the vehicle is at its point, its hold beginning."""

    place: int
    eta_s: float


def plan_places(points: Sequence[Stop], vehicle_xyz: tuple[float, float, float], speed_mps: float,
                busy_s: float = 0.0) -> dict[str, Place]:
    """Every user of ``points`` (the points still to fly, in order) with its place and the
    estimated time to its point: ``busy_s`` (what is left of a hold the vehicle is in, not
    among ``points``), then each flight at ``speed_mps`` and each hold before it. A user
    planned twice keeps its first place. Points without a user count in the time, not in
    the places. ``PlanningError`` for a speed that is not positive or a value not finite."""
    if not (speed_mps > 0 and math.isfinite(speed_mps)):
        raise PlanningError("speed_mps", f"must be positive and finite, got {speed_mps}")
    if not (busy_s >= 0 and math.isfinite(busy_s)):
        raise PlanningError("busy_s", f"must be zero or more and finite, got {busy_s}")
    places: dict[str, Place] = {}
    here = tuple(float(v) for v in vehicle_xyz)
    t = busy_s
    for i, point in enumerate(points):
        there = (float(point.x_m), float(point.y_m), float(point.z_m))
        if not all(math.isfinite(v) for v in (*here, *there, point.hold_s)):
            raise PlanningError("points", f"point {i} or the vehicle's position is not finite")
        t += math.dist(here, there) / speed_mps
        if point.user_id is not None and point.user_id not in places:
            places[point.user_id] = Place(len(places) + 1, t)
        t += max(float(point.hold_s), 0.0)
        here = there
    return places


def user_places(backlogs: Iterable[UserBacklog], places: Mapping[str, Place], *, sortie: int, plan_id: int,
                time_s: float) -> list[UserPlace]:
    """The ``user_place`` message of every user of the sortie (``Journal.user_backlogs``):
    its place in plan ``plan_id`` (made at ``time_s``) or none, its request in force,
    backlog and services."""
    out = []
    for b in backlogs:
        place = places.get(b.user_id)
        out.append(UserPlace(user_id=b.user_id, sortie=sortie, plan_id=plan_id, time_s=time_s,
                             place=None if place is None else place.place,
                             eta_s=None if place is None else place.eta_s,
                             request_id=b.request_id, backlog=b.backlog, served_tasks=b.served_tasks,
                             services=b.services))
    return out
