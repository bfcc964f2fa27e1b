"""The operator's commands at the edge (``start``, ``hold``, ``status`` on
``{prefix}/{vehicle}/operator``), pure: a payload in, a command or an error naming the
field out; a decision of the sortie logic in, the reply out. What a command does to the
service's authority is the sortie logic's (``SortieLogic.operator``; the rule is in
docs/OPERATIONS.md): ``start`` gives the authority to command modes and arming, ``hold``
takes it back (always accepted), ``status`` changes nothing. Who may send them is the
``OperatorGate``'s: the holder of the operator key (its proof on every command), or under
zenoh's access control whoever its rules let query the operator key (docs/SERVICE.md,
"The operator's key")."""

from __future__ import annotations

from dataclasses import dataclass

import msgspec

from protocol import ErrorReply, OperatorCommand, OperatorReply, ProtocolError, State, Status, decode_operator_command
from protocol.operator_proof import ProofCheck
from protocol.text import printable

from .intake import client_ref

MESSAGE_CHARS = 256
"""``OperatorReply.message`` holds at most this many characters."""
REASON_CHARS = 100
"""How much of the operator's reason is kept (in the authority's detail and the reply)."""


def read_command(payload: bytes | None, gate: "OperatorGate", now_s: float) -> OperatorCommand | ErrorReply:
    """The command in ``payload`` if ``gate`` lets it through (its proof checked on the
    bytes as sent), its reason escaped and bounded; an ``ErrorReply`` naming the field (with
    the client's ``client_ref`` when it can be read) otherwise."""
    if payload is None:
        return ErrorReply(field="payload", message="an operator command needs a payload")
    try:
        command = decode_operator_command(payload)
    except ProtocolError as err:
        return ErrorReply(field=printable(err.field, MESSAGE_CHARS), message=printable(err.message, MESSAGE_CHARS),
                          client_ref=client_ref(payload))
    refused = gate.refusal(command, now_s)
    if refused is not None:
        return refused
    if not command.reason:
        return command
    return msgspec.structs.replace(command, reason=printable(command.reason, REASON_CHARS))


@dataclass
class OperatorGate:
    """Who may command: ``check`` (the key's proof on every command), or None when zenoh's
    access control decides (``why`` says which, for the log)."""

    check: ProofCheck | None
    why: str

    def refusal(self, command: OperatorCommand, now_s: float) -> ErrorReply | None:
        """None if ``command`` may be carried out; else the error naming the field at fault
        (the proof, its time, its client_ref)."""
        if self.check is None:
            return None
        err = self.check.refusal(command.command, command.reason, command.client_ref, command.sent_at_ms,
                                 command.proof, now_s)
        if err is None:
            return None
        return ErrorReply(field=err.field, message=printable(err.message, MESSAGE_CHARS),
                          client_ref=command.client_ref)


def reply_for(command: OperatorCommand, accepted: bool, message: str, status: Status,
              state: State | None = None) -> OperatorReply:
    """What the operator hears: the decision, the authority and phase after it, the status,
    and for ``status`` the fleet-wide ``state``."""
    return OperatorReply(command=command.command, accepted=accepted, authority=status.authority,
                         phase=status.phase, message=printable(message, MESSAGE_CHARS),
                         client_ref=command.client_ref, status=status,
                         state=state if command.command == "status" else None)
