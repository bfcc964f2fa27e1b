"""What the fleet's members tell each other in flight, so that one user space is served by
several UAVs without a coordinator (docs/OPERATIONS.md, "A fleet"):

- **intentions** (``{prefix}/fleet/intentions/{vehicle}``): on every plan, the users of the
  points still to fly and when each service should begin (wall clock), and its claims: the
  next point's user, and the user a hold serves from the moment it is bound (``bound``, a
  typed claim that beats any plan's), and the points it holds and flies to next, as the
  offline ``claims`` planner commits (the rest of a plan may still change, and claiming it
  would starve the others). Who owns what several members claim is the one rule of
  ``model.fleet.claims``, shared with the offline planner; a member plans and binds only the
  users no other live member owns, and plans without the points the others claim. A member whose token goes loses its intentions at once:
  its users are planned by the others at their next decision (one interval).
- **services** (``{prefix}/fleet/served/{vehicle}``): each service flown. The others count
  it as their own (``world.FleetWorld``): the user's backlog less what was served, its
  services one more, so the fairness rule spans the fleet.

Every message is signed by its member's vehicle key and read only from the enrolled
(``protocol.fleet_signing``), and what a member may claim is bounded by what it can do, so
that even a member whose key was stolen cannot starve the fleet: at most ``MAX_CLAIMS``
users and points (its next point, its hold's), each due within ``DUE_PAST_S`` before and
``DUE_AHEAD_S`` after the message's signed time, a bound time within ``MAX_HOLD_S`` of it;
its route capped at ``MAX_ROUTE`` points; a service it reports counts only for a user it
claimed within ``CLAIM_KEPT_S``. A message beyond a bound is refused whole, and counted.

Both are zenoh.ext advanced publishers with a cache, read by advanced subscribers with
history, late-publisher detection and recovery (heartbeats): a member that joins late or
whose router restarted reads what it missed, rather than a replication protocol written
here. Pure bookkeeping apart from the declarations; thread-safe (zenoh calls back on its
own threads).
"""

from __future__ import annotations

import logging
import math
import statistics
import threading
import time
from collections import deque
from typing import Any, Callable, Iterable, Mapping

import msgspec
import zenoh
import zenoh.ext as zext

from protocol import FleetKeys, ProtocolError
from protocol.fleet_signing import FUTURE_S, FleetSigner, FleetVerifier, Unverified
from protocol.messages import FleetIntentions, FleetServed, Intention, decode, encode

from ...model.fleet.claims import BOUND, PLANNED, Claim, keeper, others_points, owned_by_others

log = logging.getLogger(__name__)

SERVED_CACHE = 256
"""Services each member keeps in its publisher's cache for members that join late."""
HEARTBEAT_S = 1.0
MAX_SERVED_QUEUED = 4096
MAX_INTENTIONS = 256
MAX_CLAIMS = 2
"""Users, and points, a member may claim at once: its next point's and its hold's."""
MAX_ROUTE = 32
"""Points of a member's route kept (the first, in the order it flies them): the airspace a
member gone armed keeps is what one sortie can fly, not the whole area."""
MAX_MEMBERS = 1024
"""Members whose intentions are kept."""
DUE_PAST_S = 120.0
"""A claim's due may lie at most this long before its message's signed time (a plan late
on its estimate); earlier (``due -1e15``) is refused: it would beat every honest claim."""
DUE_AHEAD_S = 3600.0
"""A claim's due may lie at most this long after its signed time (a sortie's flight)."""
MAX_HOLD_S = 900.0
"""A bound claim's time may lie at most this long before its signed time (a hold's length)."""
CLAIM_KEPT_S = 3600.0
"""A member's service counts for a user it claimed within this long; any other is refused."""
INTENTIONS_MAX_AGE_S = 900.0
"""Intentions signed longer ago than this are refused (the replay rule's window): a member
publishes them on every plan and every binding."""
SERVED_MAX_AGE_S = 3600.0
"""Services signed longer ago than this are refused (a sortie's flight)."""

