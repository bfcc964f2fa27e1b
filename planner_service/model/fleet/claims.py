"""The fleet's claim rule, one for the offline ``claims`` planner and the live fleet
(``planner_service.service.fleet``): what a member has committed to, and who owns what
several members claim.

- **Points.** A member claims the hovering point it holds and the point it flies to next,
  from the moment its mission there is uploaded until it leaves the point. Every member plans
  without the points the others claim (``others_points``), and a member whose next point
  another claims plans again (``lost_points``). Of members that claimed one point before any
  heard the others, the one that claimed it first keeps it (by the claimants' own times,
  carried in their claims; equal times: the id that sorts first) and the others give it up,
  so nobody holds at a point another member keeps. Decisions: both giving it up, as this
  rule first said, made two members that decide alike (idle side by side, on the way home,
  hearing the same request) give up one point, choose the next one together, give that up
  too, and so on until one was near enough to arrive before hearing the other (20 UAVs over
  radios: each hold of two at one point that was traced began so). The first id keeping it,
  as it then said, gave a point to a member that claimed it a radio's hearing delay after
  another (it had not heard the first), and the first, already there, held it with it until
  it heard the later claim (20 UAVs: three members at one point, the last to claim keeping
  it); the first to claim is the nearest to its hold, and the others hear it first.
- **Users.** A member claims the user its hold serves (``BOUND``, from the moment the hold is
  bound) and the user of its next point (``PLANNED``, with when its service should begin).
  A user several members claim belongs to one (``owner``): a bound claim before a planned one,
  then the earlier, then the smaller member id. Every member computes the same owner from the
  same claims, whatever its own clock reads: the times compared are the claimants' own, carried
  in their claims, never a reader's.

Pure: members, users and points are any hashable ids (vehicle ids and user ids live, indexes
offline), and nothing here reads a clock.
"""

from __future__ import annotations

import math
from typing import Hashable, Iterable, Mapping, TypeVar

Member = TypeVar("Member", bound=Hashable)
Thing = TypeVar("Thing", bound=Hashable)

Claim = tuple[int, float]
"""How a member claims a user: (``BOUND``, when its hold was bound) beats every
(``PLANNED``, when its service should begin); among equals the earlier wins."""
BOUND = 0
PLANNED = 1


def owner(thing: Thing, claims: Mapping[Member, Mapping[Thing, Claim]]) -> Member | None:
    """The member that owns ``thing`` among ``claims`` (member -> thing -> claim): the least
    claim, ties to the smaller member id; None when no member claims it."""
    ranked = [(claim[thing], member) for member, claim in claims.items() if thing in claim]
    return min(ranked)[1] if ranked else None  # type: ignore[type-var]


def owned_by_others(own: Member, claims: Mapping[Member, Mapping[Thing, Claim]],
                    alive: Iterable[Member]) -> dict[Thing, Member]:
    """What a live member other than ``own`` owns (``owner`` among the live members' claims and
    ``own``'s), each with that member: ``own`` neither plans, binds nor records it."""
    members = set(alive) | {own}
    live = {m: c for m, c in claims.items() if m in members}
    things = {t for m, c in live.items() if m != own for t in c}
    owners = {t: owner(t, live) for t in things}
    return {t: m for t, m in owners.items() if m is not None and m != own}


def others_points(own: Member, points: Mapping[Member, Iterable[int]], alive: Iterable[Member],
                  since: Mapping[Member, Mapping[int, float]] | None = None) -> frozenset[int]:
    """The hovering points the live members other than ``own`` claim (each the point it holds
    and the point it flies to next): ``own`` plans without them, but for a point it claims
    too and keeps (``keeper``: it claimed it first)."""
    members = set(alive)
    mine = {int(k) for k in points.get(own, ())}
    claimed = {int(k) for m, ks in points.items() if m != own and m in members for k in ks}
    return frozenset(k for k in claimed
                     if k not in mine or keeper(k, points, members | {own}, since) != own)


def keeper(point: int, points: Mapping[Member, Iterable[int]], alive: Iterable[Member],
           since: Mapping[Member, Mapping[int, float]] | None = None) -> Member | None:
    """Of the live members claiming ``point``, the one that keeps it: the earliest claim
    (``since``: member -> point -> when it claimed it, by its own clock; none given: all at
    once; a claim it leaves out, the latest), then the id that sorts first."""
    members = set(alive)
    unsaid = 0.0 if since is None else math.inf
    ranked = [((since or {}).get(m, {}).get(point, unsaid), m) for m, ks in points.items()
              if m in members and point in {int(k) for k in ks}]
    return min(ranked)[1] if ranked else None  # type: ignore[type-var]


def lost_points(own_points: Iterable[int], blocked: Iterable[int]) -> frozenset[int]:
    """The points ``own`` claims that are blocked to it (``others_points``: another member
    claims them and keeps them): ``own`` gives them up (plans again without them)."""
    return frozenset(own_points) & frozenset(blocked)
