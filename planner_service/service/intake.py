"""Request intake: validate -> journal -> ack. Pure: no event loop, no zenoh; the caller
gives it the payload bytes, the query's key and clocks, and sends back the reply it returns.

A request is a user's data waiting (docs/PROTOCOL.md, "Requests"): its newest request is
its request in force (the journal keeps the older ones, ``replaced``); a request of no tasks
says it has nothing (more) to offload and closes as it arrives. A request that says
``served_seen`` is counted less what was served to its user since it counted
(``TaskRequest.counted_backlog``; the journal keeps doing so as services are recorded), so
one that crossed a service on the wire asks for nothing already served; the fairness rule,
the pending bound and ``Accepted.backlog`` judge that count. A bad request gets an
``ErrorReply`` naming the field and changes nothing. A good one is in the journal before
the ack exists.

On a user's own request key (``{prefix}/{vehicle}/request/{user_id}``), which access
control can give to that user's certificate alone, the request must be that user's: the
key binds the user id. The plain key (``.../request``) binds none, for deployments without
access control.

Bounds (``IntakeConfig``), so that a flood on the request keys cannot grow the journal, the
planner or the fsync load without limit: pending requests that can be served (a new one
beyond it is refused "busy: ..."; replacing one's own is always allowed; a request that
cannot be served in this sortie -- no tasks, or the fairness rule leaves its user out --
holds no place), distinct users in the sortie ("full: ..."; such a request holds no user's
place either), accepted requests per second
("busy: ...", a one-second token bucket on the monotonic clock: a wall clock stepped back
refuses nothing; the wall clock only stamps the journal).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Callable, Mapping

from protocol import MAX_PAYLOAD_BYTES, Area, ErrorReply, FleetKeys, Keys, ProtocolError, TaskAck, decode_request, printable

from ..model import Scenario, pack
from ..model._jit import py
from ..model.fairness import is_eligible
from .config import IntakeConfig
from .errors import JournalError
from .journal import NO_TASKS, Journal
from .places import Place
from .rows import RequestRow
from .throttle import RateLimit

BUSY = "busy: "
"""Start of the message of a refusal that a retry later can get past."""

Unservable = Callable[[int, int], "str | None"]
"""(backlog, services of the user in the sortie) -> why such a request cannot be served in
this sortie, or None if it can."""


def no_tasks(tasks: int, services: int) -> str | None:
    """The rule without a model: only a request of no tasks cannot be served."""
    return NO_TASKS if tasks <= 0 else None


def fairness_rule(scenario: Scenario) -> Unservable:
    """The model's rule (3), (9c): no tasks, the user served ``max_services_per_user`` times,
    or a repeat asking no more than ``fairness_threshold_tasks``. The model's own rule, run
    uncompiled: a first call must not stall the event loop compiling it."""
    p = pack(scenario)
    eligible = py(is_eligible)

    def unservable(tasks: int, services: int) -> str | None:
        if eligible(p, tasks, services):
            return None
        if tasks <= 0:
            return NO_TASKS
        if services >= scenario.max_services_per_user:
            return f"fairness: already served {services} times (limit {scenario.max_services_per_user})"
        return f"fairness: a repeat needs more than {scenario.fairness_threshold_tasks:g} tasks, asked {tasks}"
    return unservable


@dataclass(frozen=True)
class Accepted:
    """A request went into the journal and is now its user's request in force."""

    request_id: int
    user_id: str
    tasks: int
    """The user's whole backlog, as it says."""
    replaced: tuple[int, ...]
    reply: TaskAck
    unservable: str | None = None
    """Why this request cannot be served in this sortie (it holds no pending place); None
    if it can."""
    backlog: int | None = None
    """The backlog the service counts for it: ``tasks`` less the tasks served since the
    user counted them (``TaskRequest.counted_backlog``); None: ``tasks``."""
    served_seen: int | None = None
    """What the request said was served that its count had taken off, in this sortie."""

    @property
    def left(self) -> int:
        """The backlog the service counts (``backlog``, else ``tasks``)."""
        return self.tasks if self.backlog is None else self.backlog

    @property
    def done(self) -> bool:
        """The user has nothing (more) to offload (none stated, or all of it served since it
        counted): its wait ends; if it is being served, its upload is done (the loop may end
        the hold)."""
        return self.left == 0

    def describe(self) -> str:
        """One line for a log or an event, wire text escaped."""
        text = f"{self.tasks} tasks"
        if self.served_seen is not None:
            text += f" ({self.served_seen} served seen; {self.left} left)"
        text += f"; replaces {list(self.replaced)}" if self.replaced else ""
        if self.unservable:
            text += f"; cannot be served in this sortie: {self.unservable}"
        if self.reply.client_ref is not None:
            text += f"; client_ref {printable(self.reply.client_ref)}"
        return text