def claims_refused(message: FleetIntentions, signed_at_s: float) -> str | None:
    """Why ``message`` (signed at ``signed_at_s``) claims more than its member can do, or None."""
    users = len(set(message.claims) | ({message.bound} if message.bound is not None else set()))
    if users > MAX_CLAIMS or len(message.points) > MAX_CLAIMS:
        return f"claims {users} users and {len(message.points)} points (at most {MAX_CLAIMS})"
    due = {i.user_id: i.due_s for i in message.users}
    for user in message.claims:
        if user in due and not signed_at_s - DUE_PAST_S <= due[user] <= signed_at_s + DUE_AHEAD_S:
            return f"claims {user} due {due[user] - signed_at_s:+.0f} s from its signed time (not a flight's)"
    if (message.bound is None) != (message.bound_at_s is None):
        return "bound without bound_at_s, or bound_at_s without bound"
    if message.bound_at_s is not None and not signed_at_s - MAX_HOLD_S <= message.bound_at_s <= signed_at_s + FUTURE_S:
        return f"bound {message.bound_at_s - signed_at_s:+.0f} s from its signed time (not a hold's)"
    if len(message.points_at_s) > len(message.points):
        return f"{len(message.points_at_s)} claim times for {len(message.points)} points"
    for at in message.points_at_s:
        if not signed_at_s - DUE_AHEAD_S <= at <= signed_at_s + FUTURE_S:
            return f"claims a point {at - signed_at_s:+.0f} s from its signed time (not a flight's)"
    return None


def points_of(message: FleetIntentions) -> dict[int, float]:
    """The points a message claims, each with when it was claimed (``time_s`` if not said)."""
    at = list(message.points_at_s) + [message.time_s] * (len(message.points) - len(message.points_at_s))
    return {int(k): t for k, t in zip(message.points, at)}


def claims_of(message: FleetIntentions) -> dict[str, Claim]:
    """The claims of a message within its bounds: its hold's user bound, its next point's planned."""
    due = {i.user_id: i.due_s for i in message.users}
    out: dict[str, Claim] = {u: (PLANNED, due[u]) for u in message.claims if u in due}
    if message.bound is not None and message.bound_at_s is not None:
        out[message.bound] = (BOUND, message.bound_at_s)
    return out


def first_route(route: Iterable[int]) -> list[int]:
    """The first ``MAX_ROUTE`` distinct points of ``route``, in its order."""
    return list(dict.fromkeys(int(k) for k in route))[:MAX_ROUTE]


def heard_line(ages_ms: list[float]) -> str:
    """``N intentions heard, p50 X ms, p99 Y ms, max Z ms``: read back by ``bench --fleet --scale``."""
    cuts = statistics.quantiles(ages_ms, n=100, method="inclusive") if len(ages_ms) > 1 else ages_ms * 99
    return (f"{len(ages_ms)} intentions heard, p50 {cuts[49]:.0f} ms, p99 {cuts[98]:.0f} ms, "
            f"max {max(ages_ms):.0f} ms")


