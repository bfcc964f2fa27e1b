"""The fleet as the sortie logic knows it, pure: what the other members own and claim
(``FleetView``, from ``inputs.FleetHeard``), and what this member claims now (``Claims``,
told with ``effects.Intend``) by the fleet's claim rule (``model.fleet.claims``):

- the point it holds (from its arrival until it leaves it) and the point it flies to next
  (from the moment its mission there is on board until it leaves it), with their users:
  the user its hold is bound to, and the planned user of the next point;
- nothing once its sortie is over or it is on its way home; on its mission's way home with
  its sortie on, that it would answer a new request (``answering``).

Who answers a new request first (``answer_rank``): of the members on their way home, the one
nearest to a pending user; each other a step later per member nearer than it. Every member
idle on its way home hears a new request at once, and deciding at once they planned the same
user and flew to it together (20 UAVs over radios: three served one user at once), since no
claim is heard faster than a radio carries it. The nearest decides first, and the others find
its claim by the time their turn comes.

A lone UAV hears nothing (an empty view) and tells nothing (the service carries no
``Intend`` without a fleet)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Iterable, Mapping

if TYPE_CHECKING:  # (annotations only: effects.py imports this module, holds.py imports effects)
    from .holds import Holds
    from .mission import HeldMission


WHEREABOUTS_M = 10.0
"""The others' positions are heard rounded to this (a view that changes at every report
would be fed to the logic at every tick; a rank needs no finer)."""


@dataclass(frozen=True)
class FleetView:
    """The other live members' claims as this member last heard them."""

    owners: Mapping[str, str] = field(default_factory=dict)
    """The users another live member owns, each with that member: not planned, bound nor
    recorded here."""
    blocked: frozenset[int] = frozenset()
    """The hovering points this member plans without: those another live member claims, the
    rest of the route of a member gone with its vehicle armed, and those another member's
    vehicle is over (``fleet.occupied_m``, but for the points this member claims)."""
    yield_to: Mapping[int, str] = field(default_factory=dict)
    """The point this member holds that another member claims too (holds or flies to) and
    keeps (it claimed it first: ``model.fleet.claims.keeper``), with that member: this member
    ends its hold there."""

    answering: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    """The other members that would answer a new request (on their way home), each where it
    is: metres east and north in this member's frame (rounded: ``WHEREABOUTS_M``)."""
    settled: frozenset[int] = frozenset()
    """The points this member claims whose claims have settled: every other live member's
    intentions signed after the claim were heard, so every claim made before it is known and
    judged (``blocked``, ``yield_to``); a decision's first point is flown to once settled."""
    bound_settled: str | None = None
    """The user this member claims as bound (``Claims.bound``) once that binding has settled
    as ``settled`` says: every binding of the user made before it is known (``owners``)."""

    def owner(self, user_id: str) -> str | None:
        return self.owners.get(user_id)


@dataclass(frozen=True)
class Claims:
    """What this member claims now (``model.fleet.claims``): its points and their users."""

    flying_to: int | None = None
    """The hovering point it flies to next (its mission's next point not yet left)."""
    next_user: str | None = None
    """The planned user of ``flying_to``."""
    holding: int | None = None
    """The hovering point it holds now (arrived, not yet left)."""
    bound: str | None = None
    """The user its hold is bound to (a request bound at the arrival), until its service is
    recorded."""
    answering: bool = False
    """It flies its mission's way home in a mission mode, its sortie on, and would turn back
    for a new request (``SortieLogic._answers``)."""

    @property
    def points(self) -> frozenset[int]:
        return frozenset(k for k in (self.flying_to, self.holding) if k is not None)


def claims_now(held: HeldMission | None, holds: Holds, seq: int, homing: bool) -> Claims:
    """What a member flying ``held`` (item ``seq`` current, ``holds`` watched) claims: the
    point it holds and its bound user (or its last hold's, until that service is recorded:
    ``Holds.judged_unrecorded``), and the first point after it (or after the item flown to,
    when it holds none) with its planned user; no point without a mission or homing."""
    unrecorded = holds.unrecorded_user
    if held is None or homing:
        return Claims(bound=unrecorded)
    holding, bound = None, unrecorded
    after = seq - 1
    w, b = holds.watch, holds.binding
    if w is not None and w.phase == "holding":
        point = held.point_at(w.seq)
        if point is not None:
            holding, after = point.hover_index, w.seq
            bound = b.user_id if b is not None and b.request_id is not None else unrecorded
    following = held.points_after(after)
    if not following:
        return Claims(holding=holding, bound=bound)
    point = following[0][1]
    return Claims(flying_to=point.hover_index, next_user=point.user_id, holding=holding, bound=bound)


def coarse(where: Mapping[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    """``where`` rounded to ``WHEREABOUTS_M``."""
    return {k: (round(x / WHEREABOUTS_M) * WHEREABOUTS_M, round(y / WHEREABOUTS_M) * WHEREABOUTS_M)
            for k, (x, y) in where.items()}


def answer_rank(own: str, here: tuple[float, float], others: Mapping[str, tuple[float, float]],
                users: Iterable[tuple[float, float]], tie_m: float) -> int:
    """How many of the ``others`` (members on their way home, where each is) answer a new
    request before ``own`` (at ``here``): each nearer than it to the nearest of the pending
    ``users`` by more than ``tie_m``, and each within ``tie_m`` of its distance whose id
    sorts first (two side by side hear each other's positions a report late: within the
    tie, the ids decide, which both read alike). 0 without users."""
    targets = list(users)
    if not targets:
        return 0

    def distance(p: tuple[float, float]) -> float:
        return min(math.hypot(p[0] - x, p[1] - y) for x, y in targets)

    mine = distance(here)
    return sum(1 for member, p in others.items() if member != own
               and (distance(p) < mine - tie_m or (abs(distance(p) - mine) <= tie_m and member < own)))
