"""The operator's commands at the edge (``start``, ``hold``, ``status``, ``hello`` on
``{prefix}/{vehicle}/operator``), pure: a payload in, a command or an error naming the
field out; a decision of the sortie logic in, the reply out, and its proof. What a command does to the
service's authority is the sortie logic's (``SortieLogic.operator``; the rule is in
docs/OPERATIONS.md): ``start`` gives the authority to command modes and arming, ``hold``
takes it back (always accepted), ``status`` changes nothing; ``hello`` (anyone's, unproved) is answered with the nonce a
proof must cover, here and not by the sortie logic. Who may send them is the
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
    refused = None if command.command == "hello" else gate.refusal(command, now_s)
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
                                 command.proof, command.nonce, now_s)
        if err is None:
            return None
        return ErrorReply(field=err.field, message=printable(err.message, MESSAGE_CHARS),
                          client_ref=command.client_ref)

    @property
    def nonce(self) -> str | None:
        """This run's nonce (None when access control decides: no proof to bind)."""
        return None if self.check is None else self.check.nonce

    def prove(self, payload: bytes, command_payload: bytes | None) -> bytes | None:
        """The proof of the reply ``payload`` (the zenoh reply's attachment) to the command
        sent as ``command_payload``; None when access control decides (no key here)."""
        if self.check is None:
            return None
        return self.check.prove(command_proof(command_payload), payload).encode()


def command_proof(payload: bytes | None) -> str | None:
    """The proof a command's payload carries, if it can be read (a reply to an unreadable
    command is proved as a reply to a command without one)."""
    if payload is None:
        return None
    try:
        return decode_operator_command(payload).proof
    except ProtocolError:
        return None


def hello_reply(command: OperatorCommand, gate: OperatorGate, status: Status) -> OperatorReply:
    """The answer to ``hello``: the nonce of this run (none when access control decides)."""
    nonce = gate.nonce
    message = "hello: prove commands with this nonce" if nonce else "hello: zenoh access control decides; no proof taken"
    return OperatorReply(command="hello", accepted=True, authority=status.authority, phase=status.phase,
                         message=message, client_ref=command.client_ref, nonce=nonce)


def reply_for(command: OperatorCommand, accepted: bool, message: str, status: Status,
              state: State | None = None) -> OperatorReply:
    """What the operator hears: the decision, the authority and phase after it, the status,
    and for ``status`` the fleet-wide ``state``."""
    return OperatorReply(command=command.command, accepted=accepted, authority=status.authority,
                         phase=status.phase, message=printable(message, MESSAGE_CHARS),
                         client_ref=command.client_ref, status=status,
                         state=state if command.command == "status" else None)
