"""The operator's commands as a pure function: what start, hold and status do to the
service's authority, what they answer, and that a command that cannot be read or carries
hostile text changes nothing and comes back escaped and bounded."""

from __future__ import annotations

import json

import pytest

from planner_service.service.operator import (AuthorityState, OperatorContext, handle, handle_payload, initial,
                                              revoke)
from protocol import ErrorReply, OperatorCommand, OperatorReply, Status, decode_operator_reply, encode

NOW = 1000.0
STATUS = Status(vehicle="uav1", phase="idle", mode="GUIDED", battery_fraction=0.9, battery_source="autopilot",
                position_ok=True, waiting_for="the operator's start")


def context(**fields: object) -> OperatorContext:
    return OperatorContext(**{"phase": "idle", "now_s": NOW, "status": STATUS, **fields})  # type: ignore[arg-type]


def command(name: str, reason: str = "", ref: str | None = "ref-1") -> OperatorCommand:
    return OperatorCommand(command=name, reason=reason, client_ref=ref)  # type: ignore[arg-type]


def sent(reply: OperatorReply | ErrorReply) -> OperatorReply | ErrorReply:
    """The reply as the operator's client reads it off the wire."""
    return decode_operator_reply(encode(reply))


NONE = initial(False, 0.0)
GIVEN = AuthorityState("operator", "given by the operator", 500.0)
REVOKED = revoke(GIVEN, "the pilot switched to LOITER", 900.0)


def test_start_gives_the_authority_and_says_so() -> None:
    new, reply = handle(command("start", "range clear, pilot ready"), NONE, context())
    assert new == AuthorityState("operator", "given by the operator (range clear, pilot ready)", NOW)
    assert sent(reply) == reply
    assert (reply.command, reply.accepted, reply.authority, reply.phase, reply.client_ref) == (
        "start", True, "operator", "idle", "ref-1")
    assert reply.message.startswith("authority given: the service may arm, switch to the mission mode")
    assert reply.status is not None and reply.status.authority == "operator"
    assert reply.status.authority_detail == new.detail and reply.status.mode == "GUIDED"


def test_start_after_a_revocation_gives_it_back_and_twice_is_harmless() -> None:
    assert REVOKED.authority == "revoked" and "the pilot switched to LOITER" in REVOKED.detail
    new, reply = handle(command("start"), REVOKED, context())
    assert new.authority == "operator" and reply.accepted and new.detail == "given by the operator"
    again, reply2 = handle(command("start"), new, context(now_s=NOW + 5))
    assert again == new and reply2.accepted and reply2.message.startswith("the service already has the authority")


@pytest.mark.parametrize("fields, words", [
    ({"degraded": "the journal cannot be written: disk full"},
     "the service is degraded: the journal cannot be written: disk full"),
    ({"start_refusal": "the battery reading is unknown"}, "the battery reading is unknown"),
])
def test_start_is_refused_when_the_service_cannot_take_it(fields: dict[str, str], words: str) -> None:
    for state in (NONE, REVOKED):
        new, reply = handle(command("start"), state, context(**fields))
        assert new == state and not reply.accepted and reply.message == words
        assert reply.authority == state.authority


def test_hold_always_takes_the_authority_back() -> None:
    new, reply = handle(command("hold", "pilot takes over"), GIVEN, context(degraded="a task died", phase="degraded"))
    assert new == AuthorityState("none", "handed back by the operator's hold (pilot takes over)", NOW)
    assert reply.accepted and reply.authority == "none" and reply.phase == "degraded"
    assert reply.message.startswith("authority withdrawn: the service commands no mode and no arming")
    for state in (NONE, REVOKED):  # nothing to take back: accepted, unchanged, said
        same, r = handle(command("hold"), state, context())
        assert same == state and r.accepted and "nothing changed" in r.message


def test_status_changes_nothing_and_summarises() -> None:
    for state in (NONE, GIVEN, REVOKED):
        same, reply = handle(command("status"), state, context(degraded="the status task died"))
        assert same == state and reply.accepted and reply.authority == state.authority
        assert reply.message == (f"authority {state.authority}: {state.detail}; phase idle; degraded: the status "
                                 "task died; waiting for the operator's start")
        assert reply.status is not None and reply.status.battery_fraction == 0.9


def test_revoke_and_the_initial_authority() -> None:
    assert revoke(NONE, "whatever", 1.0) == NONE  # nothing to revoke
    assert initial(True, 7.0) == AuthorityState(
        "operator", "given by the configuration (mavlink.start_mission = true)", 7.0)
    assert initial(False, 7.0).authority == "none"
    long = revoke(GIVEN, "x" * 1000, 1.0)
    assert long.authority == "revoked" and len(long.detail) <= 256


def test_a_payload_that_is_not_a_command_changes_nothing() -> None:
    for payload, field in ((None, "payload"), (b"\xff\xfe", "payload"), (b'{"kind": "task_request"}', "kind"),
                           (b'{"kind": "operator_command", "command": "arm", "client_ref": "r-9"}', "command"),
                           (b'{"kind": "operator_command", "command": "start", "schema": 2}', "schema"),
                           (b'{"kind": "operator_command", "command": "start", "force": true}', "force")):
        state, reply = handle_payload(payload, GIVEN, context())
        assert state is GIVEN and isinstance(reply, ErrorReply) and reply.field == field, (payload, reply)
        assert sent(reply) == reply
    _, reply = handle_payload(b'{"kind": "operator_command", "command": "arm", "client_ref": "r-9"}', GIVEN, context())
    assert reply.client_ref == "r-9"


def test_hostile_text_in_a_reason_is_escaped_and_bounded() -> None:
    reason = "ok\x1b[2J\x1b]0;pwned\x07\nINFO forged log line\u202e" + "\x00" * 300
    payload = json.dumps({"kind": "operator_command", "command": "start", "reason": reason[:256]}).encode()
    new, reply = handle_payload(payload, NONE, context())
    assert isinstance(reply, OperatorReply) and reply.accepted
    for text in (new.detail, reply.message):
        assert not any(ord(c) < 32 or c == "\u202e" for c in text), text
        assert "\\x1b[2J" in text and "\\x0aINFO forged" in text and len(text) <= 256
    assert sent(reply) == reply
