"""The harness's child processes (harness/processes.py) die with the process that started
them: a test run killed mid-test (a CI time-out, an interrupted flake hunt) must not leave a
vehicle stub flying and writing its state and track files into the next run's folders."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from planner_service.harness.processes import REPO, free_port

STARTER = """
import sys, time
from pathlib import Path
from planner_service.harness.processes import Child
child = Child("sim_bridge", ["vehicle", "--mavlink", "udpin:127.0.0.1:{port}"], Path(sys.argv[1]))
child.wait_ready("listening")
print(child.proc.pid, flush=True)
time.sleep(120)
"""


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(") ", 1)[1][0] != "Z"  # a zombie has died
    except FileNotFoundError:
        return False


def test_a_child_dies_with_the_process_that_started_it(tmp_path: Path) -> None:
    script = STARTER.format(port=free_port(socket.SOCK_DGRAM))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    starter = subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "vehicle.log")], cwd=REPO, env=env,
                               stdout=subprocess.PIPE, text=True)
    try:
        assert starter.stdout is not None
        child = int(starter.stdout.readline())
        assert alive(child)
        starter.send_signal(signal.SIGKILL)  # no cleanup runs
        starter.wait(10)
        deadline = time.monotonic() + 20.0
        while alive(child) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not alive(child), "the vehicle stub outlived the process that started it"
    finally:
        if starter.poll() is None:
            starter.kill()
            starter.wait()
