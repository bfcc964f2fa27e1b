"""What the fleet's members tell each other in flight, so that one user space is served by
several UAVs without a coordinator (docs/OPERATIONS.md, "A fleet"):

- **intentions** (``{prefix}/fleet/intentions/{vehicle}``): on every plan, the users of the
  points still to fly and when each service should begin (wall clock), and its claims: the
  next point's user, and the user a hold serves from the moment it is bound (``bound_due``:
  before any plan's), as the offline ``claims`` planner commits (the rest of a plan may still
  change, and claiming it would starve the others). A user several members claim belongs to
  the earliest (ties: the smaller vehicle id); every
  member computes the same from the same messages, and a member plans and binds only the
  users no other live member owns. A member whose token goes loses its intentions at once:
  its users are planned by the others at their next decision (one interval).
- **services** (``{prefix}/fleet/served/{vehicle}``): each service flown. The others count
  it as their own (``world.FleetWorld``): the user's backlog less what was served, its
  services one more, so the fairness rule spans the fleet.

Both are zenoh.ext advanced publishers with a cache, read by advanced subscribers with
history, late-publisher detection and recovery (heartbeats): a member that joins late or
whose router restarted reads what it missed, rather than a replication protocol written
here. Pure bookkeeping apart from the declarations; thread-safe (zenoh calls back on its
own threads).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable, Iterable, Mapping

import zenoh
import zenoh.ext as zext

from protocol import FleetKeys, ProtocolError
from protocol.messages import FleetIntentions, FleetServed, Intention, decode, encode

SERVED_CACHE = 256
"""Services each member keeps in its publisher's cache for members that join late."""
HEARTBEAT_S = 1.0
MAX_SERVED_QUEUED = 4096
MAX_INTENTIONS = 256
MAX_CLAIMS = 8
MAX_MEMBERS = 1024
"""Members whose intentions are kept: a peer announcing thousands of vehicle ids (a network
without access control) cannot grow them without bound."""


BOUND_LEAD_S = 1.0e10
"""A user bound by a hold is claimed as due this long before its binding: a hold under way
beats every plan's estimate (an ETA is a prediction, and may be early), and of two holds the
one bound first wins."""


def bound_due(at_s: float) -> float:
    """The due of a user bound by a hold at ``at_s`` (wall clock): before any plan's."""
    return at_s - BOUND_LEAD_S


def owner(user: str, intentions: Mapping[str, Mapping[str, float]]) -> str | None:
    """The member that serves ``user`` (the earliest due, ties to the smaller vehicle id) of
    ``intentions`` (vehicle -> user -> due); None when no member means to."""
    dues = [(due[user], vehicle) for vehicle, due in intentions.items() if user in due]
    return min(dues)[1] if dues else None


def owned_by_others(own: str, intentions: Mapping[str, Mapping[str, float]], alive: Iterable[str]) -> dict[str, str]:
    """The users a live member other than ``own`` owns (``owner``), each with that member:
    this member neither plans, binds nor records them."""
    members = set(alive) | {own}
    live = {v: d for v, d in intentions.items() if v in members}
    users = {u for v, d in live.items() if v != own for u in d}
    owners = {u: owner(u, live) for u in users}
    return {u: v for u, v in owners.items() if v is not None and v != own}


