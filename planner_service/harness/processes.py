"""Child processes for the demo and the end-to-end bench: each in its own process group
with its stderr in a log file, started ready (a line in its log) and always stopped
(SIGINT, then SIGKILL to the group after a bounded wait). On Linux a child is also killed
when the process that started it dies without stopping it (a killed test run): an orphaned
vehicle stub would go on flying, writing its state and track files where the next run's
test of the same name writes its own."""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable

from ..service.errors import ServiceError

REPO = Path(__file__).resolve().parents[2]


class ChildError(ServiceError):
    """A child process failed to start or become ready."""


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port on 127.0.0.1 that was free a moment ago (TCP by default, SOCK_DGRAM for UDP)."""
    with socket.socket(socket.AF_INET, kind) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


PR_SET_PDEATHSIG = 1
_prctl = ctypes.CDLL(None).prctl if sys.platform == "linux" else None
"""Looked up here, not in the child: a lookup there (dlopen's lock) could hang a child
forked while another thread of ours held that lock."""


def die_with_parent() -> None:
    """In the child before exec: SIGKILL when the parent's thread that started it ends."""
    if _prctl is not None:
        _prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def tied_to_parent() -> Callable[[], None] | None:
    """``die_with_parent`` for a child started from the main thread; None from another,
    whose end (not the process's) would kill the child."""
    return die_with_parent if threading.current_thread() is threading.main_thread() else None


class Child:
    """``python -m MODULE ARGS`` with stderr in ``log_path`` (``ProgramChild``: any program)."""

    def __init__(self, module: str, args: list[str], log_path: Path, program: list[str] | None = None) -> None:
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.name = f"{module} {args[0] if args else ''}".strip()
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen(program or [sys.executable, "-m", module, *args], cwd=REPO, env=env,
                                     stdout=subprocess.DEVNULL, stderr=self._log, start_new_session=True,
                                     preexec_fn=tied_to_parent())

    def log(self) -> str:
        return self.log_path.read_text(errors="replace")

    def wait_ready(self, marker: str, timeout_s: float = 30.0) -> None:
        deadline = time.monotonic() + timeout_s
        while marker not in self.log():
            if self.proc.poll() is not None:
                raise ChildError(f"{self.name} exited with {self.proc.returncode}:\n{self.log()[-2000:]}")
            if time.monotonic() > deadline:
                raise ChildError(f"{self.name} not ready after {timeout_s:g} s:\n{self.log()[-2000:]}")
            time.sleep(0.05)

    def stop(self, timeout_s: float = 10.0) -> int:
        """SIGINT, wait, then SIGKILL to the whole group; the exit status."""
        if self.proc.poll() is None:
            try:
                self.proc.send_signal(signal.SIGINT)
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                self.proc.wait(5)
        if not self._log.closed:
            self._log.close()
        return int(self.proc.returncode)


def cpu_seconds(pid: int) -> float | None:
    """The CPU time (user + system) process ``pid`` has used so far; None once it is gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def peak_rss_mb(pid: int) -> float | None:
    """The most resident memory process ``pid`` has held (VmHWM); None once it is gone."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


class ProgramChild(Child):
    """Another program (``argv``) as a child: stderr in ``log_path``, stopped as a child is."""

    def __init__(self, argv: list[str], log_path: Path) -> None:
        super().__init__(Path(argv[0]).name, [], log_path, program=argv)


def start_vehicle_and_service(folder: Path, vehicle_args: list[str] | None, children: list[Child]) -> None:
    """Start the vehicle stub (``python -m sim_bridge vehicle VEHICLE_ARGS``; None: no stub,
    the service flies an autopilot of its own), then the service on ``folder/planner.toml``,
    each once ready; both are appended to ``children`` as they start, so the caller's
    cleanup stops whatever did start."""
    if vehicle_args is not None:
        vehicle = Child("sim_bridge", ["vehicle", *vehicle_args], folder / "vehicle.log")
        children.append(vehicle)
        vehicle.wait_ready("listening")
    service = Child("planner_service", ["serve", "--config", str(folder / "planner.toml")], folder / "service.log")
    children.append(service)
    service.wait_ready("ready:", 60.0)
