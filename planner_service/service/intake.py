"""Request intake: validate -> journal -> ack. Pure: no event loop, no zenoh; the caller
gives it the payload bytes and a clock and sends back the reply it returns.

A bad request gets an ``ErrorReply`` naming the field and changes nothing. A good one is in
the journal before the ack exists; a user's newer request replaces its pending one.

Bounds (``IntakeConfig``), so that a flood on the request key cannot grow the journal, the
planner or the fsync load without limit: pending requests (a new user beyond it is refused
"busy: ..."; replacing one's own pending request is always allowed), distinct users in the
sortie ("full: ..."), accepted requests per second ("busy: ...", a one-second token bucket).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Callable

from protocol import MAX_PAYLOAD_BYTES, Area, ErrorReply, ProtocolError, TaskAck, decode_request

from .config import IntakeConfig
from .errors import JournalError
from .journal import Journal
from .throttle import RateLimit

BUSY = "busy: "
"""Start of the message of a refusal that a retry later can get past."""


@dataclass(frozen=True)
class Accepted:
    """A request went into the journal."""

    request_id: int
    user_id: str
    tasks: int
    replaced: tuple[int, ...]
    reply: TaskAck


@dataclass(frozen=True)
class Rejected:
    """A request was refused; ``reply.field`` names why."""

    reply: ErrorReply


class Intake:
    """Turns request payloads into journal rows and replies."""

    def __init__(self, journal: Journal, area: Area, clock: Callable[[], float],
                 limits: IntakeConfig = IntakeConfig()) -> None:
        self.journal = journal
        self.area = area
        self.clock = clock
        self.limits = limits
        self.closed_reason: str | None = None
        """When set, every request is refused with this message (shutdown, sortie over)."""
        self._users = journal.user_ids()
        """Users of this sortie (at most ``limits.max_users``), kept here so that the check
        does not scan the journal on every request."""
        self._rate = RateLimit(limits.max_requests_per_s, clock())

    def new_sortie(self) -> None:
        """The journal began a new sortie: open, and count that sortie's users."""
        self.closed_reason = None
        self._users = self.journal.user_ids()

    def handle(self, payload: bytes | None) -> Accepted | Rejected:
        ref = client_ref(payload)
        if self.closed_reason is not None:
            return Rejected(ErrorReply(field="service", message=self.closed_reason, client_ref=ref))
        if payload is None:
            return Rejected(ErrorReply(field="payload", message="a task request needs a payload", client_ref=ref))
        try:
            request = decode_request(payload, self.area)
        except ProtocolError as err:
            return Rejected(ErrorReply(field=_sendable(err.field), message=_sendable(err.message), client_ref=ref))
        now = self.clock()
        refusal = self._over_limit(request.user_id, now)
        if refusal is not None:
            return Rejected(ErrorReply(field="service", message=refusal, client_ref=request.client_ref))
        try:
            request_id, replaced = self.journal.accept(
                request.user_id, request.x_m, request.y_m, request.z_m, request.tasks, request.client_ref, now)
            position = len(self.journal.pending())
        except JournalError as err:
            return Rejected(ErrorReply(field="journal", message=_sendable(str(err)), client_ref=request.client_ref))
        self._users.add(request.user_id)
        ack = TaskAck(request_id=request_id, user_id=request.user_id, accepted_at_s=now,
                      queue_position=position, client_ref=request.client_ref)
        return Accepted(request_id, request.user_id, request.tasks, tuple(replaced), ack)

    def _over_limit(self, user_id: str, now_s: float) -> str | None:
        """Why this valid request cannot be taken now, or None. Checked in this order so that
        a refused request costs no rate token."""
        lim = self.limits
        if user_id not in self._users and len(self._users) >= lim.max_users:
            return (f"full: this sortie already has {len(self._users)} users (intake.max_users); "
                    f"a new user id is not taken")
        pending = self.journal.pending()
        if len(pending) >= lim.max_pending_requests and all(r.user_id != user_id for r in pending):
            return (f"{BUSY}{len(pending)} requests pending (intake.max_pending_requests); "
                    f"retry once some are served")
        if not self._rate.take(now_s):
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
