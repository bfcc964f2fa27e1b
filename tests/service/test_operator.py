"""The operator's commands: what start, hold and status do to the service's authority (the
sortie logic decides), what they answer, and that a command that cannot be read or carries
hostile text changes nothing and comes back escaped and bounded (the edge)."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from planner_service.model import preset
from planner_service.service.operator import read_command, reply_for
from planner_service.service.sortie import Authority, Rules, SortieLogic, Vehicle, new_sortie
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from protocol import Area, ErrorReply, GeoOrigin, OperatorCommand, OperatorReply, Status, decode_operator_reply, encode


class NoRequests:
    def request_for(self, user_id: str) -> None:
        return None

    def services_of(self, user_id: str) -> int:
        return 0

    def pending_count(self) -> int:
        return 0

    def pending(self) -> list:
        return []


LOGIC = SortieLogic(Rules(preset("field"), GeoOrigin(), Area(500.0, 120.0, 10.0)), NoRequests())
READY = Vehicle(connected=True, position_ok=True, boot_s=1.0, landed_known=True, mode="STABILIZE",
                battery_fraction=0.9, battery_source="autopilot", time_rate=1.0)
NONE = new_sortie(1, LOGIC.rules)
GIVEN = replace(NONE, authority=Authority.by_operator())
REVOKED = replace(NONE, authority=GIVEN.authority.revoke("mode changed to LOITER"))


def operator(state, command: str, reason: str = "", v: Vehicle = READY):  # type: ignore[no-untyped-def]
    return LOGIC.operator(state, ins.OperatorCommand(command, reason), v, 0.0)  # type: ignore[arg-type]


def sent(reply: OperatorReply | ErrorReply) -> OperatorReply | ErrorReply:
    """The reply as the operator's client reads it off the wire."""
    return decode_operator_reply(encode(reply))


def test_start_gives_the_authority_and_says_so() -> None:
    new, out, accepted, said = operator(NONE, "start", "range clear, pilot ready")
    assert accepted and new.authority.granted
    assert new.authority.detail == "given by the operator (range clear, pilot ready)"
    assert said.startswith("authority given: the service may arm")
    assert [e.event.kind for e in out if isinstance(e, fx.Emit)] == ["authority_granted"]


def test_start_after_a_revocation_gives_it_back_and_twice_is_harmless() -> None:
    assert REVOKED.authority.state == "revoked" and "mode changed to LOITER" in REVOKED.authority.detail
    new, _, accepted, _ = operator(REVOKED, "start")
    assert accepted and new.authority.granted
    again, out, accepted, said = operator(new, "start")
    assert accepted and again.authority == new.authority and not out
    assert said.startswith("the service already has the authority")


@pytest.mark.parametrize("state, vehicle, words", [
    (replace(NONE, degraded="the status task failed"), READY, "degraded: the status task failed"),
    (NONE, Vehicle(), "not connected"),
    (NONE, replace(READY, position_ok=False), "no position"),
    (NONE, replace(READY, battery_fraction=None, battery_source="unknown"), "battery's charge is unknown"),
    (NONE, replace(READY, battery_fraction=0.5, battery_source="model"), "battery's charge is model"),
])
def test_start_is_refused_when_the_service_cannot_take_it(state, vehicle, words: str) -> None:  # type: ignore[no-untyped-def]
    new, out, accepted, said = operator(state, "start", v=vehicle)
    assert not accepted and words in said and new == state and not out


def test_hold_always_takes_the_authority_back() -> None:
    flying = replace(READY, armed=True, airborne=True, mode="AUTO")
    new, out, accepted, said = operator(replace(GIVEN, degraded="a task died"), "hold", "pilot takes over", flying)
    assert accepted and new.authority.state == "none" and "pilot takes over" in new.authority.detail
    assert [e.kind for e in out if isinstance(e, fx.Command)] == ["hold"]
    assert said.startswith("authority withdrawn")
    for state in (NONE, REVOKED):
        same, out, accepted, said = operator(state, "hold")
        assert accepted and same == state and not out and "nothing changed" in said


def test_status_changes_nothing_and_summarises() -> None:
    for state in (NONE, GIVEN, REVOKED):
        same, out, accepted, said = operator(state, "status")
        assert accepted and same is state and not out
        assert said.startswith(f"authority {state.authority.state}: {state.authority.detail}")


def test_a_payload_that_is_not_a_command_changes_nothing() -> None:
    for payload, field in ((None, "payload"), (b"\xff\xfe", "payload"), (b'{"kind": "task_request"}', "kind"),
                           (b'{"kind": "operator_command", "command": "arm", "client_ref": "r-9"}', "command"),
                           (b'{"kind": "operator_command", "command": "start", "schema": 2}', "schema"),
                           (b'{"kind": "operator_command", "command": "start", "force": true}', "force")):
        reply = read_command(payload)
        assert isinstance(reply, ErrorReply) and reply.field == field, (payload, reply)
        assert sent(reply) == reply
    reply = read_command(b'{"kind": "operator_command", "command": "arm", "client_ref": "r-9"}')
    assert isinstance(reply, ErrorReply) and reply.client_ref == "r-9"


def test_hostile_text_in_a_reason_is_escaped_and_bounded() -> None:
    reason = "ok\x1b[2J\x1b]0;pwned\x07\nINFO forged log line\u202e" + "\x00" * 300
    cmd = read_command(json.dumps({"kind": "operator_command", "command": "start", "reason": reason[:256]}).encode())
    assert isinstance(cmd, OperatorCommand)
    new, _, accepted, said = operator(NONE, "start", cmd.reason)
    reply = reply_for(cmd, accepted, said, Status(authority=new.authority.state))
    assert isinstance(reply, OperatorReply) and reply.accepted
    for text in (new.authority.detail, reply.message):
        assert not any(ord(c) < 32 or c == "\u202e" for c in text), text
        assert "\\x1b[2J" in text and "\\x0aINFO forged" in text and len(text) <= 256
    assert sent(reply) == reply
