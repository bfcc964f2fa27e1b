"""The vehicle stub with ``--signing-key``: a ground station with the key flies it; unsigned
and wrongly signed commands and mission messages change nothing and get no answer; a
replayed signed command is ignored; a ground station restarted with its clock an hour back
is still heard thanks to its timestamp file."""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from protocol.mission import same_items
from protocol.signing import Signer, TimestampStore, load_key, write_key
from tests.support.gcs import M, GcsError, GroundStation, as_stored, ten_items

ARDUPILOT_GUIDED = 4
ARDUPILOT_AUTO = 3


@pytest.fixture
def key_path(tmp_path: Path) -> Path:
    path = tmp_path / "vehicle.key"
    write_key(path)
    return path


@pytest.fixture
def stations():
    made: list[GroundStation] = []

    def make(port: int, signer: Signer | None = None, **kwargs) -> GroundStation:
        station = GroundStation(f"udpout:127.0.0.1:{port}", signer=signer, **kwargs)
        made.append(station)
        return station

    yield make
    for station in made:
        station.close()


def armed(hb) -> bool:
    return bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def latest_heartbeat(gcs: GroundStation):
    """A heartbeat sent after this call (the vehicle sends one a second)."""
    gcs.recv(["HEARTBEAT"], 2.0)
    hb = gcs.recv(["HEARTBEAT"], 2.0)
    assert hb is not None and hb.get_signed(), "the vehicle's telemetry must come signed"
    return hb


def signing_line(log: str) -> str:
    lines = [line for line in log.splitlines() if "signing:" in line]
    assert lines, f"no signing summary in the vehicle's log:\n{log[-2000:]}"
    return lines[-1]


@pytest.mark.timeout(60)
def test_the_right_key_uploads_downloads_arms_and_flies(vehicle, stations, key_path: Path) -> None:
    process, port = vehicle("--signing-key", str(key_path), "--speedup", "300", "--gps-delay-s", "0")
    gcs = stations(port, Signer(load_key(key_path)))
    hb = gcs.wait_vehicle()
    assert hb.get_signed()
    items = ten_items()
    assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
    assert same_items(gcs.download(), as_stored(items, "ardupilot"))
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    time.sleep(0.2)  # a busy machine's pause between two commands: 60 simulated seconds armed
    assert gcs.set_mode(ARDUPILOT_AUTO) == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_MISSION_START, 0, 0) == M.MAV_RESULT_ACCEPTED
    reached = gcs.recv(["MISSION_ITEM_REACHED"], 20.0)
    assert reached is not None and reached.get_signed()
    process.stop()
    summary = signing_line(process.log())
    assert " 0 dropped" in summary, summary


@pytest.mark.timeout(60)
def test_unsigned_and_wrongly_signed_messages_change_nothing(vehicle, stations, key_path: Path) -> None:
    process, port = vehicle("--signing-key", str(key_path), "--gps-delay-s", "0")
    gcs = stations(port, Signer(load_key(key_path)))
    gcs.wait_vehicle()
    mission = ten_items()
    assert gcs.upload(mission) == M.MAV_MISSION_ACCEPTED
    before = latest_heartbeat(gcs)
    assert not armed(before) and before.custom_mode != ARDUPILOT_GUIDED

    forger = Signer(bytes(32))  # another key, and a timestamp far ahead on the real station's stream
    forger.state.timestamp = (1 << 48) - 1000
    attackers = {"unsigned": stations(port), "wrong key": stations(port, forger)}
    for name, attacker in attackers.items():
        mav = attacker.conn.mav
        for _ in range(3):
            mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            mav.command_long_send(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
            mav.command_long_send(1, 1, M.MAV_CMD_DO_SET_MODE, 0, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                  ARDUPILOT_GUIDED, 0, 0, 0, 0, 0)
            mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, ARDUPILOT_GUIDED)
            mav.mission_count_send(1, 1, 3, M.MAV_MISSION_TYPE_MISSION)
            mav.send(mission[1].to_message(1, 1))
            mav.mission_clear_all_send(1, 1, M.MAV_MISSION_TYPE_MISSION)
        # No COMMAND_ACK, no MISSION_REQUEST: nothing at all, not even a greeting heartbeat.
        heard = attacker.recv(None, 1.5)
        assert heard is None, f"{name}: the vehicle answered with {heard}"

    after = latest_heartbeat(gcs)
    assert not armed(after) and after.custom_mode == before.custom_mode
    assert same_items(gcs.download(), as_stored(mission, "ardupilot")), "the held mission must be unchanged"
    # The same requests, signed with the key, do take effect (so the checks above can fail),
    # and the forged far-future timestamp did not lock the real station out.
    gcs.conn.mav.set_mode_send(1, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, ARDUPILOT_GUIDED)
    assert gcs.recv(["HEARTBEAT"], 3.0, lambda m: m.custom_mode == ARDUPILOT_GUIDED) is not None
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED

    process.stop()
    summary = signing_line(process.log())
    for kind in ("COMMAND_LONG 12", "SET_MODE 6", "MISSION_COUNT 6", "MISSION_ITEM_INT 6", "MISSION_CLEAR_ALL 6",
                 "HEARTBEAT 6", "bad signature 21", "unsigned 21"):
        assert kind in summary, summary
    assert "Traceback" not in process.log()