class FleetLedger:
    """One member's side of the exchange: ``open`` on a session, ``intend`` on every plan,
    ``served`` on every service, ``take_served`` to read the others'."""

    def __init__(self, keys: FleetKeys, vehicle: str, alive: Callable[[], Iterable[str]],
                 lost: Callable[[], Iterable[str]] = lambda: ()) -> None:
        self.keys = keys
        self.vehicle = vehicle
        self._alive = alive
        self._lost = lost
        """The members gone while their vehicles were armed (``FleetRoster.lost``)."""
        self._lock = threading.Lock()
        self._intentions: dict[str, dict[str, float]] = {}
        self._claims: dict[str, dict[str, float]] = {}
        self._points: dict[str, set[int]] = {}
        self._routes: dict[str, set[int]] = {}
        self._served: deque[FleetServed] = deque(maxlen=MAX_SERVED_QUEUED)
        self._seen: set[tuple[str, str, float]] = set()
        self.refused: deque[str] = deque(maxlen=16)
        self._decl: list[Any] = []
        self._intent_pub: Any = None
        self._served_pub: Any = None

    def open(self, session: Any) -> None:
        """A member's side: its publishers, and ``follow``."""
        miss = zext.MissDetectionConfig(heartbeat=HEARTBEAT_S)
        self._intent_pub = zext.declare_advanced_publisher(
            session, self.keys.intentions(self.vehicle), cache=zext.CacheConfig(max_samples=1),
            sample_miss_detection=miss, publisher_detection=True)
        self._served_pub = zext.declare_advanced_publisher(
            session, self.keys.served(self.vehicle), cache=zext.CacheConfig(max_samples=SERVED_CACHE),
            sample_miss_detection=miss, publisher_detection=True)
        self._decl += [self._intent_pub, self._served_pub]
        self.follow(session)

    def follow(self, session: Any) -> None:
        """Read every member's intentions and services (a watcher's side: ``vehicle`` "")."""
        for key, handler in ((self.keys.all_intentions, self._on_intentions), (self.keys.all_served, self._on_served)):
            self._decl.append(zext.declare_advanced_subscriber(
                session, key, handler, history=zext.HistoryConfig(detect_late_publishers=True),
                recovery=zext.RecoveryConfig(heartbeat=True)))

    def close(self) -> None:
        for thing in reversed(self._decl):
            try:
                thing.undeclare()
            except zenoh.ZError:
                pass
        self._decl.clear()
        self._intent_pub = self._served_pub = None

    # --- this member's side ------------------------------------------------------------------
    def intend(self, due: Mapping[str, float], now_s: float, claims: Iterable[str] = (),
               points: Iterable[int] = (), route: Iterable[int] = ()) -> None:
        """Say which users this member's plan means to serve and when (wall clock), which of
        them it claims (``claims``: the next point's user and the one a hold serves) and the
        hovering points it claims (``points``: its next point, its hold's)."""
        users = sorted(due.items(), key=lambda kv: kv[1])[:MAX_INTENTIONS]
        claimed = sorted(set(claims) & set(due))[:MAX_CLAIMS]
        held = sorted(set(int(k) for k in points))[:MAX_CLAIMS]
        with self._lock:
            self._intentions[self.vehicle] = dict(users)
            self._claims[self.vehicle] = {u: due[u] for u in claimed}
            self._points[self.vehicle] = set(held)
        if self._intent_pub is not None:
            self._intent_pub.put(encode(FleetIntentions(
                vehicle=self.vehicle, time_s=now_s, users=[Intention(u, d) for u, d in users], claims=claimed,
                points=held, route=sorted(set(int(k) for k in route))[:512])))

    def served(self, user_id: str, tasks: int, at_s: float) -> None:
        """Tell the fleet of a service this member flew."""
        if self._served_pub is not None and tasks > 0:
            self._served_pub.put(encode(FleetServed(vehicle=self.vehicle, user_id=user_id, tasks=tasks, at_s=at_s)))

    # --- what the others said ----------------------------------------------------------------
    def taken(self) -> set[str]:
        """The users another live member owns now."""
        return set(self.owners())

    def owners(self) -> dict[str, str]:
        """The users another live member owns now, each with that member."""
        return owned_by_others(self.vehicle, self.claims(), self._alive())

    def blocked_points(self) -> frozenset[int]:
        """The hovering points this member plans without: those the other live members claim,
        and every point still to fly of a member gone with its vehicle armed (its vehicle
        flies its mission home: it keeps that airspace until its service is back)."""
        alive, lost = set(self._alive()), set(self._lost()) - {self.vehicle}
        with self._lock:
            claimed = {k for v, ks in self._points.items() if v != self.vehicle and v in alive for k in ks}
            return frozenset(claimed | {k for v in lost for k in self._routes.get(v, ())})

    def claims(self) -> dict[str, dict[str, float]]:
        """Every member's last claims (vehicle -> user -> due), live or not."""
        with self._lock:
            return {v: dict(d) for v, d in self._claims.items()}

    def intentions(self) -> dict[str, dict[str, float]]:
        """Every member's last intentions (vehicle -> user -> due), live or not."""
        with self._lock:
            return {v: dict(d) for v, d in self._intentions.items()}

    def take_served(self) -> list[FleetServed]:
        """The other members' services heard since the last call, oldest first."""
        with self._lock:
            out = list(self._served)
            self._served.clear()
        return out

    def _read(self, sample: Any, kind: type) -> Any:
        key = str(sample.key_expr)
        vehicle = self.keys.vehicle_of(key)
        if vehicle is None or vehicle == self.vehicle or sample.kind != zenoh.SampleKind.PUT:
            return None
        try:
            message = decode(sample.payload.to_bytes(), kind)
        except ProtocolError as err:
            self.refused.append(f"{key}: {err}")
            return None
        if message.vehicle != vehicle:  # a member speaks for its own vehicle only
            self.refused.append(f"{key}: names vehicle {message.vehicle!r}")
            return None
        return message

    def _on_intentions(self, sample: Any) -> None:
        message = self._read(sample, FleetIntentions)
        if message is not None:
            due = {i.user_id: i.due_s for i in message.users}
            with self._lock:
                if message.vehicle not in self._intentions and len(self._intentions) >= MAX_MEMBERS:
                    return
                self._intentions[message.vehicle] = due
                self._claims[message.vehicle] = {u: due[u] for u in message.claims if u in due}
                self._points[message.vehicle] = set(message.points)
                self._routes[message.vehicle] = set(message.route)

    def _on_served(self, sample: Any) -> None:
        message = self._read(sample, FleetServed)
        if message is None:
            return
        mark = (message.vehicle, message.user_id, message.at_s)
        with self._lock:
            if mark in self._seen:  # history and live delivery may both bring it
                return
            if len(self._seen) >= 4 * MAX_SERVED_QUEUED:
                self._seen.clear()
            self._seen.add(mark)
            self._served.append(message)