@dataclass(frozen=True)
class Rejected:
    """A request was refused; ``reply.field`` names why."""

    reply: ErrorReply

    def describe(self) -> str:
        """One line for a log or an event, wire text (a field's name, the client's ref) escaped."""
        text = f"{printable(self.reply.field)}: {printable(self.reply.message)}"
        if self.reply.client_ref is not None:
            text += f" (client_ref {printable(self.reply.client_ref)})"
        return text


class Intake:
    """Turns request payloads into journal rows and replies.

    ``clock`` is the wall clock stamped in the journal and the ack (``accepted_at_s``);
    ``monotonic`` times the rate bound; ``unservable`` is the fairness rule (default: only
    a request of no tasks cannot be served; the service passes ``fairness_rule(scenario)``)."""

    def __init__(self, journal: Journal, area: Area, clock: Callable[[], float],
                 limits: IntakeConfig = IntakeConfig(), *, keys: Keys = Keys(),
                 monotonic: Callable[[], float] = time.monotonic, unservable: Unservable = no_tasks,
                 fleet_keys: FleetKeys | None = None, vehicle: str = "") -> None:
        self.journal = journal
        self.area = area
        self.clock = clock
        self.monotonic = monotonic
        self.limits = limits
        self.keys = keys
        self.fleet_keys = fleet_keys
        """A fleet member's: requests on the fleet's request keys are taken too."""
        self.vehicle = vehicle
        """Named in every ack (a fleet's user reads which member answered)."""
        self.unservable = unservable
        self.closed_reason: str | None = None
        """When set, every request is refused with this message (shutdown, sortie over)."""
        self._users = journal.counted_user_ids()
        """Users that hold a place in this sortie (at most ``limits.max_users``): each took it
        with its first request that could be served. Kept here so that the check does not
        scan the journal on every request."""
        self._rate = RateLimit(limits.max_requests_per_s, monotonic())
        self.places: Mapping[str, Place] = {}
        """Every user's place in the current plan (``places.plan_places``), for the ack."""

    def new_sortie(self) -> None:
        """The journal began a new sortie: open, count that sortie's users, no plan yet."""
        self.closed_reason = None
        self._users = self.journal.counted_user_ids()
        self.places = {}

    def set_places(self, places: Mapping[str, Place]) -> None:
        """The places of the plan just made (the loop calls it on every re-plan)."""
        self.places = dict(places)

    def handle(self, payload: bytes | None, key: str | None = None) -> Accepted | Rejected:
        """One query on a request key: ``key`` is the query's key expression (None: the
        plain request key)."""
        ref = client_ref(payload)
        if self.closed_reason is not None:
            return Rejected(ErrorReply(field="service", message=self.closed_reason, client_ref=ref))
        try:
            key_user = None if key is None else self._key_user(key)
        except ProtocolError as err:
            return Rejected(ErrorReply(field=err.field, message=_sendable(err.message), client_ref=ref))
        if payload is None:
            return Rejected(ErrorReply(field="payload", message="a task request needs a payload", client_ref=ref))
        try:
            request = decode_request(payload, self.area)
        except ProtocolError as err:
            return Rejected(ErrorReply(field=_sendable(err.field), message=_sendable(err.message), client_ref=ref))
        if key_user is not None and request.user_id != key_user:
            return Rejected(ErrorReply(field="user_id", client_ref=request.client_ref, message=(
                f"this request key is user {key_user}'s ({key}); "
                f"a request on it must carry that user_id")))
        try:
            services = self.journal.service_counts()
            pending = self.journal.pending()
            served = self.journal.served_tasks(request.user_id)
        except JournalError as err:
            return Rejected(ErrorReply(field="journal", message=_sendable(str(err)), client_ref=request.client_ref))
        sortie = self.journal.sortie
        seen = request.seen_in(sortie)
        backlog = request.counted_backlog(sortie, served)
        why_not = self.unservable(backlog, services.get(request.user_id, 0))
        refusal = self._over_limit(request.user_id, why_not is None, pending, services)
        if refusal is not None:
            return Rejected(ErrorReply(field="service", message=refusal, client_ref=request.client_ref))
        now = self.clock()
        try:
            request_id, replaced = self.journal.accept(
                request.user_id, request.x_m, request.y_m, request.z_m, request.tasks, request.client_ref, now,
                served_seen=seen)
            position = next((i for i, r in enumerate(self.journal.pending(), 1) if r.request_id == request_id), 0)
        except JournalError as err:
            return Rejected(ErrorReply(field="journal", message=_sendable(str(err)), client_ref=request.client_ref))
        if why_not is None:  # a request of no tasks, or one the fairness rule leaves out, takes no place
            self._users.add(request.user_id)
        place = self.places.get(request.user_id)
        ack = TaskAck(request_id=request_id, user_id=request.user_id, accepted_at_s=now, queue_position=position,
                      client_ref=request.client_ref, sortie=sortie, served_tasks=served,
                      place=None if place is None else place.place, eta_s=None if place is None else place.eta_s,
                      note="" if why_not is None else f"cannot be served in this sortie: {why_not}"[:256],
                      vehicle=self.vehicle)
        return Accepted(request_id, request.user_id, request.tasks, tuple(replaced), ack, why_not, backlog, seen)

    def _key_user(self, key: str) -> str | None:
        fk = self.fleet_keys
        if fk is not None and (key == fk.request or key.startswith(fk.request + "/")):
            return fk.request_user(key)
        return self.keys.request_user(key)

    def _over_limit(self, user_id: str, servable: bool, pending: list[RequestRow],
                    services: dict[str, int]) -> str | None:
        """Why this valid request cannot be taken now, or None. Checked in this order so that
        a refused request costs no rate token. Only requests that can be served need a
        user's place or count against the pending bound (each user's own is left out: it is
        replaced), so that requests which cannot be served fill neither bound."""
        lim = self.limits
        if servable and user_id not in self._users and len(self._users) >= lim.max_users:
            return (f"full: this sortie already has {len(self._users)} users (intake.max_users); "
                    f"a new user id is not taken")
        if servable:
            waiting = sum(1 for r in pending if r.user_id != user_id
                          and self.unservable(r.backlog, services.get(r.user_id, 0)) is None)
            if waiting >= lim.max_pending_requests:
                return (f"{BUSY}{waiting} requests pending (intake.max_pending_requests); "
                        f"retry once some are served")
        if not self._rate.take(self.monotonic()):
            return (f"{BUSY}over {lim.max_requests_per_s:g} requests/s (intake.max_requests_per_s); "
                    f"retry in a second")
        return None


def client_ref(payload: bytes | None) -> str | None:
    """The client's correlation id, echoed even in an error reply when it can be read.

    Read loosely (json.loads takes NaN, which msgspec refuses), so it guards against what
    json.loads lets through: nesting deeper than the interpreter's recursion limit raises
    RecursionError (not a ValueError), and a lone surrogate escape gives a str that cannot
    be encoded back into the reply.
    """
    if payload is None or len(payload) > MAX_PAYLOAD_BYTES:
        return None
    try:
        data = json.loads(payload)
    except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        return None
    ref = data.get("client_ref") if isinstance(data, dict) else None
    if not isinstance(ref, str) or len(ref) > 64 or _sendable(ref) != ref:
        return None
    return ref


def _sendable(text: str, limit: int = 256) -> str:
    """``text`` cut to ``limit`` characters, lone surrogates written as escapes: an error
    reply must always encode, and decode within the ``ErrorReply`` limits."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")[:limit]
