"""Trust only the autopilot, over real MAVLink bytes on loopback UDP: a small autopilot (1/1)
streams an airborne vehicle in AUTO to the link, and a forger on the same network sends
datagrams from system 1, component 2 (a clock at 0, MISSION_ITEM_REACHED, EXTENDED_SYS_STATE
on the ground, a heartbeat in RTL), then one clock-at-0 report with the autopilot's own ids.
None of it may change what the link reports; the autopilot's own reports still count."""

from __future__ import annotations

import asyncio
import os
import socket
import threading
import time
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner_service.service.link import (Current, OnGround, LinkEvent, LinkSettings, ModeChanged, Reached,  # noqa: E402
                                          Restarted, open_link)
from planner_service.harness.processes import free_port  # noqa: E402

M = mavutil.mavlink


class Autopilot:
    """An ArduCopter-like sender: airborne in AUTO, flying item 3, its clock running."""

    def __init__(self, port: int, component: int = 1) -> None:
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1,
                                               source_component=component)
        self.boot_ms = 60_000
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def send(self, msg: Any) -> None:
        self.conn.mav.send(msg)

    def _run(self) -> None:
        while not self.stop.is_set():
            self.boot_ms += 100
            base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | M.MAV_MODE_FLAG_SAFETY_ARMED
            self.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, 3, 4, 3))
            self.send(M.MAVLink_global_position_int_message(self.boot_ms, 473977420, 85455940, 518000, 30000, 0, 0,
                                                            0, 0))
            self.send(M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_IN_AIR))
            self.send(M.MAVLink_mission_current_message(3, 5))
            while (msg := self.conn.recv_match(blocking=False)) is not None:
                if msg.get_type() == "COMMAND_LONG" and self.conn.mav.srcComponent == 1:  # as autopilots do
                    self.send(M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_ACCEPTED, 0, 0,
                                                            msg.get_srcSystem(), msg.get_srcComponent()))
            time.sleep(0.1)


@pytest.mark.timeout(60)
@pytest.mark.parametrize("backend", ["pymavlink", "mavsdk"])
def test_forged_datagrams_from_another_component_change_nothing(backend: str) -> None:
    port = free_port(socket.SOCK_DGRAM)

    async def run() -> tuple[list[LinkEvent], Any, int]:
        events: list[LinkEvent] = []
        link = open_link(backend, LinkSettings(f"udpin:127.0.0.1:{port}", "ardupilot", link_timeout_s=2.0),
                         events.append)
        autopilot = Autopilot(port)
        autopilot.thread.start()
        try:
            await link.connect(10.0)
            deadline = time.monotonic() + 10.0
            while not (link.telemetry.airborne and link.telemetry.mission_seq == 3):
                assert time.monotonic() < deadline, link.telemetry
                await asyncio.sleep(0.05)
            before = link.telemetry
            seen = len(events)
            forger = Autopilot(port, component=2)
            for msg in (M.MAVLink_global_position_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0),
                        M.MAVLink_global_position_int_message(100, 0, 0, 0, 0, 0, 0, 0, 0),
                        M.MAVLink_mission_item_reached_message(3),
                        M.MAVLink_mission_current_message(4, 5),
                        M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_ON_GROUND),
                        M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                    M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 6, 3, 3)):
                forger.send(msg)
                await asyncio.sleep(0.05)
            # One report with the autopilot's own ids and a clock at 0: not believed alone.
            autopilot.send(M.MAVLink_global_position_int_message(0, 0, 0, 0, 0, 0, 0, 0, 0))
            await asyncio.sleep(1.0)
            after = link.telemetry
            forged = events[seen:]
            # Control: the autopilot's own report of a completed item counts.
            autopilot.send(M.MAVLink_mission_item_reached_message(3))
            await asyncio.sleep(0.5)
            counted = [e for e in events[seen:] if isinstance(e, Reached)]
            assert counted == [Reached(3, link.generation)], events[seen:]
            untrusted = link.state.untrusted
            return forged, (before, after), untrusted
        finally:
            autopilot.stop.set()
            await link.close()

    forged, (before, after), untrusted = asyncio.run(run())
    assert [e for e in forged if isinstance(e, (Restarted, Reached, OnGround, ModeChanged, Current))] == []
    assert after.airborne and after.mode == "AUTO" and after.mission_seq == 3 and after.armed
    assert (after.lat_deg, after.lon_deg) == (before.lat_deg, before.lon_deg) != (0.0, 0.0)
    assert after.position_boot_s is not None and before.position_boot_s is not None
    assert after.position_boot_s >= before.position_boot_s  # the clock never went back
    assert untrusted >= 6