class FleetLedger:
    """One member's side of the exchange: ``open`` on a session, ``intend`` on every plan,
    ``served`` on every service, ``take_served`` to read the others'."""

    def __init__(self, keys: FleetKeys, vehicle: str, alive: Callable[[], Iterable[str]],
                 lost: Callable[[], Iterable[str]], signer: FleetSigner | None, verifier: FleetVerifier,
                 wall: Callable[[], float] = time.time) -> None:
        self.keys = keys
        self.vehicle = vehicle
        self._alive = alive
        self._lost = lost
        """The members gone while their vehicles were armed (``FleetRoster.lost``)."""
        self._signer = signer
        """This member's key (None: a watcher, who only reads)."""
        self._verifier = verifier
        self._wall = wall
        self._lock = threading.Lock()
        self._intentions: dict[str, dict[str, float]] = {}
        self._claims: dict[str, dict[str, Claim]] = {}
        self._claimed: dict[str, dict[str, float]] = {}
        """vehicle -> user -> when (monotonic) it last claimed the user: its services count
        for these only."""
        self._points: dict[str, dict[int, float]] = {}
        """vehicle -> the points it claims -> when it claimed each (its clock)."""
        self._routes: dict[str, set[int]] = {}
        self._holding: dict[str, int | None] = {}
        """The point each member holds now (its last intentions'), if any."""
        self._answering: set[str] = set()
        """The members whose last intentions say they would answer a new request."""
        self._signed_at: dict[str, float] = {}
        """vehicle -> the signed time (its clock) of its latest intentions heard: its claims
        are known as they stood then (``heard_since``)."""
        self._told: FleetIntentions | None = None
        """This member's intentions as last told (``intend``), put again by ``beat``."""
        self._put_at = -math.inf
        """When (monotonic) they were last put."""
        self._served: deque[FleetServed] = deque(maxlen=MAX_SERVED_QUEUED)
        self._seen: set[tuple[str, str, float]] = set()
        self.refused: deque[str] = deque(maxlen=16)
        self.heard_ms: deque[float] = deque(maxlen=4096)
        """How long each of the others' intentions took from its signature to this member
        (its signed time against this member's clock): the fleet's agreement delay."""
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
        if self.heard_ms:
            log.info("fleet: %s", heard_line(list(self.heard_ms)))
        for thing in reversed(self._decl):
            try:
                thing.undeclare()
            except zenoh.ZError:
                pass
        self._decl.clear()
        self._intent_pub = self._served_pub = None
        self._told = None

    # --- this member's side ------------------------------------------------------------------
    def intend(self, due: Mapping[str, float], now_s: float, claims: Iterable[str] = (),
               points: Iterable[int] = (), route: Iterable[int] = (), bound: tuple[str, float] | None = None,
               holding: int | None = None, answering: bool = False, points_at: Mapping[int, float] | None = None) -> None:
        """Say which users this member's plan means to serve and when (wall clock), which of
        them it claims (``claims``: the next point's user), the user its hold serves and when
        it was bound (``bound``), the hovering points it claims (``points``: its next point,
        its hold's, ``holding``; ``points_at``: when it claimed each, ``now_s`` if not said),
        and whether it would answer a new request (``answering``: on its way home)."""
        users = sorted(due.items(), key=lambda kv: kv[1])[:MAX_INTENTIONS]
        claimed = sorted(set(claims) & set(due))[:MAX_CLAIMS - (bound is not None)]
        held = sorted(set(int(k) for k in points))[:MAX_CLAIMS]
        held_at = [(points_at or {}).get(k, now_s) for k in held]
        message = FleetIntentions(
            vehicle=self.vehicle, time_s=now_s, users=[Intention(u, d) for u, d in users], claims=claimed,
            points=held, route=first_route(route), bound=None if bound is None else bound[0],
            bound_at_s=None if bound is None else bound[1], holding=holding if holding in held else None,
            answering=answering and not held, points_at_s=held_at)
        with self._lock:
            self._holding[self.vehicle] = message.holding
            self._intentions[self.vehicle] = dict(users)
            self._claims[self.vehicle] = claims_of(message)
            self._points[self.vehicle] = points_of(message)
        self._told = message
        self._put(message)

    @property
    def told(self) -> bool:
        """Whether this member has told its intentions (``intend``) since it opened."""
        return self._told is not None

    def beat(self, every_s: float) -> None:
        """Put this member's intentions again, dated and signed now, if they were last put
        ``every_s`` ago or more: the others know its claims as they stand at the signed time
        (``heard_since``), whether they changed or not. Not put when the others would refuse
        them now (a due left ``DUE_PAST_S`` behind by a long hold): the next plan tells them."""
        told = self._told
        if told is None or time.monotonic() - self._put_at < every_s:
            return
        now = self._wall()
        again = msgspec.structs.replace(told, time_s=now)
        if claims_refused(again, now) is None:
            self._put(again)

    def _put(self, message: FleetIntentions) -> None:
        if self._intent_pub is not None and self._signer is not None:
            key = self.keys.intentions(self.vehicle)
            self._intent_pub.put(self._signer.seal(key, encode(message), self._wall()))
            self._put_at = time.monotonic()

    def served(self, user_id: str, tasks: int, at_s: float) -> None:
        """Tell the fleet of a service this member flew."""
        if self._served_pub is not None and self._signer is not None and tasks > 0:
            body = encode(FleetServed(vehicle=self.vehicle, user_id=user_id, tasks=tasks, at_s=at_s))
            self._served_pub.put(self._signer.seal(self.keys.served(self.vehicle), body, self._wall()))

    # --- what the others said ----------------------------------------------------------------
    def taken(self) -> set[str]:
        """The users another live member owns now."""
        return set(self.owners())

    def owners(self) -> dict[str, str]:
        """The users another live member owns now, each with that member."""
        return owned_by_others(self.vehicle, self.claims(), self._alive())

    def blocked_points(self) -> frozenset[int]:
        """The hovering points this member plans without: those the other live members claim,
        and of a member gone with its vehicle armed every point still to fly and the points it
        last claimed, the one it held among them (its vehicle holds there, then flies its
        mission home: it keeps that airspace until its service is back)."""
        lost = set(self._lost()) - {self.vehicle}
        with self._lock:
            claimed = others_points(self.vehicle, self._points, self._alive(), self._points)
            return claimed | {k for v in lost for k in (*self._routes.get(v, ()), *self._points.get(v, {}))}

    def yield_points(self) -> dict[int, str]:
        """The point this member holds that another live member claims too and keeps (it
        claimed it first, ``claims.keeper``: every member judges the same), with that member:
        this one arrived before it heard the other's claim, and ends its hold (before the
        other arrives, if it hears in time)."""
        alive = set(self._alive()) | {self.vehicle}
        with self._lock:
            own = self._holding.get(self.vehicle)
            if own is None:
                return {}
            claimants = {v: dict(p) for v, p in self._points.items() if own in p and v in alive}
        first = keeper(own, claimants, claimants, claimants)
        return {own: first} if first is not None and first != self.vehicle else {}

    def answering(self) -> set[str]:
        """The live members other than this one that would answer a new request now (on
        their way home, by their last intentions)."""
        alive = set(self._alive()) - {self.vehicle}
        with self._lock:
            return self._answering & alive

    def heard_since(self, vehicles: Iterable[str] | None = None) -> float:
        """The time (wall clock) as of which the claims of every other live member (or of
        ``vehicles``) are known here: the earliest of their latest intentions' signed times
        (each member's own clock; -inf while one was never heard, +inf without others). A
        claim this member made before it was heard by every member with it or after it (the
        claim rule has judged it: a claim made after it by another loses to it)."""
        others = set(self._alive() if vehicles is None else vehicles) - {self.vehicle}
        with self._lock:
            return min((self._signed_at.get(v, -math.inf) for v in others), default=math.inf)

    def not_heard_since(self, at: float, vehicles: Iterable[str]) -> list[str]:
        """Of ``vehicles`` (other than this member), those whose latest intentions heard here
        were signed before ``at`` (wall clock), or never heard: what a claim made then still
        waits on (``heard_since``), sorted."""
        with self._lock:
            return sorted(v for v in set(vehicles) - {self.vehicle} if self._signed_at.get(v, -math.inf) < at)

    def claims(self) -> dict[str, dict[str, Claim]]:
        """Every member's last claims (vehicle -> user -> claim), live or not."""
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

    def _read(self, sample: Any, kind: type, max_age_s: float, latest_wins: bool) -> tuple[Any, float] | None:
        """The signed message of an enrolled member in ``sample`` and its signed time, or None
        (refused: counted by the verifier, said in ``refused``)."""
        key = str(sample.key_expr)
        vehicle = self.keys.vehicle_of(key)
        if vehicle is None or vehicle == self.vehicle or sample.kind != zenoh.SampleKind.PUT:
            return None
        try:
            body, signed_at = self._verifier.open(key, vehicle, sample.payload.to_bytes(), self._wall(), max_age_s,
                                                  latest_wins)
            message = decode(body, kind)
        except Unverified as err:
            self.refused.append(f"{key}: {err.why}")
            return None
        except ProtocolError as err:
            self._refuse(f"{key}: {err}")
            return None
        if message.vehicle != vehicle:  # a member speaks for its own vehicle only
            self._refuse(f"{key}: names vehicle {message.vehicle!r}")
            return None
        return message, signed_at

    def _refuse(self, why: str) -> None:
        self._verifier.count_ignored()
        self.refused.append(why)

    def _on_intentions(self, sample: Any) -> None:
        read = self._read(sample, FleetIntentions, INTENTIONS_MAX_AGE_S, latest_wins=True)
        if read is None:
            return
        message, signed_at = read
        why = claims_refused(message, signed_at)
        if why is not None:
            self._refuse(f"{sample.key_expr}: {why}")
            return
        claims, now = claims_of(message), time.monotonic()
        with self._lock:
            self.heard_ms.append(max(0.0, (self._wall() - signed_at) * 1000.0))
            self._signed_at[message.vehicle] = max(signed_at, self._signed_at.get(message.vehicle, -math.inf))
            if message.vehicle not in self._intentions and len(self._intentions) >= MAX_MEMBERS:
                return
            self._intentions[message.vehicle] = {i.user_id: i.due_s for i in message.users}
            self._claims[message.vehicle] = claims
            self._points[message.vehicle] = points_of(message)
            self._holding[message.vehicle] = message.holding if message.holding in message.points else None
            if message.answering and not message.points:
                self._answering.add(message.vehicle)
            else:
                self._answering.discard(message.vehicle)
            self._routes[message.vehicle] = set(first_route(message.route))
            claimed = self._claimed.setdefault(message.vehicle, {})
            for user in claims:
                claimed[user] = now
            if len(claimed) > 4 * MAX_INTENTIONS:  # the oldest go: a member claims two at a time
                for user in sorted(claimed, key=claimed.__getitem__)[:len(claimed) - 4 * MAX_INTENTIONS]:
                    del claimed[user]

    def _on_served(self, sample: Any) -> None:
        read = self._read(sample, FleetServed, SERVED_MAX_AGE_S, latest_wins=False)
        if read is None:
            return
        message = read[0]
        with self._lock:
            at = self._claimed.get(message.vehicle, {}).get(message.user_id)
        if at is None or at < time.monotonic() - CLAIM_KEPT_S:  # it serves only whom it claimed
            self._refuse(f"{sample.key_expr}: {message.vehicle} served {message.user_id}, a user it never claimed")
            return
        mark = (message.vehicle, message.user_id, message.at_s)
        with self._lock:
            if mark in self._seen:  # history and live delivery may both bring it
                return
            if len(self._seen) >= 4 * MAX_SERVED_QUEUED:
                self._seen.clear()
            self._seen.add(mark)
            self._served.append(message)
