"""A peer that restarts. (a) The users' side: a client session closed and a new one opened
is served at once. (b) The service in client mode behind a zenoh router (``sim_bridge
router``: a session in router mode): started before the router it waits for it; the router
killed and restarted, the service's liveliness token comes back and requests are served
again, and the service never exits meanwhile."""

from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from planner_service.harness.processes import Child, free_port
from protocol.client import ClientError, PlannerClient
from tests.support.stack import Stack

RESTARTS = 2


@pytest.mark.timeout(60)
def test_a_new_client_session_is_served_at_once(stack: Stack) -> None:
    stack.vehicle()
    stack.service()
    times = []
    for n in range(3):
        t0 = time.perf_counter()
        with PlannerClient([stack.endpoint]) as client:
            t1 = time.perf_counter()
            ack = client.submit(f"session-{n}", 100.0, 100.0 + n, 3, timeout_s=5.0)  # no waiting first
            times.append(((t1 - t0) * 1e3, (time.perf_counter() - t1) * 1e3))
        assert ack.user_id == f"session-{n}"
    print("\nnew client session: open / first request acked in " +
          ", ".join(f"{a:.0f} / {b:.1f}" for a, b in times) + " ms")
    assert [p.user_id for p in stack.fleet().pending] == ["session-0", "session-1", "session-2"]  # type: ignore[union-attr]


def router(stack: Stack, endpoint: str, n: int) -> Child:
    child = Child("sim_bridge", ["router", "--listen", endpoint], stack.tmp / f"router-{n}.log")
    stack.children.append(child)
    child.wait_ready("router listening")
    return child


@pytest.mark.timeout(300)
@pytest.mark.parametrize("down_s", [1.0, pytest.param(90.0, marks=pytest.mark.slow)])
def test_service_in_client_mode_survives_its_router_restarting(stack: Stack, down_s: float) -> None:
    stack.vehicle()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    stack.endpoint = endpoint  # the stack's client reaches the service through the router
    # the router comes up only once the service has said it waits for one
    routers: list[Child] = []

    def start_router_late() -> None:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not any(
                c.name == "planner_service serve" and "waiting for a zenoh router" in c.log() for c in stack.children):
            time.sleep(0.05)
        routers.append(router(stack, endpoint, 0))
    late = threading.Thread(target=start_router_late)
    late.start()
    service = stack.service(zenoh__mode="client", zenoh__connect=endpoint, zenoh__listen="")
    late.join()
    client = stack.client
    assert client is not None
    assert client.submit("before", 100.0, 100.0, 5).request_id == 1
    recoveries = []
    for n in range(1, RESTARTS + 1):
        os.kill(routers[-1].proc.pid, signal.SIGKILL)  # the router crashes
        time.sleep(down_s)
        assert service.proc.poll() is None
        with pytest.raises(ClientError):  # nobody routes meanwhile
            client.submit("meanwhile", 100.0, 100.0, 5, timeout_s=0.5)
        t0 = time.perf_counter()
        routers.append(router(stack, endpoint, n))
        assert client.wait_for_service(30.0), "the service's liveliness token never came back"
        alive_s = time.perf_counter() - t0
        ack = client.submit(f"after-{n}", 120.0, 100.0, 5, timeout_s=5.0)
        recoveries.append((alive_s, time.perf_counter() - t0))
        assert ack.user_id == f"after-{n}" and service.proc.poll() is None
    print(f"\nrouter down {down_s:g} s, restarted: service alive again / request acked after " +
          ", ".join(f"{a:.2f} s / {b:.2f} s" for a, b in recoveries) + " (from the new router's start)")
    log = service.log()
    assert "Traceback" not in log, log[-3000:]
