"""Issue 34, finding 8 (unsigned MAVLink): one forged datagram from the autopilot's own ids
(system 1, component 1), sent by a rogue host on the network to the service's MAVLink
socket mid-sortie, changes nothing (docs/OPERATIONS.md section 6). A real service flies the
vehicle stub through a relay (``tests/support/udp_tap.py``) that shows the rogue where the
service listens.

- One GLOBAL_POSITION_INT with ``time_boot_ms`` far ahead: before, it became the clock, the
  vehicle's own reports after it looked like a clock gone back, and 0.5 s later a restart
  was believed (authority revoked, the hold cut, the battery unknown).
- One MISSION_CURRENT naming the mission's last item: before, every planned point before it
  was marked skipped and the hold flown was ended.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest

from tests.support.stack import Stack
from tests.support.udp_tap import M, UdpTap

SPEEDUP = "40"
SERVICE = {"mavlink__start_mission": "true", "planner__min_requests": "5"}
BELIEVED_WITHIN_S = 2.0
"""Wall seconds in which the service would have acted on the forged datagram: before the fix
a restart was believed 0.5 s after it, a skip at the next tick (1 s)."""


@pytest.fixture
def flying(stack: Stack) -> Iterator[UdpTap]:
    """A sortie under way (a first user served, the authority the service's), the service
    reaching the vehicle through the tap."""
    stack.vehicle("--speedup", SPEEDUP)
    tap = UdpTap(stack.mav_port)
    try:
        stack.service(mavlink__url=f"udpout:127.0.0.1:{tap.port}", **SERVICE)
        stack.users("--count", "6", "--speedup", SPEEDUP, "--seed", "3")
        stack.wait_event(lambda e: e.event == "user_served", 60.0, "a first service")
        yield tap
    finally:
        tap.close()


def since(stack: Stack, t: float, *kinds: str) -> list[str]:
    return [f"{e.event}: {e.detail}" for e in list(stack.events) if e.time_s >= t and e.event in kinds]


def go_on(stack: Stack, after: float) -> None:
    """The sortie goes on: another user served after ``after`` (or the landing)."""
    stack.wait_event(lambda e: e.event in ("user_served", "landed") and e.time_s > after, 60.0,
                     "the sortie going on")


@pytest.mark.timeout(120)
def test_one_report_with_a_clock_far_ahead_is_no_restart(stack: Stack, flying: UdpTap) -> None:
    assert stack.client is not None
    before = stack.client.state().status
    assert before.authority == "operator" and before.battery_source == "autopilot", before
    position = flying.latest["GLOBAL_POSITION_INT"]
    forged_at = time.time()
    flying.forge(M.MAVLink_global_position_int_message(4_000_000_000, position.lat, position.lon, position.alt,
                                                       position.relative_alt, 0, 0, 0, 0))
    time.sleep(BELIEVED_WITHIN_S)  # absence: what the service did with it shows within this
    status = stack.client.state().status
    assert since(stack, forged_at, "vehicle_restarted", "authority_revoked", "waypoint_skipped") == []
    assert status.authority == "operator" and status.battery_source == "autopilot", status
    assert status.battery_fraction is not None
    go_on(stack, forged_at)
    assert since(stack, forged_at, "vehicle_restarted", "authority_revoked") == []


@pytest.mark.timeout(120)
def test_one_mission_current_skips_no_planned_user(stack: Stack, flying: UdpTap) -> None:
    assert stack.client is not None
    current = flying.latest["MISSION_CURRENT"]
    last = max(int(current.total), int(current.seq) + 2)  # the mission's last item (ArduPilot: home not counted)
    forged_at = time.time()
    flying.forge(M.MAVLink_mission_current_message(last, int(current.total)))
    time.sleep(BELIEVED_WITHIN_S)
    assert since(stack, forged_at, "waypoint_skipped", "authority_revoked") == []
    go_on(stack, forged_at)
    assert since(stack, forged_at, "waypoint_skipped") == []
    assert stack.client.state().status.authority == "operator"