@pytest.mark.timeout(60)
def test_a_replayed_signed_command_is_ignored(vehicle, stations, key_path: Path) -> None:
    process, port = vehicle("--signing-key", str(key_path))
    gcs = stations(port, Signer(load_key(key_path)))
    gcs.wait_vehicle()
    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    captured = arm.pack(gcs.conn.mav)  # the exact signed bytes, as an eavesdropper records them
    gcs.conn.write(captured)
    ack = gcs.recv(["COMMAND_ACK"], 2.0, lambda m: m.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED  # disarm, freshly signed
    assert not armed(latest_heartbeat(gcs))

    gcs.conn.write(captured)  # replayed from the station's own address
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:  # and from another one
        other.bind(("127.0.0.1", 0))
        other.sendto(captured, ("127.0.0.1", port))
        other.settimeout(1.5)
        with pytest.raises(TimeoutError):
            other.recvfrom(4096)
    assert gcs.recv(["COMMAND_ACK"], 0.5) is None
    assert not armed(latest_heartbeat(gcs))
    process.stop()
    assert "replayed 2" in signing_line(process.log())


@pytest.mark.timeout(60)
def test_a_station_restarted_with_its_clock_back_is_heard_only_with_its_timestamp_file(
        vehicle, stations, key_path: Path, tmp_path: Path) -> None:
    _, port = vehicle("--signing-key", str(key_path))
    key = load_key(key_path)
    first = Signer(key, TimestampStore(tmp_path / "gcs-ts"))
    gcs = stations(port, first)
    gcs.wait_vehicle()
    assert gcs.arm() == M.MAV_RESULT_ACCEPTED
    gcs.close()
    first.close()

    hour_back = lambda: time.time() - 3600.0  # noqa: E731
    restarted = Signer(key, TimestampStore(tmp_path / "gcs-ts", clock=hour_back))
    gcs = stations(port, restarted)
    assert gcs.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 0) == M.MAV_RESULT_ACCEPTED  # heard: disarmed
    restarted.close()
    gcs.close()

    clock_only = stations(port, Signer(key, clock=hour_back), retries=4)
    with pytest.raises(GcsError, match="no COMMAND_ACK"):
        clock_only.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1)  # its timestamps look like replays


@pytest.mark.timeout(60)
def test_the_vehicle_refuses_a_key_others_can_read(key_path: Path, python_env) -> None:
    key_path.chmod(0o644)
    done = subprocess.run([sys.executable, "-m", "sim_bridge", "vehicle", "--mavlink", "udpin:127.0.0.1:0",
                           "--signing-key", str(key_path)], env=python_env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert str(key_path) in done.stderr and "0644" in done.stderr and "chmod 600" in done.stderr
