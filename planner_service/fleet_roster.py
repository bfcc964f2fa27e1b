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
- a subscriber to every vehicle's ``status``: the members' own positions, on which the
  fleet's separation is judged (``fleet_separation``). A member that leaves with its vehicle
  last seen armed stays in that judgement, unknown, until its service is back.

Read by the service (``service/fleet_presence.py``: its layer checked against the others')
and by ``operator watch``. Pure bookkeeping apart from the declarations; thread-safe (zenoh
calls back on its own threads).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

import zenoh
import zenoh.ext as zext

from protocol import FleetKeys, ProtocolError, Status
from protocol.messages import FleetMember, decode

from .fleet_separation import MIN_HORIZONTAL_M, STALE_S, Judgement, Seen, judge

SETTLE_POLL_S = 0.02
MAX_PUBLISHERS_KEPT = 8
"""Announcement publishers kept per vehicle: two already say it is claimed twice."""
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

    def __init__(self, keys: FleetKeys, on_change: Callable[[Change], None] | None = None) -> None:
        self.keys = keys
        self._on_change = on_change
        self._lock = threading.Lock()
        self._alive: set[str] = set()
        self._said: dict[str, FleetMember] = {}
        self._seen: dict[str, Seen] = {}
        """Each member's last status (its vehicle's own position)."""
        self._lost: dict[str, Seen] = {}
        """The last status of each member gone with its vehicle armed, until it is back."""
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
        self._subs.append(session.declare_subscriber(self.keys.statuses, self._on_status))
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
        members = self.members()
        with self._lock:
            return None not in members.values() and (not positions or all(v in self._seen for v in members))

    def close(self) -> None:
        for sub in self._subs:
            try:
                sub.undeclare()
            except zenoh.ZError:  # the session is already closed
                pass
        self._subs.clear()

    def members(self) -> dict[str, FleetMember | None]:
        """Every member whose token is alive, with its announcement (None: not read yet)."""
        with self._lock:
            return {v: self._said.get(v) for v in sorted(self._alive)}

    def separation(self, min_horizontal_m: float = MIN_HORIZONTAL_M, stale_s: float = STALE_S) -> Judgement:
        """The fleet's separation now, on the members' last statuses (``fleet_separation``)."""
        with self._lock:
            seen, lost = dict(self._seen), dict(self._lost)
        return judge(self.members(), seen, time.monotonic(), min_horizontal_m, stale_s, lost)

    def lost(self) -> list[str]:
        """The members gone while their vehicles were armed (not back yet)."""
        with self._lock:
            return sorted(self._lost)

    def _on_status(self, sample: Any) -> None:
        vehicle = self.keys.status_vehicle(str(sample.key_expr)) or ""
        with self._lock:
            if vehicle not in self._alive:  # a member's only: what it holds stays bounded
                return
        try:
            status = decode(sample.payload.to_bytes(), Status)
        except ProtocolError:
            return
        with self._lock:
            self._seen[vehicle] = Seen(status, time.monotonic())

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
        joined = sample.kind == zenoh.SampleKind.PUT
        armed = False
        with self._lock:
            if joined == (vehicle in self._alive):
                return
            if joined:
                self._alive.add(vehicle)
                self._lost.pop(vehicle, None)  # judged as a member again
            else:
                self._alive.discard(vehicle)
                last = self._seen.pop(vehicle, None)
                armed = last is not None and last.status.armed
                if armed and len(self._lost) < MAX_VEHICLES_KEPT:
                    self._lost[vehicle] = last
        self._tell(Change(vehicle, "joined" if joined else "left", armed=armed))

    def _on_announce(self, sample: Any) -> None:
        key = str(sample.key_expr)
        vehicle = self.keys.vehicle_of(key)
        if vehicle is None or sample.kind != zenoh.SampleKind.PUT:
            return
        try:
            member = decode(sample.payload.to_bytes(), FleetMember)
        except ProtocolError as err:
            with self._lock:
                self.refused.append(f"{key}: {err}")
            return
        if member.vehicle != vehicle:  # a member speaks for its own vehicle only
            with self._lock:
                self.refused.append(f"{key}: names vehicle {member.vehicle!r}")
            return
        with self._lock:
            if self._said.get(vehicle) == member:
                return
            if vehicle not in self._said and len(self._said) >= MAX_VEHICLES_KEPT:
                self.refused.append(f"{key}: more than {MAX_VEHICLES_KEPT} vehicles announced")
                return
            self._said[vehicle] = member
        self._tell(Change(vehicle, "announced", member))

    def _tell(self, change: Change) -> None:
        if self._on_change is not None:
            self._on_change(change)
