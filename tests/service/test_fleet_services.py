"""Fleet membership between real ``serve`` processes on loopback: a service configured into
another member's layer refuses to start (before it takes a request or touches its vehicle),
one in a layer of its own joins (``operator watch`` shows both), and its loss is seen by the
others."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from planner_service.harness.processes import Child, free_port
from planner_service.service.config import build_config, to_toml
from tests.support.fleet import ROSTER, fleet_settings
from tests.support.stack import Stack

FLEET = {"fleet.enabled": "true", "fleet.discovery_s": "1.0", **fleet_settings()}


def second_service(stack: Stack, folder: Path, altitude_m: float) -> Child:
    """uav2's service, its own journal and a vehicle port nobody answers (the fleet is joined
    before the vehicle matters), its zenoh session connected to uav1's."""
    folder.mkdir()
    config = build_config({}, {**FLEET, **fleet_settings(vehicle="uav2"), "zenoh.vehicle": "uav2", "zenoh.connect": stack.endpoint,
                               "mavlink.url": f"udpout:127.0.0.1:{free_port(socket.SOCK_DGRAM)}",
                               "journal.path": str(folder / "journal.sqlite"),
                               "scenario.altitude_m": str(altitude_m)})
    path = folder / "planner.toml"
    path.write_text(to_toml(config))
    child = Child("planner_service", ["serve", "--config", str(path)], folder / "service.log")
    stack.children.append(child)
    return child


def wait_exit(child: Child, timeout_s: float) -> int:
    deadline = time.monotonic() + timeout_s
    while child.proc.poll() is None:
        assert time.monotonic() < deadline, f"{child.name} still running after {timeout_s} s"
        time.sleep(0.05)
    return child.proc.returncode


def test_a_service_in_another_members_layer_refuses_to_start(stack: Stack, tmp_path: Path) -> None:
    stack.vehicle()
    first = stack.service(**FLEET)  # uav1 at the preset's 100 m
    stack.wait_log(first, "fleet: joined as uav1, layer 100 m", 10.0)

    # 10 m above: on the 10 m vertical separation itself, no margin (issue 35, finding 2)
    clash = second_service(stack, tmp_path / "clash", 110.0)
    assert wait_exit(clash, 60.0) == 1
    assert ("error: fleet: uav1 flies at 100 m, within 15 m of this UAV's layer 110 m (fleet.vertical_separation_m "
            "+ fleet.altitude_margin_m)") in clash.log()
    assert "ready:" not in clash.log()

    other = second_service(stack, tmp_path / "other", 115.0)
    other.wait_ready("ready:", 60.0)
    assert "fleet: joined as uav2, layer 115 m; uav1 at 100 m" in other.log()
    stack.wait_log(first, "fleet: uav2 announced layer 115 m", 10.0)
    watch = subprocess.run([sys.executable, "-m", "planner_service", "operator", "watch", "--once", "--plain",
                            "--connect", stack.endpoint, "--operator-key", str(stack.operator_key_path),
                            "--fleet-roster", str(ROSTER)],
                           capture_output=True, text=True, timeout=60)
    assert watch.returncode == 0, watch.stderr
    assert "fleet      2 members: uav1 100 m (this), uav2 115 m" in watch.stdout, watch.stdout
    # both on the ground (uav2's vehicle not even there), each position from its own status
    assert "separation ok" in watch.stdout, watch.stdout
    other.proc.send_signal(signal.SIGKILL)  # as a companion computer that dies: no goodbye
    stack.wait_log(first, "fleet: uav2 left", 20.0)
    assert first.proc.poll() is None
