"""One user's place across a fleet (``PlannerClient.follow_fleet_place``).

Every member that journalled the user's request publishes the user's ``user_place`` on its own
key, ``{prefix}/{vehicle}/users/{user_id}``, each time its plan changes: with a place and an
ETA if its plan has the user, without one if not (another member owns it, or nobody plans it
yet). So the user's place in the fleet is the member whose latest plan has it, soonest in wall
clock (``time_s + eta_s``: the members' ``time_s`` are wall clock, one time base for all); a
member whose service is gone is forgotten, for its last word may no longer be true.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from .messages import UserPlace


@dataclass(frozen=True)
class FleetPlace:
    """Where a user stands in the fleet: ``vehicle``'s plan has it, in ``place.place``, its
    hold due at ``due_s`` (wall clock, the member's estimate)."""

    vehicle: str
    place: UserPlace

    @property
    def due_s(self) -> float:
        return self.place.time_s + (self.place.eta_s or 0.0)


class FleetPlaces:
    """The latest ``user_place`` of one user from each live member. Thread-safe: zenoh's
    threads ``update`` and ``forget``, the user's reads ``where``."""

    def __init__(self, user_id: str) -> None:
        self.user_id = user_id
        self._lock = threading.Lock()
        self._latest: dict[str, UserPlace] = {}

    def update(self, vehicle: str, place: UserPlace) -> bool:
        """Keep ``place`` as ``vehicle``'s word, unless it is another user's or older than
        the one kept (an earlier sortie or plan: delivery may reorder). True if kept."""
        if place.user_id != self.user_id:
            return False
        with self._lock:
            kept = self._latest.get(vehicle)
            if kept is not None and (place.sortie, place.plan_id) < (kept.sortie, kept.plan_id):
                return False
            self._latest[vehicle] = place
        return True

    def forget(self, vehicle: str) -> bool:
        """``vehicle``'s service is gone: its word no longer counts. True if it was kept."""
        with self._lock:
            return self._latest.pop(vehicle, None) is not None

    def where(self) -> FleetPlace | None:
        """The member whose plan has the user soonest (ties: the smaller vehicle id), or None
        while no live member plans it."""
        with self._lock:
            planned = [FleetPlace(v, p) for v, p in self._latest.items() if p.place is not None]
        return min(planned, key=lambda f: (f.due_s, f.vehicle), default=None)

    def members(self) -> dict[str, UserPlace]:
        """Each live member's latest word about the user."""
        with self._lock:
            return dict(self._latest)
