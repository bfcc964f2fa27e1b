"""A MISSION_CURRENT that names no item (seq UINT16_MAX) is read as "not said", never as
item 65535: PX4 sends one after an upload marking no item current, before its navigator
keeps the index (``link.progress``; a CI run of PX4 SITL caught it). The service marks an item
current in every upload of its own; another station's need not. The stub's PX4 flavour always
sends that report, so both backends meet it here over real MAVLink on loopback."""

from __future__ import annotations

import asyncio
import socket
from dataclasses import replace
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from planner_service.harness.processes import Child, free_port
from planner_service.service.link import Current, LinkSettings, open_link
from planner_service.service.link.progress import NO_ITEM, mission_progress
from protocol import GeoOrigin, HoverPoint, encode_path, replacement_items
from tests.service.test_link_sitl import Recorder, until
from tests.support.gcs import GroundStation

ORIGIN = GeoOrigin()
BACKENDS = ["pymavlink", "mavsdk"]


def test_uint16_max_names_no_item_and_the_totals_keep_their_meaning() -> None:
    assert mission_progress(M.MAVLink_mission_current_message(NO_ITEM, 5)) == (-1, 5)
    assert mission_progress(M.MAVLink_mission_current_message(2, 5)) == (2, 5)
    assert mission_progress(M.MAVLink_mission_current_message(0, 0)) == (0, -1)  # total not said
    assert mission_progress(M.MAVLink_mission_current_message(0, 0xFFFF)) == (0, 0)  # no mission


@pytest.mark.timeout(120)
@pytest.mark.parametrize("backend", BACKENDS)
def test_another_stations_upload_marking_no_item_is_never_read_as_item_65535(backend: str, tmp_path: Path) -> None:
    """The link flies [takeoff, a, b, c, RTL]; on the way to b (item 2) a second station
    uploads [takeoff, a, d, RTL] marking no item current (the service always marks one, and
    MAVSDK refuses to send a mission without one): PX4 keeps the index, 2."""
    port = free_port(socket.SOCK_DGRAM)
    stub = Child("sim_bridge", ["vehicle", "--flavour", "px4", "--mavlink", f"udpin:127.0.0.1:{port}",
                                "--speedup", "10"], tmp_path / "vehicle.log")
    a, b, c = HoverPoint(0.0, 20.0, 10.0), HoverPoint(0.0, 450.0, 10.0), HoverPoint(0.0, 480.0, 10.0)
    d = HoverPoint(40.0, 450.0, 10.0)
    first = encode_path([a, b, c], ORIGIN, "px4")
    second = [replace(item, current=0) for item in replacement_items(first, 1, [d], ORIGIN, "px4")[0]]

    def named(events: Recorder) -> list[int]:
        return [ev.seq for ev in events.of(Current)]

    async def run() -> Recorder:
        events = Recorder()
        link = open_link(backend, LinkSettings(f"udpout:127.0.0.1:{port}", "px4", item_timeout_s=0.5, retries=10,
                                               link_timeout_s=2.0), events)
        other = GroundStation(f"udpout:127.0.0.1:{port}", timeout_s=0.5, retries=10)
        try:
            await link.connect(30.0)
            await until("a position", lambda: link.telemetry.position_ok, 60.0, link)
            await link.upload(first)
            await link.start()
            await until("flying to b (item 2)", lambda: link.telemetry.mission_seq == 2, 60.0, link)
            await asyncio.to_thread(other.wait_vehicle)
            assert await asyncio.to_thread(other.upload, second) == M.MAV_MISSION_ACCEPTED
            await until("no item named, then item 2 again (or an item past the mission's end)", lambda: (
                -1 in named(events) and 2 in named(events)[named(events).index(-1):])
                or any(seq >= len(first) for seq in named(events)), 30.0, link)
            return events
        finally:
            other.close()
            await link.close()

    try:
        events = asyncio.run(run())
    finally:
        stub.stop()
    assert all(-1 <= seq < len(first) for seq in named(events)), f"items named: {named(events)}"
