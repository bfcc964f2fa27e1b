"""The fleet as the sortie logic knows it, pure: what the other members own and claim
(``FleetView``, from ``inputs.FleetHeard``), and what this member claims now (``Claims``,
told with ``effects.Intend``) by the fleet's claim rule (``model.fleet.claims``):

- the point it holds (from its arrival until it leaves it) and the point it flies to next
  (from the moment its mission there is on board until it leaves it), with their users:
  the user its hold is bound to, and the planned user of the next point;
- nothing once its sortie is over or it is on its way home.

A lone UAV hears nothing (an empty view) and tells nothing (the service carries no
``Intend`` without a fleet)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Mapping

if TYPE_CHECKING:  # (annotations only: effects.py imports this module, holds.py imports effects)
    from .holds import Holds
    from .mission import HeldMission


@dataclass(frozen=True)
class FleetView:
    """The other live members' claims as this member last heard them."""

    owners: Mapping[str, str] = field(default_factory=dict)
    """The users another live member owns, each with that member: not planned, bound nor
    recorded here."""
    blocked: frozenset[int] = frozenset()
    """The hovering points this member plans without: those another live member claims, and
    the rest of the route of a member gone with its vehicle armed."""
    yield_to: Mapping[int, str] = field(default_factory=dict)
    """The point this member holds that another member holds too and keeps (its id sorts
    first), with that member: this member ends its hold there."""

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
    """The user its hold is bound to (a request bound at the arrival)."""

    @property
    def points(self) -> frozenset[int]:
        return frozenset(k for k in (self.flying_to, self.holding) if k is not None)


def claims_now(held: HeldMission | None, holds: Holds, seq: int, homing: bool) -> Claims:
    """What a member flying ``held`` (item ``seq`` current, ``holds`` watched) claims: the
    point it holds and its bound user, and the first point after it (or after the item flown
    to, when it holds none) with its planned user; nothing without a mission or homing."""
    if held is None or homing:
        return Claims()
    holding = bound = None
    after = seq - 1
    w, b = holds.watch, holds.binding
    if w is not None and w.phase == "holding":
        point = held.point_at(w.seq)
        if point is not None:
            holding, after = point.hover_index, w.seq
            bound = b.user_id if b is not None and b.request_id is not None else None
    following = held.points_after(after)
    if not following:
        return Claims(holding=holding, bound=bound)
    point = following[0][1]
    return Claims(flying_to=point.hover_index, next_user=point.user_id, holding=holding, bound=bound)
