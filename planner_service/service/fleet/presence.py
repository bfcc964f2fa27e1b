"""A service's membership of the fleet (``[fleet] enabled``): its token, its announcement,
and the separation rule checked before it takes a request or commands its vehicle.

Each UAV flies its own altitude layer (its scenario's ``altitude_m``); no two members' layers
may lie closer than the larger of their layer gaps (``airspace.layer_gap_m``: the vertical
separation plus a margin for altitude errors). A service joining the fleet:

1. asks which tokens are alive: another service already a member under its own vehicle id is
   refused (two services for one vehicle would both command it), and so is one that sees
   another announce itself under that id at the same moment (step 3: zenoh.ext's publisher
   detection counts the announcement publishers of each vehicle; of two, one at most goes on);
2. declares its announcement (an advanced publisher with a cache of one) and its token, and
   follows the others' (``planner_service.service.fleet.roster``);
3. waits ``fleet.discovery_s`` for the mesh to tell it of every member, then for the
   announcements of the members it saw (at most ``discovery_s`` or ``ANNOUNCE_WAIT_S``, the
   longer: each normally comes within milliseconds of its token, so the wait costs nothing
   unless one is missing, and a loaded computer is not taken for a missing layer);
4. refuses to go on when a member's layer is too close to its own (a token with no signed,
   fresh announcement is no member: anyone may declare a token), or when an enrolled
   vehicle's clock reads more than ``fleet.max_clock_offset_s`` from this computer's (its
   signed times: the bounds on claims, the freshness of positions and the ownership of a
   user all read the signed times against the reader's clock). Two services started at once
   with one layer both see the other in step 3 and both refuse: neither flies into the
   other's layer.

Every message it puts on the fleet's keys is signed with its vehicle's key, and it reads only
the enrolled vehicles' (``protocol.fleet_signing``; ``fleet.roster``): its announcement again
every ``ANNOUNCE_EVERY_S``, its position on each status (``publish_position``). What it
ignores (not enrolled, unsigned, stale, replayed, beyond the bounds) is counted and logged.

A member that joins later with a clashing layer is refused by its own check; this service
logs it. The check keeps two services from being configured into one layer; what the vehicles
really fly is for their own positions to show (docs/OPERATIONS.md, "A fleet").
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Iterable, Mapping, Sequence

import zenoh
import zenoh.ext as zext

from protocol import FleetKeys, Status
from protocol.fleet_signing import FleetSigner, FleetVerifier
from protocol.messages import FleetMember, FleetPosition, encode
from protocol.text import printable

from .ledger import FleetLedger
from .airspace import MIN_HORIZONTAL_M, VERTICAL_SEPARATION_M
from .roster import ANNOUNCE_EVERY_S, LOST_S, MAX_LAYER_GAP_M, Change, FleetRoster
from .separation import STALE_S, Judgement, occupied, origin_of, whereabouts
from ..errors import ServiceError

log = logging.getLogger("planner_service.fleet")
HEARTBEAT_S = 1.0
"""The announcement's publisher says every this many seconds which sample it last sent, so
that a subscriber that missed it (a router lost meanwhile) asks its cache again (the
subscribers' recovery)."""
ANNOUNCE_WAIT_S = 5.0
"""Seconds a joining service waits at least for the announcements of the members it saw."""
OVER_EVERY_S = 0.25
"""How often the points the others' vehicles are over are found again (``others_over``)."""
IGNORED_LOG_EVERY_S = 10.0
"""The count of fleet messages ignored is logged at most this often (a flood is one line)."""
MAX_CLOCK_OFFSET_S = 2.0
"""How far another member's clock may read from this computer's (``fleet.max_clock_offset_s``)."""
MESSAGE_AGE_S = ANNOUNCE_EVERY_S + 0.5
"""How old the freshest signed message of a member may be when it arrives (its announcement
is signed every ``ANNOUNCE_EVERY_S``; a joining service may hear nothing fresher), which a
clock offset measured on it does not show."""


class MembershipError(ServiceError):
    """The service may not join the fleet (its vehicle id or its layer clashes)."""


POSITION_DECIMALS = 2
"""A member's position is told to the centimetre: finer digits are bytes on every member's
downlink and below any autopilot's accuracy."""


def compact_position(status: Status) -> FleetPosition:
    """What the other members judge separation on, of ``status``."""
    d = POSITION_DECIMALS
    return FleetPosition(x_m=round(status.x_m, d), y_m=round(status.y_m, d), z_m=round(status.z_m, d),
                         armed=status.armed)


def layer_clashes(own: FleetMember, others: Mapping[str, FleetMember | None]) -> list[str]:
    """Why ``own`` may not fly beside the live members ``others`` (their announcements, None
    where none was read): one sentence per clash, [] when there is none."""
    out = []
    for vehicle, member in sorted(others.items()):
        if vehicle == own.vehicle:
            continue
        if member is None:
            out.append(f"{vehicle} is a member but its layer is unknown (no announcement read)")
            continue
        gap = max(own.min_gap_m, member.min_gap_m)
        if abs(own.layer_m - member.layer_m) < gap:
            out.append(f"{vehicle} flies at {member.layer_m:g} m, within {gap:g} m of this UAV's layer "
                       f"{own.layer_m:g} m (fleet.vertical_separation_m + fleet.altitude_margin_m)")
    return out


def clock_clashes(offsets: Mapping[str, float | None], max_offset_s: float) -> list[str]:
    """Why this service may not fly beside the vehicles whose clocks read ``offsets`` ahead of
    its own (None: nothing signed heard of it; ``FleetVerifier.clock_offset``): one sentence
    per vehicle surely too far off. An offset is measured on the freshest signed message,
    whose age on the way lowers it by up to ``MESSAGE_AGE_S``: ahead, it is at least what is
    measured; behind, it may be that much less than measured."""
    out = []
    for vehicle, offset in sorted(offsets.items()):
        if offset is None or -max_offset_s - MESSAGE_AGE_S <= offset <= max_offset_s:
            continue
        way, by = ("ahead of", offset) if offset > 0 else ("behind", -offset - MESSAGE_AGE_S)
        out.append(f"{vehicle}'s clock reads {by:.1f} s {way} this computer's (at most {max_offset_s:g} s, "
                   f"fleet.max_clock_offset_s): synchronise the clocks (NTP, chrony)")
    return out


class FleetPresence:
    """One service's membership: ``join`` on an open session, ``leave`` at the end."""

    def __init__(self, keys: FleetKeys, own: FleetMember, signer: FleetSigner, verifier: FleetVerifier,
                 min_horizontal_m: float = MIN_HORIZONTAL_M, stale_s: float = STALE_S,
                 max_gap_m: float = MAX_LAYER_GAP_M, lost_s: float = LOST_S,
                 wall: Callable[[], float] = time.time, *,
                 vertical_separation_m: float = VERTICAL_SEPARATION_M,
                 max_clock_offset_s: float = MAX_CLOCK_OFFSET_S) -> None:
        self.keys = keys
        self.own = own
        self.signer = signer
        """This vehicle's key: every fleet message it puts is signed."""
        self.min_horizontal_m = min_horizontal_m
        self.vertical_separation_m = vertical_separation_m
        self.max_clock_offset_s = max_clock_offset_s
        self.stale_s = stale_s
        self._clocks_said: set[str] = set()
        self._wall = wall
        self._conflicts: set[str] = set()
        self._unknown: set[str] = set()
        self._ignored_logged = (0.0, 0)
        self._over: frozenset[int] = frozenset()
        self._over_at = -OVER_EVERY_S
        self.roster = FleetRoster(keys, verifier, self._on_change, max_gap_m, lost_s, wall)
        self.ledger = FleetLedger(keys, own.vehicle, lambda: self.roster.members().keys(), self.roster.lost,
                                  signer, verifier, wall)
        """Intentions and services exchanged with the other members (opened on joining)."""
        self.joined = False
        """A member now (``join`` went through, ``leave`` not called)."""
        self._publisher: Any = None
        self._position_pub: Any = None
        self._status_pub: Any = None
        self._token: Any = None
        self._stop = threading.Event()
        self._announcer: threading.Thread | None = None

    def join(self, session: Any, discovery_s: float) -> None:
        """Become a member (blocking: run it off the event loop), or ``MembershipError`` naming
        every clash; nothing is left declared after a refusal."""
        v = self.own.vehicle
        self.roster.follow(session, discovery_s)
        self.roster.settle(max(discovery_s, ANNOUNCE_WAIT_S))  # a token counts with its announcement only
        if v in self.roster.members():  # before this service's own token is declared
            self.leave()
            raise MembershipError(f"fleet: another service is already the member for vehicle {v} "
                                  f"({self.keys.member(v)}); one service per UAV")
        self._publisher = zext.declare_advanced_publisher(
            session, self.keys.announce(v), cache=zext.CacheConfig(max_samples=1),
            sample_miss_detection=zext.MissDetectionConfig(heartbeat=HEARTBEAT_S), publisher_detection=True)
        self._announce()
        self._stop.clear()
        self._announcer = threading.Thread(target=self._announce_again, name="fleet-announce", daemon=True)
        self._announcer.start()
        self._position_pub = session.declare_publisher(self.keys.position(v))
        self._status_pub = session.declare_publisher(self.keys.signed_status(v))
        self._token = session.liveliness().declare_token(self.keys.member(v))
        time.sleep(discovery_s)
        self.roster.settle(max(discovery_s, ANNOUNCE_WAIT_S))
        clashes = layer_clashes(self.own, self._others()) + clock_clashes(self._clock_offsets(), self.max_clock_offset_s)
        if self.roster.publishers(v) > 1:  # started at the same moment under one id
            clashes.insert(0, f"another service announces itself as vehicle {v} too; one service per UAV")
        if clashes:
            self.leave()
            raise MembershipError("fleet: " + "; ".join(printable(c, 200) for c in clashes))
        self.ledger.open(session)
        self.joined = True
        others = self._others()
        log.info("fleet: joined as %s, layer %g m; %s", v, self.own.layer_m,
                 ", ".join(f"{k} at {m.layer_m:g} m" for k, m in others.items() if m) or "no other member yet")

    def _announce(self) -> None:
        publisher = self._publisher
        if publisher is not None:
            try:
                publisher.put(self.signer.seal(self.keys.announce(self.own.vehicle), encode(self.own), self._wall()))
            except zenoh.ZError:  # undeclared meanwhile (leaving)
                pass

    def _announce_again(self) -> None:
        """Sign and put the announcement again every ``ANNOUNCE_EVERY_S``: a member counts
        only while its announcement is fresh, so a replayed old one cannot keep it."""
        while not self._stop.wait(ANNOUNCE_EVERY_S):
            self._announce()

    def publish_position(self, status: Status) -> None:
        """With each status: this vehicle's position, signed, for the others' separation watch
        (``fleet_position``: every member reads it), and the whole status, signed, for the
        operator's live map (only the map subscribes to it)."""
        if self._position_pub is None or self._status_pub is None or not self.joined:
            return
        v, now = self.own.vehicle, self._wall()
        self._position_pub.put(self.signer.seal(self.keys.position(v), encode(compact_position(status)), now))
        self._status_pub.put(self.signer.seal(self.keys.signed_status(v), encode(status), now))

    def _log_ignored(self) -> None:
        """Say how many fleet messages were ignored since the last line, with the latest reason."""
        since, seen = self._ignored_logged
        now, count = time.monotonic(), self.roster.ignored
        if count > seen and now - since >= IGNORED_LOG_EVERY_S:
            latest = self.roster.refused[-1] if self.roster.refused else ""
            log.warning("fleet: %d fleet messages or tokens ignored (not enrolled, unsigned, stale, replayed or "
                        "beyond the bounds); the latest: %s", count - seen, printable(latest, 200))
            self._ignored_logged = (now, count)

    def _clock_offsets(self) -> dict[str, float | None]:
        """How far each other enrolled vehicle with a live token reads ahead of this clock."""
        now = self._wall()
        return {k: self.roster.verifier.clock_offset(k, now) for k in self.roster.tokens() if k != self.own.vehicle}

    def _log_clocks(self) -> None:
        """Say once (an error) when a member's clock has drifted beyond the bound, and when it is back."""
        off = {c.split("'", 1)[0]: c for c in clock_clashes(self._clock_offsets(), self.max_clock_offset_s)}
        for vehicle in sorted(off.keys() - self._clocks_said):
            log.error("fleet: %s", printable(off[vehicle], 200))
        for vehicle in sorted(self._clocks_said - off.keys()):
            log.warning("fleet: %s's clock within fleet.max_clock_offset_s again", printable(vehicle, 64))
        self._clocks_said = set(off)

    def _others(self) -> dict[str, FleetMember | None]:
        return {k: m for k, m in self.roster.members().items() if k != self.own.vehicle}

    def _on_change(self, change: Change) -> None:
        if change.vehicle == self.own.vehicle or not self.joined:
            return
        if change.what == "left" and change.armed:
            log.error("fleet: %s left with its vehicle armed: it may still be flying its mission, and its "
                      "position is unknown until its service is back", change.vehicle)
        elif change.what == "announced" and change.member is not None:
            clash = layer_clashes(self.own, {change.vehicle: change.member})
            if clash:
                log.error("fleet: %s (its service should refuse to fly)", printable(clash[0], 200))
            else:
                log.info("fleet: %s announced layer %g m", change.vehicle, change.member.layer_m)
        else:
            log.info("fleet: %s %s", change.vehicle, change.what)

    def members(self) -> dict[str, FleetMember | None]:
        return self.roster.members()

    def whereabouts(self, vehicles: Iterable[str]) -> dict[str, tuple[float, float]]:
        """Where each of ``vehicles`` is (metres east and north of this member's origin), of
        those whose position is fresh and armed."""
        return whereabouts(origin_of(self.own), vehicles, self.roster.members(), self.roster.positions(),
                           time.monotonic(), self.stale_s)

    def others_over(self, points: Sequence[tuple[float, float]], radius_m: float) -> frozenset[int]:
        """The hovering points another live member's vehicle is over now (within ``radius_m``
        horizontally of ``points``, this member's frame, by its signed position: fresh and
        armed). Found again at most every ``OVER_EVERY_S`` (the positions come at 2 Hz, the
        service asks at its tick)."""
        now = time.monotonic()
        if now - self._over_at >= OVER_EVERY_S:
            others = [v for v in self.roster.members() if v != self.own.vehicle]
            self._over, self._over_at = occupied(self.whereabouts(others), points, radius_m), now
        return self._over

    def check_separation(self) -> Judgement:
        """Judge the fleet's separation now and log what changed: a pair that lost it (an
        error), a pair that has it again, a member whose position became unknown or known."""
        self._log_ignored()
        self._log_clocks()
        j = self.roster.separation(self.min_horizontal_m, self.stale_s, self.vertical_separation_m)
        conflicts = {c.split(":", 1)[0]: c for c in j.conflicts}
        unknown = {u.split(":", 1)[0]: u for u in j.unknown}
        for pair in sorted(conflicts.keys() - self._conflicts):
            log.error("fleet: SEPARATION LOST %s (fleet.min_horizontal_m %g, fleet.vertical_separation_m %g)",
                      printable(conflicts[pair], 200), self.min_horizontal_m, self.vertical_separation_m)
        for pair in sorted(self._conflicts - conflicts.keys()):
            log.warning("fleet: separation back for %s", printable(pair, 140))
        for vehicle in sorted(unknown.keys() - self._unknown):
            log.warning("fleet: %s: its separation cannot be judged", printable(unknown[vehicle], 140))
        for vehicle in sorted(self._unknown - unknown.keys()):
            log.info("fleet: %s's position known again", printable(vehicle, 64))
        self._conflicts, self._unknown = set(conflicts), set(unknown)
        return j

    def leave(self) -> None:
        """Withdraw the token and the announcement, stop following the others."""
        self.joined = False
        self._stop.set()
        if self._announcer is not None:
            self._announcer.join(timeout=2 * ANNOUNCE_EVERY_S)
            self._announcer = None
        self.ledger.close()
        for thing in (self._token, self._publisher, self._position_pub, self._status_pub):
            if thing is not None:
                try:
                    thing.undeclare()
                except zenoh.ZError:
                    pass
        self._token = self._publisher = self._position_pub = self._status_pub = None
        self.roster.close()
