"""Issue 23, items 4 and 5, on the default configuration (zenoh without access control) with
real processes on loopback: a peer without the service's operator key cannot start, hold or
ask (before: its ``start`` was accepted and the vehicle armed); a command captured on the
wire and sent again is refused; the public ``state`` shows no user's position or backlog,
which the operator's ``status`` holds; a key file others may read stops the service at start."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner_service.harness.processes import REPO
from protocol import ErrorReply, Keys, OperatorCommand, OperatorReply, decode_operator_reply, encode
from protocol.client import ClientError, PlannerClient
from protocol.operator_proof import sign
from tests.support.stack import Stack


def send(client: PlannerClient, payload: bytes) -> OperatorReply | ErrorReply:
    replies = client._replies(client.keys.operator, payload, 10.0)
    assert len(replies) == 1, replies
    return decode_operator_reply(replies[0])


@pytest.mark.timeout(180)
def test_only_the_key_holder_commands_and_a_replay_is_refused(stack: Stack) -> None:
    stack.vehicle()
    service = stack.service()
    client = stack.client
    assert client is not None
    assert stat.S_IMODE(os.stat(stack.operator_key_path).st_mode) == 0o600  # made by the service at start
    assert f"operator commands need the proof of the key in {stack.operator_key_path} (made now" in service.log()
    deadline = time.monotonic() + 30
    while not client.state().status.position_ok and time.monotonic() < deadline:
        time.sleep(0.2)
    assert client.submit("u-1", 100.0, 120.0, 9).request_id == 1
    assert client.submit("u-2", 300.0, 320.0, 4).request_id == 2
    stack.wait_event(lambda e: e.event == "mission_uploaded", 120.0, "a mission for the two requests")

    # any peer without the key: every command refused, naming the proof; nothing changes
    with PlannerClient([stack.endpoint]) as peer:
        for command in ("start", "hold", "status"):
            with pytest.raises(ClientError) as refused:
                peer.operator(command, timeout_s=10.0)
            assert refused.value.field == "proof", refused.value
        with pytest.raises(ClientError) as wrong:
            peer.operator("start", timeout_s=10.0, key=b"\x07" * 32)
        assert (wrong.value.field, wrong.value.message[:14]) == ("proof", "does not match")
    time.sleep(1.0)  # time enough for the arming a start would have commanded
    status = client.state().status
    assert (status.authority, status.armed) == ("none", False), status
    assert "operator command refused: proof: " in service.log()

    # the key holder: a start, captured as an eavesdropper would, then sent again after a hold
    key, keys = stack.operator_key(), Keys()
    ref, at_ms = "captured-1", int(time.time() * 1000)
    captured = encode(OperatorCommand(command="start", reason="range clear", client_ref=ref, sent_at_ms=at_ms,
                                      proof=sign(key, keys, "start", "range clear", ref, at_ms)))
    started = send(client, captured)
    assert isinstance(started, OperatorReply) and started.accepted, started
    assert stack.operator("hold", "pilot takes over").accepted
    replayed = send(client, captured)
    assert isinstance(replayed, ErrorReply) and replayed.field == "client_ref", replayed
    assert "already used" in replayed.message
    assert client.state().status.authority == "none"

    # item 5: the public state names nobody; the operator's status holds everyone
    public = client.state()
    assert public.pending == [] and public.status.pending_requests == 2
    assert public.plan is not None and public.plan.points and all(p.user_id is None for p in public.plan.points)
    fleet = stack.fleet()
    assert [(p.user_id, p.x_m, p.y_m, p.tasks) for p in fleet.pending] == [("u-1", 100.0, 120.0, 9),
                                                                           ("u-2", 300.0, 320.0, 4)]
    assert fleet.plan is not None and {p.user_id for p in fleet.plan.points} <= {"u-1", "u-2"}
    assert "Traceback" not in service.log()


def test_a_key_file_others_may_read_stops_the_service_at_start(tmp_path: Path) -> None:
    key = tmp_path / "operator.key"
    key.write_text("ab" * 32 + "\n")
    os.chmod(key, 0o644)
    out = subprocess.run([sys.executable, "-m", "planner_service", "serve", "--journal", str(tmp_path / "j.sqlite"),
                          "--mavlink", "udpout:127.0.0.1:9", "--listen", "tcp/127.0.0.1:9"],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert lines[0] == (f"error: operator.key_file: {key}: permissions 0644 are too open: the key must be readable "
                        f"by its owner only (chmod 600 {key})")
    assert not (tmp_path / "j.sqlite").exists()




@pytest.mark.skipif(os.geteuid() != 0, reason="only root can give a file to another user")
def test_a_key_file_another_user_owns_stops_the_service_at_start(tmp_path: Path) -> None:
    """Issue 34, finding 9: a service running as root took an ``operator.key`` planted beside
    its journal by another user (mode 0600, owned by them): whoever planted it could then
    prove any command. Now refused at start, naming the owner."""
    key = tmp_path / "operator.key"
    key.write_text("ab" * 32 + "\n")
    os.chmod(key, 0o600)
    os.chown(key, 65534, 65534)  # nobody
    out = subprocess.run([sys.executable, "-m", "planner_service", "serve", "--journal", str(tmp_path / "j.sqlite"),
                          "--mavlink", "udpout:127.0.0.1:9", "--listen", "tcp/127.0.0.1:9"],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert lines[0].startswith(f"error: operator.key_file: {key}: is owned by uid 65534, not by this process's user "
                               f"(uid 0)"), lines[0]
    assert not (tmp_path / "j.sqlite").exists()
