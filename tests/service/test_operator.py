"""The operator's commands: what start, hold and status do to the service's authority (the
sortie logic decides), what they answer, and that a command that cannot be read or carries
hostile text changes nothing and comes back escaped and bounded (the edge)."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from planner_service.model import preset
from planner_service.service.operator import OperatorGate, hello_reply, read_command, reply_for
from planner_service.service.sortie import Authority, Rules, SortieLogic, VehicleSnapshot, new_sortie
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from protocol import (Area, ErrorReply, GeoOrigin, Keys, OperatorCommand, OperatorReply, PendingRequest, State, Status,
                      decode_operator_reply, encode)
from protocol.operator_proof import ProofCheck, reply_proved, sign


class NoRequests:
    def request_for(self, user_id: str) -> None:
        return None

    def services_of(self, user_id: str) -> int:
        return 0

    def service_counts(self) -> dict[str, int]:
        return {}

    def pending_count(self) -> int:
        return 0

    def pending(self) -> list:
        return []

    def served_elsewhere(self, user_id: str) -> None:
        return None


LOGIC = SortieLogic(Rules(preset("field"), GeoOrigin(), Area(500.0, 120.0, 10.0)), NoRequests())
READY = VehicleSnapshot(connected=True, position_ok=True, boot_s=1.0, landed_known=True, mode="STABILIZE",
                battery_fraction=0.9, battery_source="autopilot", time_rate=1.0)
NONE = new_sortie(1, LOGIC.rules)
GIVEN = replace(NONE, authority=Authority.by_operator())
REVOKED = replace(NONE, authority=GIVEN.authority.revoke("mode changed to LOITER"))


def operator(state, command: str, reason: str = "", v: VehicleSnapshot = READY):  # type: ignore[no-untyped-def]
    return LOGIC.operator(state, ins.OperatorAsked(command, reason), v, 0.0)  # type: ignore[arg-type]


def sent(reply: OperatorReply | ErrorReply) -> OperatorReply | ErrorReply:
    """The reply as the operator's client reads it off the wire."""
    return decode_operator_reply(encode(reply))


OPEN = OperatorGate(None, "access control decides (a test of what comes after the gate)")


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
    (replace(NONE, life=replace(NONE.life, degraded="the status task failed")), READY,
     "degraded: the status task failed"),
    (NONE, VehicleSnapshot(), "not connected"),
    (NONE, replace(READY, position_ok=False), "no position"),
    (NONE, replace(READY, battery_fraction=None, battery_source="unknown"), "battery's charge is unknown"),
    (NONE, replace(READY, battery_fraction=0.5, battery_source="model"), "battery's charge is model"),
])
def test_start_is_refused_when_the_service_cannot_take_it(state, vehicle, words: str) -> None:  # type: ignore[no-untyped-def]
    new, out, accepted, said = operator(state, "start", v=vehicle)
    assert not accepted and words in said and new == state and not out


def test_hold_always_takes_the_authority_back() -> None:
    flying = replace(READY, armed=True, airborne=True, mode="AUTO")
    new, out, accepted, said = operator(replace(GIVEN, life=replace(GIVEN.life, degraded="a task died")), "hold",
                                        "pilot takes over", flying)
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
                           (b'{"kind": "operator_command", "command": "start", "schema": 1}', "schema"),
                           (b'{"kind": "operator_command", "command": "start", "force": true}', "force")):
        reply = read_command(payload, OPEN, 0.0)
        assert isinstance(reply, ErrorReply) and reply.field == field, (payload, reply)
        assert sent(reply) == reply
    reply = read_command(b'{"kind": "operator_command", "command": "arm", "client_ref": "r-9"}', OPEN, 0.0)
    assert isinstance(reply, ErrorReply) and reply.client_ref == "r-9"


