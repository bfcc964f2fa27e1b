"""The service never sends a plan of more items than the autopilot holds
(``mavlink.max_mission_items``): the planner's path is cut to fit (a prefix is safe: every
step kept the energy for the way home), and ``protocol.validate_mission`` refuses anything
larger before an upload (tests/protocol/test_unsafe_missions.py)."""

from __future__ import annotations

import time

import pytest

from planner_service.service.config import build_config
from planner_service.service.errors import ConfigError
from protocol import Area, GeoOrigin, HoverPoint, encode_path, validate_mission
from protocol.mission import max_points
from tests.support.stack import Stack


def test_the_capacity_is_checked_at_start() -> None:
    assert build_config({}, {"mavlink.max_mission_items": "3"}).mavlink.max_mission_items == 3
    for bad in ("2", "65536", "-1"):
        with pytest.raises(ConfigError) as err:
            build_config({}, {"mavlink.max_mission_items": bad})
        assert err.value.key == "mavlink.max_mission_items"


def test_the_planner_keeps_room_for_the_items_around_the_points() -> None:
    assert max_points(5, "ardupilot") == 2 and max_points(5, "px4") == 3  # home, takeoff, RTL; takeoff, RTL
    for flavour in ("ardupilot", "px4"):
        points = [HoverPoint(50.0 + 10 * i, 60.0, 40.0, 5.0) for i in range(max_points(7, flavour))]
        items = encode_path(points, GeoOrigin(), flavour)  # type: ignore[arg-type]
        assert len(items) == 7
        validate_mission(items, GeoOrigin(), Area(500.0, 120.0, 10.0), flavour, max_items=7)  # type: ignore[arg-type]


@pytest.mark.timeout(60)
def test_the_service_plans_within_the_capacity(stack: Stack) -> None:
    """With room for no point at all (ArduPilot: home, takeoff, RTL) the planner's paths
    are empty: nothing is uploaded and nothing fails (a plan of one point used to be
    refused by validate_mission, once a second, for ever)."""
    stack.vehicle()
    service = stack.service(mavlink__max_mission_items="3")
    assert stack.client is not None
    for n in range(6):
        stack.client.submit(f"u-{n}", 100.0 + 150.0 * (n % 3), 120.0 + 200.0 * (n // 3), 12)
    time.sleep(3.0)  # a plan a second is tried while requests are pending
    assert not any(e.event in ("upload_failed", "mission_uploaded") for e in stack.events), stack.events
    assert stack.rows("SELECT * FROM missions") == [] and "exceed" not in service.log()
