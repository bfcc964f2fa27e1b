"""The operator's commands at the edge (``start``, ``hold``, ``status`` on
``{prefix}/{vehicle}/operator``), pure: a payload in, a command or an error naming the
field out; a decision of the sortie logic in, the reply out. What a command does to the
service's authority is the sortie logic's (``SortieLogic.operator``; the rule is in
docs/OPERATIONS.md): ``start`` gives the authority to command modes and arming, ``hold``
takes it back (always accepted), ``status`` changes nothing."""

from __future__ import annotations

from protocol import ErrorReply, OperatorCommand, OperatorReply, ProtocolError, Status, decode_operator_command
from protocol.text import printable

from .intake import client_ref

MESSAGE_CHARS = 256
"""``OperatorReply.message`` holds at most this many characters."""
REASON_CHARS = 100
"""How much of the operator's reason is kept (in the authority's detail and the reply)."""


def read_command(payload: bytes | None) -> OperatorCommand | ErrorReply:
    """The command in ``payload``, its reason escaped and bounded; an ``ErrorReply``
    naming the field (with the client's ``client_ref`` when it can be read) otherwise."""
    if payload is None:
        return ErrorReply(field="payload", message="an operator command needs a payload")
    try:
        command = decode_operator_command(payload)
    except ProtocolError as err:
        return ErrorReply(field=printable(err.field, MESSAGE_CHARS), message=printable(err.message, MESSAGE_CHARS),
                          client_ref=client_ref(payload))
    if not command.reason:
        return command
    return OperatorCommand(command=command.command, reason=printable(command.reason, REASON_CHARS),
                           client_ref=command.client_ref)


def reply_for(command: OperatorCommand, accepted: bool, message: str, status: Status) -> OperatorReply:
    """What the operator hears: the decision, the authority and phase after it, the status."""
    return OperatorReply(command=command.command, accepted=accepted, authority=status.authority,
                         phase=status.phase, message=printable(message, MESSAGE_CHARS),
                         client_ref=command.client_ref, status=status)