def test_hostile_text_in_a_reason_is_escaped_and_bounded() -> None:
    reason = "ok\x1b[2J\x1b]0;pwned\x07\nINFO forged log line\u202e" + "\x00" * 300
    cmd = read_command(json.dumps({"kind": "operator_command", "command": "start", "reason": reason[:256]}).encode(), OPEN, 0.0)
    assert isinstance(cmd, OperatorCommand)
    new, _, accepted, said = operator(NONE, "start", cmd.reason)
    reply = reply_for(cmd, accepted, said, Status(authority=new.authority.state))
    assert isinstance(reply, OperatorReply) and reply.accepted
    for text in (new.authority.detail, reply.message):
        assert not any(ord(c) < 32 or c == "\u202e" for c in text), text
        assert "\\x1b[2J" in text and "\\x0aINFO forged" in text and len(text) <= 256
    assert sent(reply) == reply


KEY = bytes(range(32))
GATED_KEYS = Keys()
NONCE = "0123456789abcdef" * 2
"""The gated service's nonce for this run."""


def gated(nonce: str = NONCE) -> OperatorGate:
    return OperatorGate(ProofCheck(KEY, GATED_KEYS, window_s=30.0, nonce=nonce), "the key's proof")


def command(name: str = "start", reason: str = "range clear", ref: str = "r-1", at_ms: int = 1_000_000,
            key: bytes = KEY, nonce: str = NONCE, **fields: object) -> bytes:
    body = {"kind": "operator_command", "command": name, "reason": reason, "client_ref": ref, "sent_at_ms": at_ms,
            "nonce": nonce, "proof": sign(key, GATED_KEYS, name, reason, ref, at_ms, nonce), **fields}
    return json.dumps({k: v for k, v in body.items() if v is not None}).encode()


@pytest.mark.parametrize("name", ["start", "hold", "status"])
def test_without_the_keys_proof_no_command_passes_the_gate(name: str) -> None:
    """Issue 23, item 4: on the default configuration any peer's start was carried out.
    Every command (start, hold, status) now needs the proof; refused ones name the field."""
    gate = gated()
    bare = json.dumps({"kind": "operator_command", "command": name, "client_ref": "r-0"}).encode()
    for payload, field in ((bare, "proof"),
                           (command(name, key=b"\x01" * 32), "proof"),  # another key
                           (command(name, proof=None), "proof"),
                           (command(name, ref=None), "client_ref"),
                           (command(name, at_ms=None), "sent_at_ms"),
                           (command(name, nonce=None), "nonce")):
        reply = read_command(payload, gate, 1000.0)
        assert isinstance(reply, ErrorReply) and reply.field == field, (payload, reply)
        assert sent(reply) == reply
    assert gate.check is not None and gate.check.seen == {}  # nothing refused is remembered
    ok = read_command(command(name), gate, 1000.0)
    assert isinstance(ok, OperatorCommand) and ok.command == name


def test_an_altered_command_fails_its_proof() -> None:
    good = json.loads(command("hold", reason="pilot takes over"))
    for field, value in (("command", "start"), ("reason", "anything"), ("client_ref", "r-2"), ("sent_at_ms", 1_000_001),
                         ("nonce", "f" * 32)):
        reply = read_command(json.dumps({**good, field: value}).encode(), gated(), 1000.0)
        assert isinstance(reply, ErrorReply) and reply.field == "proof", field
    other_vehicle = sign(KEY, Keys(vehicle="uav2"), "hold", "pilot takes over", "r-1", 1_000_000, NONCE)
    reply = read_command(json.dumps({**good, "proof": other_vehicle}).encode(), gated(), 1000.0)
    assert isinstance(reply, ErrorReply) and reply.field == "proof"


def test_a_replayed_or_stale_command_is_refused() -> None:
    gate = gated()
    assert isinstance(read_command(command(ref="r-1", at_ms=1_000_000), gate, 1000.0), OperatorCommand)
    again = read_command(command(ref="r-1", at_ms=1_000_000), gate, 1005.0)  # the same bytes, 5 s later
    assert isinstance(again, ErrorReply) and again.field == "client_ref" and "already used" in again.message
    # the same bytes after the window: refused for their time (and still remembered until then)
    late = read_command(command(ref="r-1", at_ms=1_000_000), gate, 1030.5)
    assert isinstance(late, ErrorReply) and late.field == "sent_at_ms" and "+" not in late.message
    assert late.message.startswith("-30.5 s from the service's clock")
    ahead = read_command(command(ref="r-3", at_ms=1_031_000), gate, 1000.0)  # a clock 31 s ahead
    assert isinstance(ahead, ErrorReply) and ahead.field == "sent_at_ms" and ahead.message.startswith("+31.0 s")
    # within the window either way: taken
    assert isinstance(read_command(command(ref="r-4", at_ms=1_029_000), gate, 1000.0), OperatorCommand)
    assert isinstance(read_command(command(ref="r-5", at_ms=971_000), gate, 1000.0), OperatorCommand)
    # a ref is forgotten once its command can no longer pass the window
    assert gate.check is not None and "r-1" in gate.check.seen
    read_command(command(ref="r-6", at_ms=1_100_000), gate, 1100.0)
    assert "r-1" not in gate.check.seen and "r-6" in gate.check.seen


