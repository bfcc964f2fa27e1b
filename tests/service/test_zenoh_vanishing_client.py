"""A client that disappears mid-query: a users process submitting as fast as it can is
SIGKILLed, several times. The service keeps running, logs no traceback, serves the next
client at once, and its open file descriptors return to their level before."""

from __future__ import annotations

import os
import signal
import time

import pytest

from tests.support.stack import Stack

KILLS = 5


def open_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


@pytest.mark.timeout(120)
def test_killed_clients_leave_nothing_behind(stack: Stack) -> None:
    stack.vehicle()
    # the bounds out of the way: every request reaches the journal, as a real load would
    service = stack.service(intake__max_requests_per_s="10000", intake__max_pending_requests="1000")
    client = stack.client
    assert client is not None
    pid = service.proc.pid
    time.sleep(0.5)
    fds_before = open_fds(pid)
    recoveries = []
    for n in range(KILLS):
        users = stack.users("--count", "100", "--interval", "0.001", "--seed", str(n), "--log-level", "INFO")
        users.wait_ready("-> request", 30.0)  # submitting
        time.sleep(0.3)
        os.kill(users.proc.pid, signal.SIGKILL)  # mid-query: it spends nearly all its time inside gets
        users.proc.wait(5)
        t0 = time.perf_counter()
        ack = client.submit(f"after-kill-{n}", 200.0, 200.0, 4, timeout_s=5.0)
        recoveries.append((time.perf_counter() - t0) * 1e3)
        assert ack.user_id == f"after-kill-{n}"
        assert service.proc.poll() is None, service.log()[-3000:]
        deadline = time.monotonic() + 10.0
        while open_fds(pid) > fds_before and time.monotonic() < deadline:
            time.sleep(0.05)
        assert open_fds(pid) <= fds_before, f"fds {open_fds(pid)} after kill {n + 1}, {fds_before} before"
    acked = stack.rows("SELECT COUNT(*) FROM requests")[0][0]
    print(f"\n{KILLS} clients killed mid-query ({acked} requests journalled); the next request acked in "
          f"{', '.join(f'{ms:.1f}' for ms in recoveries)} ms; service fds {fds_before} before, {open_fds(pid)} after")
    log = service.log()
    assert "Traceback" not in log and "Exception in callback" not in log, log[-3000:]
