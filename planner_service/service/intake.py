"""Request intake: validate -> journal -> ack. Pure: no event loop, no zenoh; the caller
gives it the payload bytes and a clock and sends back the reply it returns.

A bad request gets an ``ErrorReply`` naming the field and changes nothing. A good one is in
the journal before the ack exists; a user's newer request replaces its pending one.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Callable

from protocol import MAX_PAYLOAD_BYTES, Area, ErrorReply, ProtocolError, TaskAck, decode_request

from .errors import JournalError
from .journal import Journal


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

    def __init__(self, journal: Journal, area: Area, clock: Callable[[], float]) -> None:
        self.journal = journal
        self.area = area
        self.clock = clock
        self.closed_reason: str | None = None
        """When set, every request is refused with this message (shutdown, sortie over)."""

    def handle(self, payload: bytes | None) -> Accepted | Rejected:
        ref = _client_ref(payload)
        if self.closed_reason is not None:
            return Rejected(ErrorReply(field="service", message=self.closed_reason, client_ref=ref))
        if payload is None:
            return Rejected(ErrorReply(field="payload", message="a task request needs a payload", client_ref=ref))
        try:
            request = decode_request(payload, self.area)
        except ProtocolError as err:
            return Rejected(ErrorReply(field=_sendable(err.field), message=_sendable(err.message), client_ref=ref))
        now = self.clock()
        try:
            request_id, replaced = self.journal.accept(
                request.user_id, request.x_m, request.y_m, request.z_m, request.tasks, request.client_ref, now)
            position = len(self.journal.pending())
        except JournalError as err:
            return Rejected(ErrorReply(field="journal", message=_sendable(str(err)), client_ref=request.client_ref))
        ack = TaskAck(request_id=request_id, user_id=request.user_id, accepted_at_s=now,
                      queue_position=position, client_ref=request.client_ref)
        return Accepted(request_id, request.user_id, request.tasks, tuple(replaced), ack)


def _client_ref(payload: bytes | None) -> str | None:
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