def test_a_command_made_for_another_run_of_the_service_is_refused_whatever_its_time() -> None:
    """Issue 34, finding 3: a start captured before a restart was accepted after it (the
    client_refs seen were in memory only). A proof covers the run's nonce: after the restart
    (a new nonce) the same bytes, fresh in time and with a ref never seen, are refused."""
    captured = command("start", ref="r-9", at_ms=1_000_000)
    before = gated(NONCE)
    assert isinstance(read_command(captured, before, 1000.0), OperatorCommand)
    after = gated("fedcba9876543210" * 2)  # the service restarted: nothing of `before` kept
    replayed = read_command(captured, after, 1001.0)
    assert isinstance(replayed, ErrorReply) and replayed.field == "nonce", replayed
    assert "another run of the service" in replayed.message and after.check is not None and after.check.seen == {}


def test_hello_needs_no_proof_and_gives_the_runs_nonce_nothing_else() -> None:
    gate = gated()
    cmd = read_command(json.dumps({"kind": "operator_command", "command": "hello", "client_ref": "h-1"}).encode(),
                       gate, 1000.0)
    assert isinstance(cmd, OperatorCommand) and cmd.command == "hello"
    reply = sent(hello_reply(cmd, gate, Status()))
    assert isinstance(reply, OperatorReply) and reply.nonce == NONCE and reply.client_ref == "h-1"
    assert reply.status is None and reply.state is None and gate.check is not None and gate.check.seen == {}
    assert sent(hello_reply(cmd, OPEN, Status())).nonce is None  # access control decides: no proof to bind


def test_every_reply_is_proved_over_its_bytes_and_the_command_it_answers() -> None:
    gate, payload = gated(), command("hold")
    reply = encode(ErrorReply(field="x", message="y", client_ref="r-1"))
    proof = gate.prove(reply, payload)
    proved = json.loads(payload)["proof"]
    assert proof is not None and reply_proved(KEY, GATED_KEYS, proved, reply, proof)
    assert not reply_proved(KEY, GATED_KEYS, proved, reply + b" ", proof)  # other bytes
    assert not reply_proved(KEY, GATED_KEYS, None, reply, proof)  # an answer to another command
    assert not reply_proved(b"\x02" * 32, GATED_KEYS, proved, reply, proof)  # another key
    assert not reply_proved(KEY, Keys(vehicle="uav2"), proved, reply, proof)  # another vehicle's
    assert not reply_proved(KEY, GATED_KEYS, proved, reply, None)
    assert OPEN.prove(reply, payload) is None


def test_the_proof_is_checked_on_the_reason_as_sent_then_the_reason_is_escaped() -> None:
    reason = "ok\x1b[2J" + "x" * 200
    cmd = read_command(command(reason=reason), gated(), 1000.0)
    assert isinstance(cmd, OperatorCommand) and "\\x1b[2J" in cmd.reason and len(cmd.reason) <= 100


def test_the_status_reply_holds_the_fleet_wide_state_and_the_others_do_not() -> None:
    state = State(status=Status(), pending=[PendingRequest(request_id=1, user_id="u-1", x_m=1.0, y_m=2.0, z_m=0.0,
                                                           tasks=5)])
    for name in ("start", "hold", "status"):
        cmd = OperatorCommand(command=name, client_ref="r")  # type: ignore[arg-type]
        reply = sent(reply_for(cmd, True, "", Status(), state))
        assert isinstance(reply, OperatorReply)
        assert reply.state == (state if name == "status" else None), name
