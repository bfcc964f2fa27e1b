"""The service signs its MAVLink when ``mavlink.signing_key_file`` is set: with the vehicle's
key a request becomes an accepted mission; with another key nothing reaches the vehicle and
the service says why. Configuration refuses a key file others can read and the mavsdk backend."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from planner_service.service.config import build_config
from planner_service.service.errors import ConfigError
from planner_service.harness.processes import free_port
from protocol.signing import read_reservation, write_key
from tests.support.stack import Stack


def keys(tmp_path: Path, *names: str) -> list[Path]:
    paths = [tmp_path / name for name in names]
    for path in paths:
        write_key(path)
    return paths


def signing_summary(log: str) -> str:
    lines = [line for line in log.splitlines() if "signing:" in line]
    assert lines, f"no signing summary in:\n{log[-2000:]}"
    return lines[-1]


@pytest.mark.timeout(90)
def test_same_key_request_to_accepted_mission(stack: Stack, tmp_path: Path) -> None:
    (key,) = keys(tmp_path, "uav.key")
    vehicle = stack.vehicle("--signing-key", str(key))
    service = stack.service(mavlink__signing_key_file=str(key))
    assert stack.client is not None
    stack.client.submit("u1", 120.0, 80.0, 9)
    stack.wait_event(lambda e: e.event == "mission_uploaded", 30.0, "a mission accepted by the signing vehicle")
    service.stop()
    vehicle.stop()
    assert "mission of" in vehicle.log() and "items accepted" in vehicle.log()
    assert " 0 dropped" in signing_summary(vehicle.log()), "every message of the service was signed"
    assert " 0 dropped" in signing_summary(service.log()), "every message of the vehicle was signed"
    stamp = read_reservation(tmp_path / "uav.key.service-timestamp")
    assert stamp is not None and stamp > 0, "the service kept its last timestamp for its next start"


@pytest.mark.timeout(90)
def test_another_key_on_the_vehicle_fails_cleanly_and_says_so(stack: Stack, tmp_path: Path) -> None:
    ours, theirs = keys(tmp_path, "service.key", "vehicle.key")
    # The vehicle sends to the service whether or not it hears it, as a radio-linked
    # autopilot does, so the service sees the vehicle's signatures fail.
    port = free_port(socket.SOCK_DGRAM)
    vehicle = stack.vehicle("--signing-key", str(theirs), "--mavlink", f"udpout:127.0.0.1:{port}")
    service = stack.service(mavlink__signing_key_file=str(ours), mavlink__url=f"udpin:127.0.0.1:{port}")
    assert stack.client is not None
    stack.client.submit("u1", 120.0, 80.0, 9)
    deadline = time.monotonic() + 15.0
    while "signs with another key" not in service.log():
        assert time.monotonic() < deadline, f"the service never named the key mismatch:\n{service.log()[-2000:]}"
        time.sleep(0.2)
    time.sleep(2.0)  # time enough for a plan and an upload, had the link been up
    assert not any(e.event == "mission_uploaded" for e in stack.events)
    assert [r.user_id for r in stack.fleet().pending] == ["u1"], "the request stays pending"
    service.stop()
    vehicle.stop()
    warning = next(line for line in service.log().splitlines() if "signs with another key" in line)
    assert "bad signature" in warning and str(ours) in warning
    assert "mission of" not in vehicle.log()
    assert "Traceback" not in service.log() and "Traceback" not in vehicle.log()
    summary = signing_summary(vehicle.log())
    assert "0 signed accepted" in summary and "bad signature" in summary, summary


def test_config_refuses_signing_that_cannot_work(tmp_path: Path) -> None:
    (key,) = keys(tmp_path, "k")
    config = build_config({}, {"mavlink.signing_key_file": str(key)})
    assert config.mavlink.signing_key_file == str(key)
    key.chmod(0o644)
    with pytest.raises(ConfigError) as err:
        build_config({}, {"mavlink.signing_key_file": str(key)})
    assert err.value.key == "mavlink.signing_key_file" and str(key) in err.value.message and "0644" in err.value.message
    with pytest.raises(ConfigError) as err:
        build_config({}, {"mavlink.signing_key_file": str(tmp_path / "missing")})
    assert err.value.key == "mavlink.signing_key_file" and "missing" in err.value.message
    key.chmod(0o600)
    with pytest.raises(ConfigError) as err:
        build_config({}, {"mavlink.signing_key_file": str(key), "mavlink.backend": "mavsdk"})
    assert err.value.key == "mavlink.backend" and "signing needs the pymavlink backend" in err.value.message
    with pytest.raises(ConfigError) as err:
        build_config({}, {"mavlink.signing_key_file": str(key),
                          "mavlink.signing_timestamp_file": str(tmp_path / "no-such-dir" / "ts")})
    assert err.value.key == "mavlink.signing_timestamp_file"
    with pytest.raises(ConfigError) as err:
        build_config({}, {"mavlink.signing_timestamp_file": str(tmp_path / "ts")})
    assert err.value.key == "mavlink.signing_timestamp_file" and "without mavlink.signing_key_file" in err.value.message
