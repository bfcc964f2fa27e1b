"""The operator's commands (``start``, ``hold``, ``status`` on ``{prefix}/{vehicle}/operator``),
pure: a command and the current authority in, the new authority and the reply out. No
event loop, no zenoh, no clock of its own: the sortie loop gives it what it knows
(``OperatorContext``) and applies what it returns.

Authority is whether the service may command modes and arming (docs/OPERATIONS.md):

- ``none``: never given in this sortie, or handed back by the operator's ``hold``;
- ``operator``: given by the operator (``start``, or ``mavlink.start_mission = true``,
  which is the operator's standing authorisation written in the configuration);
- ``revoked``: taken away by a change the service did not command (a pilot's mode, a
  failsafe, a landing): the sortie loop calls ``revoke``; only a new ``start`` gives it back.

This module decides what a command does to that state; when the service may use its
authority, and when it loses it, is the sortie loop's (``revoke``, ``OperatorContext``).
``hold`` is always accepted: taking authority away from the service must never fail.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import msgspec

from protocol import ErrorReply, OperatorCommand, OperatorReply, ProtocolError, Status, decode_operator_command
from protocol.text import printable

from .intake import client_ref

AuthorityName = Literal["none", "operator", "revoked"]
MESSAGE_CHARS = 256
"""``OperatorReply.message`` and ``Status.authority_detail`` hold at most this many."""
REASON_CHARS = 100
"""How much of the operator's reason is kept in the authority's detail."""


@dataclass(frozen=True)
class AuthorityState:
    """Who may command the vehicle, why, and since when (the service's clock)."""

    authority: AuthorityName = "none"
    detail: str = "not given yet: the operator's start is awaited"
    since_s: float = 0.0


@dataclass(frozen=True)
class OperatorContext:
    """What the sortie loop knows when a command arrives."""

    phase: str
    """``Status.phase`` now (``OperatorReply.phase``)."""
    now_s: float
    degraded: str = ""
    """``Status.degraded``: a degraded service takes no authority."""
    start_refusal: str | None = None
    """Why a ``start`` cannot be taken now (no autopilot, battery unknown, no position,
    between sorties...), in words; None: it can. The sortie loop's rules."""
    status: Status | None = None
    """The snapshot sent back with every reply."""


def initial(start_mission: bool, now_s: float) -> AuthorityState:
    """The authority a service starts with: the operator's standing authorisation with
    ``mavlink.start_mission = true``, none otherwise."""
    if start_mission:
        return AuthorityState("operator", "given by the configuration (mavlink.start_mission = true)", now_s)
    return AuthorityState("none", "not given yet: the operator's start is awaited", now_s)


def revoke(state: AuthorityState, why: str, now_s: float) -> AuthorityState:
    """The service lost its authority to a change it did not command (``why``: "the pilot
    switched to LOITER", "the vehicle landed (LAND)"); unchanged if it had none."""
    if state.authority != "operator":
        return state
    return AuthorityState("revoked", _cut(f"revoked: {why}; the operator's start is awaited"), now_s)


def handle(command: OperatorCommand, state: AuthorityState,
           context: OperatorContext) -> tuple[AuthorityState, OperatorReply]:
    """What ``command`` does: (the new authority, the reply). Never raises."""
    reason = printable(command.reason, REASON_CHARS) if command.reason else ""
    because = f" ({reason})" if reason else ""
    new = state
    if command.command == "start":
        if context.degraded:
            accepted, message = False, f"the service is degraded: {context.degraded}"
        elif context.start_refusal is not None:
            accepted, message = False, context.start_refusal
        elif state.authority == "operator":
            accepted, message = True, f"the service already has the authority: {state.detail}"
        else:
            new = AuthorityState("operator", _cut(f"given by the operator{because}"), context.now_s)
            accepted, message = True, ("authority given: the service may arm, switch to the mission mode and start or "
                                       f"resume the mission{because}")
    elif command.command == "hold":
        accepted = True
        if state.authority == "operator":
            new = AuthorityState("none", _cut(f"handed back by the operator's hold{because}"), context.now_s)
            message = ("authority withdrawn: the service commands no mode and no arming; the vehicle keeps the mission "
                       f"it holds{because}")
        else:
            message = f"the service has no authority ({state.authority}: {state.detail}); nothing changed"
    else:
        accepted, message = True, _summary(state, context)
    reply = OperatorReply(command=command.command, accepted=accepted, authority=new.authority,
                          phase=context.phase, message=_cut(message), client_ref=command.client_ref,  # type: ignore[arg-type]
                          status=_with_authority(context.status, new))
    return new, reply


def handle_payload(payload: bytes | None, state: AuthorityState,
                   context: OperatorContext) -> tuple[AuthorityState, OperatorReply | ErrorReply]:
    """``handle`` for the queryable's raw payload: an ``ErrorReply`` naming the field (and
    the state unchanged) for a payload that is not a command."""
    if payload is None:
        return state, ErrorReply(field="payload", message="an operator command needs a payload")
    try:
        command = decode_operator_command(payload)
    except ProtocolError as err:
        return state, ErrorReply(field=printable(err.field, MESSAGE_CHARS), message=printable(err.message, MESSAGE_CHARS),
                                 client_ref=client_ref(payload))
    return handle(command, state, context)


def _summary(state: AuthorityState, context: OperatorContext) -> str:
    parts = [f"authority {state.authority}: {state.detail}", f"phase {context.phase}"]
    if context.degraded:
        parts.append(f"degraded: {context.degraded}")
    if context.status is not None and context.status.waiting_for:
        parts.append(f"waiting for {context.status.waiting_for}")
    return "; ".join(parts)


def _with_authority(status: Status | None, state: AuthorityState) -> Status | None:
    """The snapshot as the reply leaves it: with the authority just decided."""
    if status is None:
        return None
    return msgspec.structs.replace(status, authority=state.authority, authority_detail=_cut(state.detail))


def _cut(text: str) -> str:
    return text if len(text) <= MESSAGE_CHARS else text[:MESSAGE_CHARS - 3] + "..."
