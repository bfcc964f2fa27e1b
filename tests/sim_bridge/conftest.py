"""Fixtures that start the vehicle stub and the lossy proxy as real processes on loopback."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable, Iterator

import pytest

from planner_service.harness.processes import free_port, tied_to_parent
from tests.support.gcs import GroundStation

REPO = Path(__file__).resolve().parents[2]


class Process:
    """A ``python -m sim_bridge ...`` child with its stderr in a file."""

    def __init__(self, args: list[str], log_path: Path, ready: str) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
        self.log_path = log_path
        self._log = open(log_path, "w")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "sim_bridge", *args], cwd=REPO, env=env,
            stdout=subprocess.DEVNULL, stderr=self._log, preexec_fn=tied_to_parent(),
        )
        deadline = time.monotonic() + 20.0
        while ready not in self.log():
            if self.proc.poll() is not None:
                raise RuntimeError(f"{args[0]} exited with {self.proc.returncode}:\n{self.log()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"{args[0]} not ready:\n{self.log()}")
            time.sleep(0.05)

    def log(self) -> str:
        return self.log_path.read_text()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._log.close()
        return self.proc.returncode


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., Process]]:
    """spawn(args, ready) starts a sim_bridge command and stops it after the test."""
    started: list[Process] = []

    def start(args: list[str], ready: str) -> Process:
        process = Process(args, tmp_path / f"{args[0]}-{len(started)}.log", ready)
        started.append(process)
        return process

    yield start
    for process in reversed(started):
        process.stop()


@pytest.fixture
def vehicle(spawn: Callable[..., Process]) -> Callable[..., tuple[Process, int]]:
    """vehicle(*extra_args) -> (process, udp port) of a vehicle listening on udpin."""

    def start(*extra: str) -> tuple[Process, int]:
        port = free_port(socket.SOCK_DGRAM)
        if "--disarm-delay-s" not in extra:
            # The stub disarms 10 simulated seconds after arming on the ground, as ArduCopter
            # does: 33 ms of wall time at x300, less than a busy machine may take between a
            # test's arm and its start (a CI run: no MISSION_ITEM_REACHED, the vehicle had
            # disarmed). Off here; test_flight_missions.py checks the disarm itself.
            extra = ("--disarm-delay-s", "0", *extra)
        process = spawn(["vehicle", "--mavlink", f"udpin:127.0.0.1:{port}", *extra], "listening")
        return process, port

    return start


@pytest.fixture
def gcs_factory() -> Iterator[Callable[..., GroundStation]]:
    """Ground stations (tests/support/gcs.py) closed when the test ends."""
    stations: list[GroundStation] = []

    def make(url: str, **kwargs: object) -> GroundStation:
        station = GroundStation(url, **kwargs)  # type: ignore[arg-type]
        stations.append(station)
        return station

    yield make
    for station in stations:
        station.close()
