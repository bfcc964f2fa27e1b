"""The operator role under mutual TLS and access control, from the shipped files (as
test_zenoh_tls_acl.py runs them): an operator certificate (make-certs.sh's operator.pem, and
one more made with --operator) sends start, hold and status and is answered, and watches;
a user certificate's operator command gets no reply at all (the service's session drops the
query) and changes nothing, while the same user is still served on the request key; a user
certificate's state shows no user's position or backlog and its subscription to the plan
gets nothing, while the operator's status holds every pending request; no operator key is
made (the certificate is the proof)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner_service.harness.processes import REPO, free_port
from protocol import Plan
from protocol.client import ClientError, PlannerClient
from tests.support.stack import Stack
from tests.support.zenoh_tls import make_certs, shipped


def operator(endpoint: str, conf: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "planner_service", "operator", *args, "--connect", endpoint,
                           "--zenoh-config", str(conf), "--timeout", "3"],
                          cwd=REPO, capture_output=True, text=True, timeout=60)


@pytest.mark.timeout(180)
def test_only_operator_certificates_may_command(stack: Stack, tmp_path: Path) -> None:
    certs = tmp_path / "tls"
    make_certs(certs)
    make_certs(certs, "--operator", "console2")
    make_certs(certs, "--user", "u-1")  # the shipped example user
    assert (certs / "operator.pem").is_file() and (certs / "console2.pem").is_file()
    service_conf = shipped("service-tls-acl.json5", certs, tmp_path / "service.json5")
    user_conf = shipped("user-tls.json5", certs, tmp_path / "user.json5", **{"/user.": "/u-1."})
    operator_conf = shipped("operator-tls.json5", certs, tmp_path / "operator.json5")
    console2_conf = shipped("operator-tls.json5", certs, tmp_path / "console2.json5", **{"/operator.": "/console2."})

    endpoint = f"tls/127.0.0.1:{free_port()}"
    stack.endpoint = endpoint
    stack.vehicle()
    stack.client = PlannerClient([endpoint], config_file=operator_conf)  # the stack's follower is the operator
    stack.service(zenoh__mode="router", zenoh__config_file=str(service_conf))

    # under access control the certificate is the proof: no operator key is made
    assert not (stack.journal_path.parent / "operator.key").exists()
    assert "zenoh access control" in stack.children[-1].log()

    # a user: served on the request key, unanswered on the operator key
    with PlannerClient([endpoint], mode="client", config_file=user_conf) as user:
        plans: list[Plan] = []
        user.follow_plans(plans.append)  # the plan names users: not a user certificate's to follow
        assert user.submit("u-1", 100.0, 120.0, 9).request_id == 1
        # issue 23, item 5: the state gave every user's position and backlog to every user
        # certificate; now it holds nothing personal (the operator's status has it, below)
        public = user.state()
        assert public.pending == [] and public.status.pending_requests == 1
        t0 = time.monotonic()
        with pytest.raises(ClientError, match="no reply on uavmec/uav1/operator within 3 s") as silent:
            user.operator("start", timeout_s=3.0)
        print(f"\nuser's start: {silent.value.message} after {time.monotonic() - t0:.1f} s")
        stack.wait_log(stack.children[-1], "plan 1: ", 120.0)  # a plan published
        time.sleep(0.5)
        assert plans == [], plans
    by_user = operator(endpoint, user_conf, "start")
    assert by_user.returncode == 1 and by_user.stdout == "", by_user
    assert "error: service: no reply on uavmec/uav1/operator" in by_user.stderr
    assert "only operators may send commands" in by_user.stderr and "Traceback" not in by_user.stderr
    assert stack.client.state().status.authority == "none"  # nothing changed

    # the operators: answered
    deadline = time.monotonic() + 30
    while stack.client.state().status.phase == "lost" and time.monotonic() < deadline:
        time.sleep(0.2)
    started = operator(endpoint, operator_conf, "start", "--reason", "range clear")
    assert started.returncode == 0, (started.stdout, started.stderr)
    assert started.stdout.startswith("accepted: start: authority given")
    status = operator(endpoint, console2_conf, "status")
    assert status.returncode == 0 and "authority operator: given by the operator (range clear)" in status.stdout
    watched = operator(endpoint, operator_conf, "watch", "--once")
    assert watched.returncode == 0, watched.stderr
    assert "service alive" in watched.stdout and "authority  operator: given by the operator" in watched.stdout
    assert "pending    1: u-1 (9 tasks at 100, 120)" in watched.stdout, watched.stdout  # the operator's status
    with PlannerClient([endpoint], mode="client", config_file=operator_conf) as console:
        fleet = console.operator("status", timeout_s=5.0).state  # no key: the certificate is the proof
        assert fleet is not None and [(p.user_id, p.tasks) for p in fleet.pending] == [("u-1", 9)]
    held = operator(endpoint, console2_conf, "hold")
    assert held.returncode == 0 and "authority none, phase" in held.stdout
    service = stack.children[-1]
    assert service.proc.poll() is None and "Traceback" not in service.log()
