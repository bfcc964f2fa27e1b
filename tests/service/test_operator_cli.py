"""``python -m planner_service operator`` against a running service on loopback, as an
operator runs it: status, start and hold answered with what the service did (exit 0
accepted, 1 refused); a rogue queryable on the operator key cannot answer for the service;
``watch`` shows the live state, survives hostile text on the wire and ends cleanly on
Ctrl-C."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from planner_service.harness.processes import REPO, free_port
from protocol import Keys, OperatorReply, PendingRequest, State, Status, encode
from protocol.client import ClientError, PlannerClient, client_config
from protocol.zenoh_config import session_config
from tests.support.stack import Stack


def operator(endpoint: str, *args: str, key: Path | None = None, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    """The operator command, with the service's key file when given (cwd is the repository,
    where no default operator.key lies: without ``key`` the command carries no proof)."""
    with_key = ["--operator-key", str(key)] if key is not None else []
    return subprocess.run([sys.executable, "-m", "planner_service", "operator", *args, "--connect", endpoint,
                           *with_key], cwd=REPO, capture_output=True, text=True, timeout=timeout)


@pytest.mark.timeout(180)
def test_status_start_hold_against_the_service(stack: Stack) -> None:
    stack.service()  # no vehicle yet: a start is refused
    key = stack.operator_key_path
    status = operator(stack.endpoint, "status", key=key)
    assert status.returncode == 0, status.stderr
    assert status.stdout.startswith("accepted: status: authority none: not given yet"), status.stdout
    assert "  phase      lost" in status.stdout and "  battery    " in status.stdout
    refused = operator(stack.endpoint, "start", key=key)
    assert refused.returncode == 1 and refused.stdout.startswith("refused: start: the autopilot is not connected")
    assert "Traceback" not in refused.stderr

    stack.vehicle()
    assert stack.client is not None
    deadline = time.monotonic() + 30
    while not stack.client.state().status.position_ok and time.monotonic() < deadline:
        time.sleep(0.2)  # the stub, as ArduPilot, has no position estimate for its first seconds
    # Issue 23, item 4: without the key a start was accepted from any peer; now it is refused
    # at the edge, naming the proof, and changes nothing
    unkeyed = operator(stack.endpoint, "start")
    assert unkeyed.returncode == 1 and unkeyed.stdout == "", unkeyed
    assert unkeyed.stderr.startswith("error: proof: an operator command needs the operator's proof"), unkeyed.stderr
    assert "give the service's operator key with --operator-key FILE" in unkeyed.stderr
    assert stack.client.state().status.authority == "none"
    started = operator(stack.endpoint, "start", "--reason", "range clear\x1b[2J", key=key)
    assert started.returncode == 0, (started.stdout, started.stderr)
    assert started.stdout.startswith("accepted: start: authority given: the service may arm"), started.stdout
    assert "(range clear\\x1b[2J)" in started.stdout and "\x1b" not in started.stdout
    assert "authority operator, phase" in started.stdout
    again = operator(stack.endpoint, "status", key=key)
    assert "  authority  operator: given by the operator (range clear\\x1b[2J)" in again.stdout, again.stdout
    held = operator(stack.endpoint, "hold", key=key)
    assert held.returncode == 0 and held.stdout.startswith("accepted: hold: authority withdrawn"), held.stdout
    assert stack.client.state().status.authority == "none"
    service = stack.children[0]
    assert "operator: authority none -> operator (given by the operator (range clear\\x1b[2J))" in service.log()
    assert "\x1b" not in service.log()


@pytest.mark.timeout(120)
def test_a_rogue_queryable_cannot_answer_for_the_service(stack: Stack) -> None:
    stack.service(zenoh__mode="router")  # it routes the operator's query to every queryable on the key
    keys = Keys()
    rogue = zenoh.open(client_config([stack.endpoint], "client"))
    forged = {"n": 0}

    def answer(query: Any) -> None:  # says yes to everything, with no client_ref or the wrong one
        forged["n"] += 1
        for ref in (None, "not-yours"):
            query.reply(keys.operator, encode(OperatorReply(command="start", accepted=True, authority="operator",
                                                            phase="flying", message="forged", client_ref=ref)))
        query.drop()

    queryable = rogue.declare_queryable(keys.operator, answer)
    try:
        time.sleep(0.5)
        with PlannerClient([stack.endpoint]) as client:
            reply = client.operator("start", timeout_s=5.0, key=stack.operator_key())
        assert forged["n"] == 2  # the hello and the start
        assert not reply.accepted and reply.message == "the autopilot is not connected"  # the service's own
        quiet = operator(stack.endpoint, "start", key=stack.operator_key_path)
        assert quiet.returncode == 1 and "forged" not in quiet.stdout
    finally:
        queryable.undeclare()
        rogue.close()


@pytest.mark.timeout(120)
def test_a_rogue_queryable_that_echoes_the_command_is_not_believed(stack: Stack) -> None:
    # Was: the client took the first reply that echoed its client_ref and command, so a rogue
    # that reads the command and answers first said "accepted" for the service; then (issue
    # 23) two answers that disagreed were refused, so a rogue could make every command fail.
    # Now only a reply proved with the operator key is believed: the service's answer is.
    stack.service(zenoh__mode="router")
    keys = Keys()
    rogue = zenoh.open(client_config([stack.endpoint], "client"))
    forged = {"n": 0}

    def answer(query: Any) -> None:  # reads the command and echoes it: accepted, authority given
        forged["n"] += 1
        command = json.loads(query.payload.to_bytes())
        query.reply(keys.operator, encode(OperatorReply(
            command=command["command"], accepted=True, authority="operator", phase="flying", message="forged",
            client_ref=command["client_ref"], nonce="0" * 32)), attachment=b"0" * 64)
        query.drop()

    queryable = rogue.declare_queryable(keys.operator, answer)
    try:
        time.sleep(0.5)
        with PlannerClient([stack.endpoint]) as client:
            reply = client.operator("start", timeout_s=5.0, key=stack.operator_key())
        assert forged["n"] == 2  # the hello and the start, both answered "accepted" by the rogue
        assert not reply.accepted and reply.message == "the autopilot is not connected"  # the service's own
        quiet = operator(stack.endpoint, "start", key=stack.operator_key_path)
        assert quiet.returncode == 1 and "forged" not in quiet.stdout + quiet.stderr, quiet
        assert quiet.stdout.startswith("refused: start: the autopilot is not connected"), quiet.stdout
        # without the key nothing can be told apart: two answers that disagree are refused
        with PlannerClient([stack.endpoint]) as client:
            with pytest.raises(ClientError) as err:
                client.operator("status", timeout_s=5.0)
        assert err.value.field == "reply", err.value
        assert err.value.message.startswith("2 different replies answer the operator's status (client_ref '")
    finally:
        queryable.undeclare()
        rogue.close()
    assert stack.client is not None and stack.client.state().status.authority == "none"


@pytest.mark.timeout(60)
def test_operator_status_into_a_closed_pipe_ends_quietly() -> None:
    # Was: "operator status | head -1" ended in a BrokenPipeError traceback. Here the reader
    # has gone before the answer comes: every line the command prints meets a closed pipe.
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    keys = Keys()
    session = zenoh.open(session_config("peer", [endpoint]))

    def answer(query: Any) -> None:
        ref = json.loads(query.payload.to_bytes())["client_ref"]
        query.reply(keys.operator, encode(OperatorReply(
            command="status", accepted=True, authority="none", phase="idle", message="authority none: not given yet",
            client_ref=ref, status=Status(vehicle="uav1", phase="idle"))))
        query.drop()

    queryable = session.declare_queryable(keys.operator, answer)
    try:
        heard = operator(endpoint, "status")
        assert heard.returncode == 0 and heard.stdout.startswith("accepted: status: authority none"), heard
        assert len(heard.stdout.splitlines()) > 5
        read, write = os.pipe()
        os.close(read)
        try:
            closed = subprocess.run([sys.executable, "-m", "planner_service", "operator", "status", "--connect",
                                     endpoint], cwd=REPO, stdout=write, stderr=subprocess.PIPE, text=True, timeout=60)
        finally:
            os.close(write)
    finally:
        queryable.undeclare()
        session.close()
    assert closed.returncode == 141, closed.stderr
    assert "Traceback" not in closed.stderr and "BrokenPipe" not in closed.stderr, closed.stderr


class FakeService:
    """A zenoh session that publishes what a hostile or broken peer might on the service's
    keys (no access control here), and answers the operator's status with the fleet-wide
    state (what watch shows of the pending requests)."""

    def __init__(self, endpoint: str, status: Status, pending: list[PendingRequest]) -> None:
        keys = Keys()
        self.session = zenoh.open(session_config("peer", [endpoint]))
        self.status = status
        state = State(status=status, pending=pending)

        def answer(query: Any) -> None:
            ref = json.loads(query.payload.to_bytes())["client_ref"]
            query.reply(keys.operator, encode(OperatorReply(command="status", accepted=True, authority="none",
                                                            phase="flying", client_ref=ref, status=status,
                                                            state=state)))
            query.drop()
        self.queryable = self.session.declare_queryable(keys.operator, answer)
        self.token = self.session.liveliness().declare_token(keys.alive)
        self.key = keys.status

    def publish(self) -> None:
        self.session.put(self.key, encode(self.status))

    def close(self) -> None:
        self.token.undeclare()
        self.queryable.undeclare()
        self.session.close()


@pytest.mark.timeout(60)
def test_watch_escapes_hostile_text_and_stops_cleanly_on_ctrl_c(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hostile = Status(vehicle="uav1", phase="flying", mode="AUTO\x1b[2J\x1b]0;owned\x07", battery_fraction=None,
                     battery_source="unknown", degraded="journal: disk full\nINFO all is well",
                     authority="revoked", authority_detail="revoked: the pilot switched to LOITER")
    fake = FakeService(endpoint, hostile, [PendingRequest(request_id=3, user_id="u-7", x_m=1.0, y_m=2.0,
                                                          z_m=0.0, tasks=4)])
    out = tmp_path / "watch.out"
    try:
        with open(out, "w") as handle:
            watch = subprocess.Popen([sys.executable, "-m", "planner_service", "operator", "watch", "--connect", endpoint,
                                      "--refresh", "0.2"], cwd=REPO, stdout=handle, stderr=subprocess.PIPE, text=True,
                                     env={"PATH": "/usr/bin:/bin", "TERM": "dumb", "PYTHONPATH": str(REPO)})
            deadline = time.monotonic() + 30
            while "DEGRADED" not in out.read_text() and time.monotonic() < deadline and watch.poll() is None:
                fake.publish()
                time.sleep(0.1)
            watch.send_signal(signal.SIGINT)
            _, err = watch.communicate(timeout=10)
    finally:
        fake.close()
    text = out.read_text()
    print(f"\n{text[:1200]}")
    assert watch.returncode == 0 and "Traceback" not in err, err
    assert "\x1b" not in text and "\x07" not in text and "\u202e" not in text  # a dumb terminal: plain text only
    assert "mode AUTO\\x1b[2J\\x1b]0;owned\\x07" in text
    assert "DEGRADED   journal: disk full\\x0aINFO all is well" in text
    assert "authority  revoked: revoked: the pilot switched to LOITER" in text
    assert "battery    unknown (unknown)" in text
    assert "pending    1: u-7 (4 tasks at 1, 2)" in text
    assert "service alive" in text
