"""What feeds the fleet picture from zenoh: every vehicle's status, plan, events and users'
places under one prefix, the services' liveliness tokens, and (with the fleet's roster) the
members' signed announcements, positions and claims.

Whose word counts: with the fleet's roster, an enrolled vehicle's status is taken from its
signed status (``{prefix}/fleet/statuses/{vehicle}``, the same status signed by the
vehicle's key) and never from the plain ``{prefix}/{vehicle}/status``, which any peer could
publish on an open network; the plain keys are read for vehicles the roster does not
enrol (a lone UAV, whose keys zenoh's access control guards). Every message is decoded and
bounded by ``protocol``; a foreign or newer one is skipped, not guessed at.

The users' positions (in the pending requests) come only from the operator's ``status``,
asked every ``state_every_s`` of each vehicle whose operator key is given: they are personal,
the public state has none.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable, Mapping

import zenoh

from protocol import Event, FleetKeys, Keys, Plan, ProtocolError, Status, UserPlace, decode
from protocol.client import ClientError, PlannerClient
from protocol.fleet_signing import FleetVerifier, Unverified

from ..service.fleet.ledger import FleetLedger
from ..service.fleet.roster import POSITION_MAX_AGE_S, FleetRoster
from .picture import FleetPicture

log = logging.getLogger(__name__)

POLL_S = 0.2
"""How often the roster's members, the fleet's judgement and the claims are read into the
picture (the roster and the ledger keep them; the statuses come as they arrive)."""
STATE_EVERY_S = 2.0
MAX_VEHICLES = 256
"""Vehicles kept at most: a rogue peer publishing under endless vehicle names cannot grow the
picture without bound."""


class LiveFeed:
    """Subscriptions on ``session`` feeding ``picture`` (guarded by ``lock``); ``on_change``
    is called (from zenoh's threads or the poller) after each change."""

    def __init__(self, session: Any, picture: FleetPicture, lock: threading.Lock,
                 on_change: Callable[[], None] = lambda: None, *, fleet_keys: Mapping[str, Any] | None = None,
                 operator_keys: Mapping[str, bytes] | None = None,
                 state_every_s: float | None = STATE_EVERY_S) -> None:
        self.session = session
        self.picture = picture
        self.lock = lock
        self.on_change = on_change
        self.prefix = picture.prefix
        self.fleet_keys = dict(fleet_keys or {})
        """The roster's public keys: the vehicles whose statuses count only signed."""
        self.operator_keys = dict(operator_keys or {})
        """The operator key of each vehicle ("*": every vehicle's) for the pending requests."""
        self.state_every_s = state_every_s
        """How often each vehicle's pending requests are asked (None: never, the owner asks)."""
        self._subs: list[Any] = []
        self._clients: dict[str, PlannerClient] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.roster: FleetRoster | None = None
        self.ledger: FleetLedger | None = None
        self.verifier = FleetVerifier(self.fleet_keys)
        """Reads the members' signed messages (it only reads: it signs nothing)."""

    def start(self) -> None:
        s = self.session
        self._subs += [
            s.declare_subscriber(f"{self.prefix}/*/status", self._handler("status", Status)),
            s.declare_subscriber(f"{self.prefix}/*/plan", self._handler("plan", Plan)),
            s.declare_subscriber(f"{self.prefix}/*/events", self._handler("events", Event)),
            s.declare_subscriber(f"{self.prefix}/*/users/*", self._handler("users", UserPlace)),
            s.liveliness().declare_subscriber(f"{self.prefix}/*/alive", self._on_alive, history=True),
        ]
        keys = FleetKeys(self.prefix)
        self._subs.append(s.declare_subscriber(keys.signed_statuses, self._on_signed_status))
        self.roster = FleetRoster(keys, self.verifier)
        self.roster.follow(s, timeout_s=0.5)
        self.ledger = FleetLedger(keys, "", lambda: self.roster.members().keys(), self.roster.lost, None,
                                  self.verifier)
        self.ledger.follow(s)
        self._thread = threading.Thread(target=self._poll, name="live-feed", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        for sub in self._subs:
            try:
                sub.undeclare()
            except zenoh.ZError:
                pass
        for part in (self.ledger, self.roster, *self._clients.values()):
            if part is not None:
                part.close()
        self._subs, self._clients = [], {}

    def client(self, vehicle: str) -> PlannerClient:
        """A client for ``vehicle``'s service on the feed's session (kept: it remembers the
        service's nonce and its queriers)."""
        with self.lock:
            client = self._clients.get(vehicle)
            if client is None:
                client = self._clients[vehicle] = PlannerClient(keys=Keys(self.prefix, vehicle), session=self.session)
            return client

    def operator_key(self, vehicle: str) -> bytes | None:
        return self.operator_keys.get(vehicle, self.operator_keys.get("*"))

    # -- subscriptions ------------------------------------------------------------------------

    def _vehicle(self, key: str, leaf: str) -> str | None:
        """The vehicle of ``{prefix}/{vehicle}/{leaf}[/...]``, if it is one the picture may hold."""
        parts = key[len(self.prefix) + 1:].split("/") if key.startswith(self.prefix + "/") else []
        if len(parts) < 2 or parts[1] != leaf or parts[0] == "fleet":
            return None
        try:
            Keys(self.prefix, parts[0])
        except ProtocolError:
            return None
        if parts[0] not in self.picture.vehicles and len(self.picture.vehicles) >= MAX_VEHICLES:
            return None
        return parts[0]

    def _on_signed_status(self, sample: Any) -> None:
        """An enrolled member's status, signed by its vehicle's key (``FleetKeys.signed_status``)."""
        key = str(sample.key_expr)
        vehicle = FleetKeys(self.prefix).vehicle_of(key)
        if vehicle not in self.fleet_keys or sample.kind != zenoh.SampleKind.PUT:
            return
        try:
            body, _ = self.verifier.open(key, vehicle, sample.payload.to_bytes(), time.time(), POSITION_MAX_AGE_S)
            status = decode(body, Status)
        except (Unverified, ProtocolError):
            return  # counted by the verifier (a forgery, a replay) or not ours to parse
        if status.vehicle != vehicle:
            return
        with self.lock:
            self.picture.on_status(vehicle, status, time.monotonic())
        self.on_change()

    def _handler(self, leaf: str, kind: Any) -> Callable[[Any], None]:
        def handle(sample: Any) -> None:
            vehicle = self._vehicle(str(sample.key_expr), leaf)
            if vehicle is None or sample.kind != zenoh.SampleKind.PUT:
                return
            if leaf == "status" and vehicle in self.fleet_keys:
                return  # an enrolled member's status counts only signed (its position)
            try:
                message = decode(sample.payload.to_bytes(), kind)
            except ProtocolError:
                return  # a newer schema or a foreign publisher: not ours to parse
            with self.lock:
                if leaf == "status":
                    self.picture.on_status(vehicle, message, time.monotonic())
                elif leaf == "plan":
                    self.picture.on_plan(vehicle, message)
                elif leaf == "events":
                    self.picture.on_event(vehicle, message)
                else:
                    self.picture.on_place(vehicle, message)
            self.on_change()
        return handle

    def _on_alive(self, sample: Any) -> None:
        vehicle = self._vehicle(str(sample.key_expr), "alive")
        if vehicle is None:
            return
        with self.lock:
            self.picture.on_alive(vehicle, sample.kind == zenoh.SampleKind.PUT)
        self.on_change()

    # -- the poller ---------------------------------------------------------------------------

    def _poll(self) -> None:
        next_state = 0.0
        while not self._stop.wait(POLL_S):
            self.read_fleet()
            if self.state_every_s is not None and time.monotonic() >= next_state:
                next_state = time.monotonic() + self.state_every_s
                self._read_pending()

    def settle(self, timeout_s: float) -> bool:
        """Wait until every live member's announcement and position is known (or ``timeout_s``)."""
        assert self.roster is not None
        return self.roster.settle(timeout_s, positions=True)

    def read_fleet(self) -> None:
        """The roster's members, the fleet's judgement and the claims into the picture."""
        assert self.roster is not None and self.ledger is not None
        members = self.roster.members()
        judgement = self.roster.separation() if members or self.roster.lost() else None
        claims = {v: sorted(c) for v, c in self.ledger.claims().items() if v in members}
        with self.lock:
            before = self.picture.version
            self.picture.on_fleet(members, judgement, claims, self.roster.lost(), self.roster.ignored)
            changed = self.picture.version != before
        if changed:
            self.on_change()

    def _read_pending(self) -> None:
        """Each known vehicle's pending requests, by the operator's status (with its key)."""
        with self.lock:
            vehicles = sorted(self.picture.vehicles)
        for vehicle in vehicles:
            if self._stop.is_set():
                return
            key = self.operator_key(vehicle)
            if key is None:
                note, pending = "no operator key for this vehicle (give --operator-key)", None
            else:
                try:
                    reply = self.client(vehicle).operator("status", timeout_s=1.0, key=key)
                    pending = None if reply.state is None else list(reply.state.pending)
                    note = "" if pending is not None else "the service's status held no state"
                except (ClientError, ProtocolError) as err:
                    note, pending = f"no answer to the operator's status ({err.field}: {err.message})", None
            with self.lock:
                self.picture.on_pending(vehicle, pending, note)
            self.on_change()
