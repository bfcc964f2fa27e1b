"""``python -m sim_bridge vehicle --count N``: N vehicles in one process, each its own port,
system id and origin (40 m apart, east), as a real child process and a pymavlink ground
station per vehicle; the command line's refusals; one vehicle failing stops them all."""

from __future__ import annotations

import logging
import re
import socket
import subprocess
import sys
import threading
from pathlib import Path
from typing import Callable

import pytest

from planner_service.harness.processes import Child, free_port
from protocol.geodesy import GeoOrigin, global_to_local
from sim_bridge.commands.vehicle import fly_all
from tests.support.gcs import M, GroundStation

COUNT = 3
DEADLINE_S = 30.0
"""Generous: a loaded 2-core machine starts a stub in seconds, not milliseconds."""


def free_udp_ports(count: int) -> int:
    """The first of ``count`` consecutive UDP ports on 127.0.0.1 that were free a moment ago."""
    for _ in range(50):
        base = free_port(socket.SOCK_DGRAM)
        if base + count - 1 > 65535:
            continue
        held: list[socket.socket] = []
        try:
            for port in range(base, base + count):
                sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                held.append(sock)
                sock.bind(("127.0.0.1", port))
        except OSError:
            continue
        finally:
            for sock in held:
                sock.close()
        return base
    raise RuntimeError(f"no {count} consecutive free UDP ports")


@pytest.mark.timeout(180)
def test_three_vehicles_in_one_process_each_its_port_system_id_and_origin(tmp_path: Path) -> None:
    base = free_udp_ports(COUNT)
    stub = Child("sim_bridge", ["vehicle", "--count", str(COUNT), "--mavlink", f"udpin:127.0.0.1:{base}",
                                "--gps-delay-s", "0", "--speedup", "10", "--track", str(tmp_path / "track-{i}.csv"),
                                "--state-file", str(tmp_path / "state-{i}.json")], tmp_path / "vehicle.log")
    stations: list[GroundStation] = []
    try:
        stub.wait_ready(f"{COUNT} vehicles listening", DEADLINE_S)
        log = stub.log()
        all_up = log.index(f"{COUNT} vehicles listening")
        for i in range(COUNT):
            line = re.search(rf"vehicle sysid={1 + i} INFO \S+: vehicle \(ardupilot\) listening on "
                             rf"udpin:127\.0\.0\.1:{base + i},", log)
            assert line is not None and line.start() < all_up, log
        east = []
        for i in range(COUNT):
            gcs = GroundStation(f"udpout:127.0.0.1:{base + i}", timeout_s=1.0)
            stations.append(gcs)
            hb = gcs.wait_vehicle(DEADLINE_S)
            assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1 + i, 1)
            gcs.ask([M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT])
            position = gcs.recv(["GLOBAL_POSITION_INT"], DEADLINE_S, lambda m, s=1 + i: m.get_srcSystem() == s)
            assert position is not None, f"no GLOBAL_POSITION_INT from vehicle {i}"
            x, y, _ = global_to_local(GeoOrigin(), position.lat / 1e7, position.lon / 1e7, GeoOrigin().alt_m)
            east.append((x, y))
        for i in range(1, COUNT):  # each 40 m (--spacing-m's default) east of the one before, same latitude
            assert east[i][0] - east[i - 1][0] == pytest.approx(40.0, abs=0.05), east
            assert east[i][1] == pytest.approx(east[0][1], abs=0.05), east
    finally:
        for gcs in stations:
            gcs.close()
        status = stub.stop(DEADLINE_S)
    assert status == 0, stub.log()[-2000:]
    assert "Traceback" not in stub.log()
    assert sorted(p.name for p in tmp_path.glob("track-*")) == [f"track-{i}.csv" for i in range(COUNT)]
    assert sorted(p.name for p in tmp_path.glob("state-*")) == [f"state-{i}.json" for i in range(COUNT)]


@pytest.mark.parametrize("args, words", [
    (("--track", "track.csv"), "--track track.csv: with --count 3 the path must contain {i}"),
    (("--state-file", "state.json"), "--state-file state.json: with --count 3 the path must contain {i}"),
    (("--signing-key", "k", "--signing-timestamp-file", "ts"), "--signing-timestamp-file ts: with --count 3"),
    (("--sysid", "254"), "--count 3 with --sysid 254: system ids up to 256; a MAVLink system id is at most 255"),
    (("--mavlink", "udpin:127.0.0.1:65534"), "ports up to 65536; a port is at most 65535"),
])
def test_count_refuses_what_vehicles_would_share_or_overflow(tmp_path: Path, python_env: dict[str, str],
                                                              args: tuple[str, ...], words: str) -> None:
    out = subprocess.run([sys.executable, "-m", "sim_bridge", "vehicle", "--count", str(COUNT), *args],
                         cwd=tmp_path, env=python_env, capture_output=True, text=True, timeout=120)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and words in lines[0], out.stderr
    assert "Traceback" not in out.stderr and out.stdout == ""
    assert list(tmp_path.iterdir()) == []  # nothing started, no file made


class FakeVehicle:
    """What ``fly_all`` uses of a ``Vehicle``: its system id and ``run``."""

    def __init__(self, system_id: int, fail: bool = False) -> None:
        self.config = type("Config", (), {"system_id": system_id})()
        self.fail = fail
        self.stopped = False

    def run(self, stop: threading.Event, on_listening: Callable[[], None]) -> None:
        on_listening()
        if self.fail:
            raise OSError("the socket went away")
        stop.wait()
        self.stopped = True


@pytest.mark.timeout(60)
def test_one_vehicle_failing_stops_every_vehicle_and_fails_the_process(caplog: pytest.LogCaptureFixture) -> None:
    vehicles = [FakeVehicle(1), FakeVehicle(2, fail=True), FakeVehicle(3)]
    stop = threading.Event()
    with caplog.at_level(logging.INFO):
        status = fly_all(vehicles, stop)  # type: ignore[arg-type]
    assert status == 1 and stop.is_set()
    assert vehicles[0].stopped and vehicles[2].stopped
    assert "vehicle sysid=2 failed: stopping every vehicle" in caplog.text
    assert "OSError: the socket went away" in caplog.text
    assert "stopped: vehicle(s) with system id 2 failed" in caplog.text
