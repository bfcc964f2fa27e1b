"""SIGTERM ends the service at once: the vehicle stub and the service as real processes on
loopback (tests/support/stack.py), SIGTERM to the service, and the process must be gone
within 1 s of its last log line ("stopped: journal flushed", by the line's own timestamp).

Twice: with the service idle (its planner warmed up), and with its warm-up still compiling
every kernel (an empty numba cache, as after an update), which Python's exit used to wait
for (69 s). An idle service used to spend 0.25 s after its last line, mostly collecting its
heap (0.8 s beside two CPU hogs): that case passed before, it guards the bound. The wait
for the exit itself has a generous deadline: a slow machine makes the test slow, not wrong."""

from __future__ import annotations

import signal
import subprocess
import time
from datetime import datetime
from pathlib import Path
from typing import Callable

import pytest

from tests.support.stack import Stack

EXIT_AFTER_LAST_LINE_S = 1.0
WARMED_UP = "planner warmed up"
LAST_LINE = "stopped: journal flushed"


def wait_for(predicate: Callable[[], bool], timeout_s: float, what: str, log: Callable[[], str]) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"{what} not within {timeout_s:g} s:\n{log()[-3000:]}")
        time.sleep(0.05)


def logged_at(line: str) -> float:
    """The wall time of a log line, by its own timestamp (``%(asctime)s``: local, to the ms)."""
    return datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S,%f").timestamp()


@pytest.mark.alone
@pytest.mark.parametrize("planner", ["idle", "compiling"])
def test_sigterm_ends_the_service_within_a_second_of_its_last_line(stack: Stack, monkeypatch: pytest.MonkeyPatch,
                                                                   tmp_path: Path, planner: str) -> None:
    stack.vehicle()
    if planner == "compiling":
        monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "empty-numba-cache"))  # the service's only
    service = stack.service()
    if planner == "idle":
        wait_for(lambda: WARMED_UP in service.log(), 300.0, "the planner's warm-up", service.log)
    service.proc.send_signal(signal.SIGTERM)
    try:
        service.proc.wait(120.0)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"the service still runs 120 s after SIGTERM:\n{service.log()[-3000:]}") from None
    exited = time.time()
    log = service.log()
    lines = [line for line in log.splitlines() if line.strip()]
    assert service.proc.returncode == 0 and lines[-1].endswith(LAST_LINE), log[-3000:]
    if planner == "compiling":
        assert WARMED_UP not in log, "the warm-up had ended before SIGTERM: this case tests nothing"
    after = exited - logged_at(lines[-1])
    print(f"\n{planner}: exited {after:.3f} s after its last line ({lines[-1][:23]})")
    assert after <= EXIT_AFTER_LAST_LINE_S, f"exited {after:.2f} s after its last line:\n{log[-3000:]}"
