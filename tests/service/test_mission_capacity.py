"""The service refuses, before any upload, a plan of more items than the autopilot holds
(``mavlink.max_mission_items``, passed to ``protocol.validate_mission``)."""

from __future__ import annotations

import json

import pytest
from stack import Stack

from planner_service.service.config import build_config
from planner_service.service.errors import ConfigError
from protocol import TaskAck


def test_the_capacity_is_checked_at_start() -> None:
    assert build_config({}, {"mavlink.max_mission_items": "3"}).mavlink.max_mission_items == 3
    for bad in ("2", "65536", "-1"):
        with pytest.raises(ConfigError) as err:
            build_config({}, {"mavlink.max_mission_items": bad})
        assert err.value.key == "mavlink.max_mission_items"


@pytest.mark.timeout(60)
def test_a_plan_over_the_capacity_is_not_uploaded(stack: Stack) -> None:
    stack.vehicle()
    stack.service(mavlink__max_mission_items="3")  # ArduPilot: home, takeoff, one point, RTL is 4
    assert stack.client is not None
    ack = stack.client.submit_raw(json.dumps({"kind": "task_request", "user_id": "u-1", "x_m": 120.0, "y_m": 80.0,
                                              "tasks": 6}).encode())
    assert isinstance(ack, TaskAck)
    failed = stack.wait_event(lambda e: e.event == "upload_failed", 30.0, "the refusal of the oversize plan")
    assert failed.detail == "items: 4 items exceed the limit of 3"
    assert stack.rows("SELECT * FROM missions") == []  # refused before the upload: nothing sent
