"""Who is in the fleet, as one zenoh session sees it: the members' liveliness tokens
(``{prefix}/fleet/members/{vehicle}``) and what each says of itself (``fleet_member`` on
``{prefix}/fleet/uavs/{vehicle}``), kept up to date by zenoh's own features rather than a
protocol written here:

- a liveliness subscriber with history: the tokens already declared, then each one declared
  or withdrawn (a service that stops, is killed or is cut off from the mesh loses its token:
  zenoh withdraws it when the session's transport goes);
- an advanced subscriber (``zenoh.ext``) with history, late-publisher detection and recovery:
  each member's announcement is kept in its advanced publisher's cache, so a member who joins
  later, or whose router restarted, still reads it;
- a subscriber to every member's signed position (``{prefix}/fleet/positions/{vehicle}``: a
  ``fleet_position``, in a fleet envelope), on which the fleet's separation is judged
  (``fleet.separation``). A member that leaves with its vehicle last seen armed stays in that
  judgement, unknown, until its service is back or ``lost_s`` has passed (its battery's
  flight: it has landed by then).

Every announcement and position is read only from an enrolled vehicle, signed and fresh
(``protocol.fleet_signing``); a token counts as a member only while a signed announcement of
its vehicle came within ``ANNOUNCE_STALE_S`` (the members sign theirs again every
``ANNOUNCE_EVERY_S``). Anything else is ignored and counted (``ignored``, ``refused``): a
rogue token or a forged announcement never makes a member, nor an "unknown" layer.

Read by the service (``service/fleet/presence.py``: its layer checked against the others')
and by ``operator watch``. Pure bookkeeping apart from the declarations; thread-safe (zenoh
calls back on its own threads).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import zenoh
import zenoh.ext as zext

from protocol import FleetKeys, ProtocolError
from protocol.fleet_signing import FUTURE_S, FleetVerifier, Unverified
from protocol.messages import FleetMember, FleetPosition, decode

from .airspace import MIN_HORIZONTAL_M, VERTICAL_SEPARATION_M
from .separation import STALE_S, Judgement, Seen, judge

SETTLE_POLL_S = 0.02
MAX_PUBLISHERS_KEPT = 8
"""Announcement publishers kept per vehicle: two already say it is claimed twice."""
ANNOUNCE_EVERY_S = 2.0
"""A member signs and puts its announcement again this often (``FleetPresence``)."""
ANNOUNCE_STALE_S = 10.0
"""A token counts as a member while its vehicle's last signed announcement arrived within
this: a replayed old announcement is refused as stale, and a rogue token beside a member gone
counts for this long at most."""
ANNOUNCE_MAX_AGE_S = 30.0
"""An announcement signed longer ago than this is refused (the replay rule's window)."""
POSITION_MAX_AGE_S = 10.0
"""A signed position older than this is refused (it is stale for separation long before)."""
MAX_LAYER_GAP_M = 100.0
"""Default bound of an announced ``min_gap_m`` (``fleet.max_layer_gap_m``): above it, refused."""
LOST_S = 1800.0
"""Default of ``fleet.lost_airspace_s``: how long a member gone armed stays unknown."""
MAX_VEHICLES_KEPT = 1024
"""Vehicles whose announcements and publishers are kept: a peer that announces thousands of
vehicle ids (a network without access control) cannot grow the roster without bound."""


@dataclass(frozen=True)
class Change:
    """One change of the roster: ``vehicle`` joined (its token seen), left (its token gone)
    or announced itself (``member``)."""

    vehicle: str
    what: str
    """"joined", "left" or "announced"."""
    member: FleetMember | None = None
    armed: bool = False
    """Left with its vehicle last seen armed: it may still be flying, and nothing tells where."""


class FleetRoster:
    """The members alive and their announcements (None until one arrives)."""

    def __init__(self, keys: FleetKeys, verifier: FleetVerifier, on_change: Callable[[Change], None] | None = None,
                 max_gap_m: float = MAX_LAYER_GAP_M, lost_s: float = LOST_S,
                 wall: Callable[[], float] = time.time) -> None:
        self.keys = keys
        self.verifier = verifier
        """The enrolled vehicles' keys and the replay rule (shared with the ledger)."""
        self.max_gap_m = max_gap_m
        self.lost_s = lost_s
        self._wall = wall
        self._on_change = on_change
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._said: dict[str, FleetMember] = {}
        self._said_at: dict[str, float] = {}
        """When (monotonic) each vehicle's last signed announcement arrived."""
        self.ignored_tokens = 0
        """Tokens of vehicles not enrolled (counted, never members)."""
        self._seen: dict[str, Seen] = {}
        """Each member's last signed position (its vehicle's own)."""
        self._lost: dict[str, Seen] = {}
        """The last position of each member gone with its vehicle armed, until it is back."""
        self._left_at: dict[str, float] = {}
        """When (monotonic) each enrolled vehicle's token last went."""
        self._publishers: dict[str, set[str]] = {}
        """The announcement publishers alive for each vehicle (zenoh.ext's publisher
        detection: one per service): two for one vehicle are two services claiming it."""
        self.refused: deque[str] = deque(maxlen=16)
        """The latest announcements refused (key: why), for the log (the sender's text:
        print it through ``protocol.text.printable``)."""
        self._subs: list[Any] = []

    def follow(self, session: Any, timeout_s: float = 2.0) -> None:
        """Declare the subscribers on ``session`` (tokens and announcements so far arrive
        through their history, then every change), then ask for the tokens alive and wait for
        the answer (at most ``timeout_s``): when this returns every member already declared is
        known, though its announcement may still be on its way (``settle``)."""
        self._subs.append(session.liveliness().declare_subscriber(self.keys.members, self._on_token, history=True))
        announces = zext.declare_advanced_subscriber(
            session, self.keys.announces, self._on_announce,
            history=zext.HistoryConfig(detect_late_publishers=True),
            recovery=zext.RecoveryConfig(heartbeat=True))
        self._subs.append(announces)
        self._subs.append(announces.detect_publishers(self._on_publisher, history=True))
        self._subs.append(session.declare_subscriber(self.keys.positions, self._on_position))
        for reply in session.liveliness().get(self.keys.members, timeout=timeout_s):
            if reply.ok is not None:
                self._on_token(reply.ok)

    def settle(self, timeout_s: float, positions: bool = False) -> bool:
        """Wait until every live member's announcement is known (and with ``positions`` its
        status too) (True), or ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not self._settled(positions):
            if time.monotonic() >= deadline:
                return False
            time.sleep(SETTLE_POLL_S)
        return True

    def _settled(self, positions: bool) -> bool:
        members, now = self.members(), self._wall()
        with self._lock:  # every enrolled token announced (a rogue one under an enrolled id: the wait's end)
            alive = set(self._alive)
        # a vehicle whose key signs from too far ahead will never be read: no use waiting for it
        announced = all(v in members or (self.verifier.clock_offset(v, now) or 0.0) > FUTURE_S for v in alive)
        with self._lock:
            return announced and (not positions or all(v in self._seen for v in members))

    def close(self) -> None:
        for sub in self._subs:
            try:
                sub.undeclare()
            except zenoh.ZError:  # the session is already closed
                pass
        self._subs.clear()

    def members(self) -> dict[str, FleetMember | None]:
        """Every member: its token alive and its signed announcement fresh (never None: a
        token without one is not a member)."""
        fresh = time.monotonic() - ANNOUNCE_STALE_S
        with self._lock:
            return {v: self._said[v] for v in sorted(self._alive) if self._said_at.get(v, -1e18) >= fresh}

    @property
    def ignored(self) -> int:
        """Fleet messages and tokens ignored so far: not enrolled, unsigned, stale, replayed,
        or beyond the bounds."""
        return self.verifier.ignored + self.ignored_tokens

    def _refuse(self, why: str) -> None:
        with self._lock:
            self.refused.append(why)

    def separation(self, min_horizontal_m: float = MIN_HORIZONTAL_M, stale_s: float = STALE_S,
                   vertical_separation_m: float = VERTICAL_SEPARATION_M) -> Judgement:
        """The fleet's separation now, on the members' last positions (``fleet.separation``)."""
        with self._lock:
            seen = dict(self._seen)
        return judge(self.members(), seen, time.monotonic(), min_horizontal_m, stale_s, self._gone_now(),
                     vertical_separation_m, self._silent_now())

    def positions(self) -> dict[str, Seen]:
        """Each live member's last signed position (its vehicle's own) and when it arrived
        (the monotonic clock)."""
        with self._lock:
            return dict(self._seen)

    def tokens(self) -> list[str]:
        """The enrolled vehicles whose member token is alive (members or not: a token counts
        as a member only with a fresh signed announcement)."""
        with self._lock:
            return sorted(self._alive)

    def unsure(self, within_s: float, claimed_at: float | None = None) -> set[str]:
        """The vehicles whose claims this member may not know, for a claim to settle on: every
        enrolled token alive (members, and those gone silent: their announcements stale, their
        claims maybe unheard) and those whose token went within ``within_s`` (a session that
        dropped for a moment comes back with what it claimed meanwhile). For a claim made at
        ``claimed_at`` (monotonic), also every vehicle whose token went after it: alive then,
        it could have claimed first, and its lease may have run out because this member's
        own radio was cut (20 UAVs: a binding settled on nobody 10.07 s after the fleet's
        tokens went, 0.4 s before it heard the fleet again, and with it another member's
        earlier binding of the same user)."""
        since = time.monotonic() - within_s
        if claimed_at is not None:
            since = min(since, claimed_at)
        with self._lock:
            return set(self._alive) | {v for v, at in self._left_at.items() if at >= since}

    def lost(self) -> list[str]:
        """The members gone while their vehicles were armed (not back yet, and last seen
        within ``lost_s``: by then the vehicle has landed, whatever it flew)."""
        return sorted(self._lost_now())

    def _lost_now(self) -> dict[str, Seen]:
        """The members gone and those gone silent, each armed when last seen."""
        return {**self._silent_now(), **self._gone_now()}

    def _gone_now(self) -> dict[str, Seen]:
        since = time.monotonic() - self.lost_s
        with self._lock:
            return {v: s for v, s in self._lost.items() if s.at_s >= since}

    def _silent_now(self) -> dict[str, Seen]:
        """Members whose token lives but whose announcements stopped (a radio out of reach:
        the token lasts until zenoh's lease ends, seconds later) with their vehicles armed when
        last seen: no longer members, yet not gone; lost as a member gone is, or their
        claims and airspace would vanish unjudged in between."""
        now = time.monotonic()
        with self._lock:
            return {v: self._seen[v] for v in self._alive
                    if v in self._said_at and now - self._said_at[v] > ANNOUNCE_STALE_S
                    and v in self._seen and self._seen[v].position.armed and now - self._seen[v].at_s <= self.lost_s}

    def _open(self, sample: Any, vehicle: str, max_age_s: float) -> bytes | None:
        """The signed message in ``sample`` from enrolled ``vehicle``, or None (refused, counted)."""
        key = str(sample.key_expr)
        try:
            body, _ = self.verifier.open(key, vehicle, sample.payload.to_bytes(), self._wall(), max_age_s)
        except Unverified as err:
            self._refuse(f"{key}: {err.why}")
            return None
        return body

    def _on_position(self, sample: Any) -> None:
        vehicle = self.keys.vehicle_of(str(sample.key_expr))
        if vehicle is None or sample.kind != zenoh.SampleKind.PUT:
            return
        with self._lock:
            if vehicle not in self._alive:  # a member's only: what it holds stays bounded
                return
        body = self._open(sample, vehicle, POSITION_MAX_AGE_S)
        if body is None:
            return
        try:
            position = decode(body, FleetPosition)
        except ProtocolError as err:
            self._refuse(f"{sample.key_expr}: {err}")
            return
        with self._lock:
            self._seen[vehicle] = Seen(position, time.monotonic())

    def publishers(self, vehicle: str) -> int:
        """How many services announce themselves as ``vehicle`` (1 for a member, as it should be)."""
        with self._lock:
            return len(self._publishers.get(vehicle, ()))

    def _on_publisher(self, sample: Any) -> None:
        # an advanced publisher's token: {announce key}/@adv/pub/{its session's id}/...
        head, _, tail = str(sample.key_expr).partition("/@adv/pub/")
        vehicle, who = self.keys.vehicle_of(head), tail.split("/", 1)[0]
        if vehicle is None or not who:
            return
        with self._lock:
            if vehicle not in self._publishers and len(self._publishers) >= MAX_VEHICLES_KEPT:
                return
            held = self._publishers.setdefault(vehicle, set())
            if sample.kind == zenoh.SampleKind.PUT:
                if len(held) < MAX_PUBLISHERS_KEPT:
                    held.add(who)
            else:
                held.discard(who)
                if not held:
                    del self._publishers[vehicle]

    def _on_token(self, sample: Any) -> None:
        vehicle = self.keys.vehicle_of(str(sample.key_expr))
        if vehicle is None:
            return
        if vehicle not in self.verifier.roster:  # anyone may declare a token: only the enrolled count
            with self._lock:
                self.ignored_tokens += 1
                self.refused.append(f"{sample.key_expr}: {vehicle} is not enrolled in the fleet's roster")
            return
        joined = sample.kind == zenoh.SampleKind.PUT
        armed = False
        with self._lock:
            if joined == (vehicle in self._alive):
                return
            if joined:
                self._alive.add(vehicle)
                if self._said_at.get(vehicle, -math.inf) >= time.monotonic() - ANNOUNCE_STALE_S:
                    self._lost.pop(vehicle, None)  # a member again at once, judged as one
                # else still lost until it announces itself again (``_on_announce``): a token
                # back alone made it neither a member nor lost, its points free to plan
            else:
                self._alive.discard(vehicle)
                self._left_at[vehicle] = time.monotonic()
                last = self._seen.pop(vehicle, None)
                armed = last is not None and last.position.armed
                if armed and len(self._lost) < MAX_VEHICLES_KEPT:
                    self._lost[vehicle] = last
        self._tell(Change(vehicle, "joined" if joined else "left", armed=armed))

    def _on_announce(self, sample: Any) -> None:
        key = str(sample.key_expr)
        vehicle = self.keys.vehicle_of(key)
        if vehicle is None or sample.kind != zenoh.SampleKind.PUT:
            return
        body = self._open(sample, vehicle, ANNOUNCE_MAX_AGE_S)
        if body is None:
            return
        try:
            member = decode(body, FleetMember)
        except ProtocolError as err:
            self._refuse(f"{key}: {err}")
            return
        if member.vehicle != vehicle:  # a member speaks for its own vehicle only
            self._refuse(f"{key}: names vehicle {member.vehicle!r}")
            return
        if member.min_gap_m > self.max_gap_m:  # obeyed, it would bar every other layer
            self.verifier.count_ignored()
            self._refuse(f"{key}: min_gap_m {member.min_gap_m:g} m above fleet.max_layer_gap_m {self.max_gap_m:g} m")
            return
        with self._lock:
            self._said_at[vehicle] = time.monotonic()
            if vehicle in self._alive:
                self._lost.pop(vehicle, None)  # a member again, judged as one
            if self._said.get(vehicle) == member:
                return
            self._said[vehicle] = member
        self._tell(Change(vehicle, "announced", member))

    def _tell(self, change: Change) -> None:
        if self._on_change is not None:
            self._on_change(change)
