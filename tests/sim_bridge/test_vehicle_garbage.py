"""MAVLink garbage into the vehicle stub over UDP and TCP (tests/support/mavlink_garbage.py:
random bytes, truncated frames, flipped CRC, payload and header bytes, MAVLink 1 frames,
frames for another system, oversized datagrams, valid frames with garbage between them):
the stub stays up with no traceback, its state is what it was (the mission held, mode,
armed, position), a peer that sent only garbage is never sent anything, and a ground
station still uploads and downloads afterwards."""

from __future__ import annotations

import os
import socket
import time
from typing import Any

import pytest

from planner_service.harness.processes import free_port
from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, MissionItem, encode_path, same_items
from tests.support.gcs import M, GroundStation, as_stored
from tests.support.mavlink_garbage import chunks, random_frames, read_only_frames

ORIGIN = GeoOrigin()
SPOILED = 3000


def mission(shift_m: float = 0.0) -> list[MissionItem]:
    return encode_path([HoverPoint(50.0 + shift_m, 60.0, 40.0, 5.0), HoverPoint(200.0, 300.0 + shift_m, 60.0, 8.0)],
                       ORIGIN)


def snapshot(gcs: GroundStation) -> tuple[tuple[Any, ...], list[MissionItem]]:
    """What the vehicle says of itself: (armed, mode, status, landed state, position,
    current item), and the mission it holds."""
    hb = gcs.recv(["HEARTBEAT"], 3.0)
    pos = gcs.recv(["GLOBAL_POSITION_INT"], 3.0)
    landed = gcs.recv(["EXTENDED_SYS_STATE"], 3.0)
    current = gcs.recv(["MISSION_CURRENT"], 3.0)
    assert None not in (hb, pos, landed, current), "telemetry stopped"
    return (bool(hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED), hb.custom_mode, hb.system_status,
            landed.landed_state, pos.lat, pos.lon, pos.relative_alt, current.seq), gcs.download()


def quiet(sock: socket.socket, seconds: float) -> bool:
    """Nothing arrives on ``sock`` for ``seconds``."""
    sock.settimeout(seconds)
    try:
        sock.recv(65535)
    except socket.timeout:
        return True
    return False


@pytest.mark.timeout(60)
def test_udp_garbage_changes_nothing(vehicle, gcs_factory) -> None:
    process, port = vehicle("--gps-delay-s", "0")
    gcs = gcs_factory(f"udpout:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask()
    assert gcs.upload(mission()) == M.MAV_MISSION_ACCEPTED
    before = snapshot(gcs)
    sent = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as garbage, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as noise:
        garbage.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 1 << 20)
        for what, data in chunks(seed=1):
            garbage.sendto(data, ("127.0.0.1", port))
            sent += 1
            if len(data) > 4096:
                time.sleep(0.02)  # let the vehicle drain its receive buffer: every datagram is read
        for i, frame in enumerate(random_frames(seed=2, count=SPOILED)):
            noise.sendto(frame, ("127.0.0.1", port))
            if i % 200 == 0:
                time.sleep(0.01)
        sent += SPOILED
        # Spoiled frames only: that peer is not a ground station, so it is not answered.
        assert quiet(noise, 1.0), "the vehicle answered a peer that sent only garbage"
    after = snapshot(gcs)
    assert after[0] == before[0] and same_items(after[1], before[1])
    assert process.proc.poll() is None and "Traceback" not in process.log()
    assert gcs.upload(mission(shift_m=25.0)) == M.MAV_MISSION_ACCEPTED
    assert same_items(gcs.download()[1:], as_stored(mission(shift_m=25.0), "ardupilot")[1:])
    assert sent > SPOILED


@pytest.mark.timeout(60)
def test_tcp_garbage_changes_nothing_and_the_stream_recovers(spawn, gcs_factory) -> None:
    port = free_port()
    process = spawn(["vehicle", "--mavlink", f"tcpin:127.0.0.1:{port}", "--gps-delay-s", "0"], "listening")
    gcs = gcs_factory(f"tcp:127.0.0.1:{port}")
    gcs.wait_vehicle()
    gcs.ask()
    items = mission()
    assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
    before = snapshot(gcs)
    stream = b"".join(data for _, data in chunks(seed=3)) + b"".join(random_frames(seed=4, count=SPOILED))
    stream += os.urandom(1 << 20)  # a megabyte of noise
    with socket.create_connection(("127.0.0.1", port)) as raw:
        raw.sendall(stream)
        # The same connection then speaks valid MAVLink: a few hundred zero bytes end
        # whatever frame the parser is inside, and the requests are answered.
        raw.sendall(bytes(300) + b"".join(read_only_frames()) * 3)
        parser = M.MAVLink(None)
        parser.robust_parsing = True
        raw.settimeout(0.5)
        count = None
        deadline = time.monotonic() + 10.0
        while count is None and time.monotonic() < deadline:
            try:
                data = raw.recv(65535)
            except socket.timeout:
                continue
            for msg in parser.parse_buffer(data) or []:
                if msg.get_type() == "MISSION_COUNT":
                    count = msg.count
        assert count == len(items), "the garbage connection never got its MISSION_COUNT"
    after = snapshot(gcs)
    assert after[0] == before[0] and same_items(after[1], before[1])
    assert process.proc.poll() is None and "Traceback" not in process.log()
    changed = mission(shift_m=25.0)
    assert gcs.upload(changed) == M.MAV_MISSION_ACCEPTED
    assert same_items(gcs.download()[1:], as_stored(changed, "ardupilot")[1:])


@pytest.mark.timeout(30)
def test_frames_of_unknown_messages_do_not_make_a_peer(vehicle) -> None:
    # pymavlink cannot check the CRC of a message id its dialect does not know and passed
    # such frames on: one edited id byte made noise a peer that was greeted and sent telemetry.
    _, port = vehicle()
    payload = bytes(range(20))
    frame = bytes([0xFD, len(payload), 0, 0, 7, 255, 190, 0x4C, 0x00, 0x78]) + payload + b"\x12\x34"
    parser = M.MAVLink(None)
    (msg,) = parser.parse_buffer(frame)
    assert msg.get_type() == "UNKNOWN_7864396"  # what pymavlink makes of it
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for _ in range(5):
            sock.sendto(frame, ("127.0.0.1", port))
        assert quiet(sock, 1.5)
