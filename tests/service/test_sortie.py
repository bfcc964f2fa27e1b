"""A whole sortie, end to end: vehicle stub + service + simulated users as real processes,
real zenoh and real MAVLink on loopback, with each MAVLink backend.

Proves: every accepted request is served or reported not served (or replaced) with a
reason; fairness (3)/(9c) held; the energy reserve held (the vehicle lands above the
threshold and its battery failsafe never fires); every mission the service uploaded is
valid and ends in return to launch, and the stub holds the last of them at the end."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from collections import Counter

import pytest

from planner_service.model import field
from planner_service.service.progress import item_from_dict
from planner_service.service.report import fairness_violations
from protocol import Area, GeoOrigin, validate_mission
from protocol.mission import NAV_RTL

from stack import Stack

os.environ.setdefault("MAVLINK20", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "sim_bridge"))
from gcs import GroundStation  # noqa: E402  (the vehicle tests' small ground station)

SPEEDUP = "40"


@pytest.mark.timeout(120)
@pytest.mark.parametrize("backend, flavour", [("pymavlink", "ardupilot"), ("mavsdk", "px4")])
def test_whole_sortie(stack: Stack, backend: str, flavour: str) -> None:
    scenario = field()
    stack.vehicle("--flavour", flavour, "--speedup", SPEEDUP)
    service = stack.service(mavlink__backend=backend, mavlink__flavour=flavour, mavlink__start_mission="true",
                            planner__min_requests="5")
    users = stack.users("--count", "6", "--speedup", SPEEDUP, "--seed", "3")
    assert stack.client is not None
    probe = stack.client.submit("probe-1", 250.0, 250.0, 12, client_ref="probe")
    assert probe.client_ref == "probe" and probe.request_id >= 1
    stack.wait_event(lambda e: e.event == "landed", 90.0, "landing")
    assert users.stop() == 0 and service.stop() == 0

    statuses = Counter(s for (s,) in stack.rows("SELECT status FROM requests"))
    assert statuses["pending"] == 0, statuses
    for rid, status, reason in stack.rows("SELECT request_id, status, reason FROM requests"):
        assert status in ("served", "replaced", "not_served")
        if status != "served":
            assert reason, f"request {rid} {status} without a reason"
    (probe_status,) = stack.rows(f"SELECT status FROM requests WHERE request_id = {probe.request_id}")[0]
    assert probe_status in ("served", "not_served", "replaced")

    services = stack.rows("SELECT user_id, tasks, battery_j FROM services ORDER BY service_id")
    assert len(services) >= 3, services
    assert fairness_violations(scenario, [(u, t) for u, t, _ in services]) == 0
    assert max(Counter(u for u, _, _ in services).values()) <= scenario.max_services_per_user
    assert all(b >= scenario.energy_floor_j for _, _, b in services)

    # the reserve held: no battery failsafe on the vehicle, landed above the threshold
    vehicle_log = stack.children[0].log()
    assert ": returning" not in vehicle_log, "the vehicle's battery failsafe fired"
    assert not any(e.event == "returning" and "battery at" in e.detail for e in stack.events), "the service's RTL fired"
    landed = [line for line in vehicle_log.splitlines() if "landed at" in line]
    assert landed, vehicle_log[-2000:]
    battery_pct = float(landed[-1].rsplit("battery", 1)[1].strip().rstrip("%"))
    assert battery_pct >= 100 * scenario.battery_threshold

    missions = stack.rows("SELECT items FROM missions WHERE result = 'accepted' ORDER BY mission_id")
    assert len(missions) >= 2
    origin, area = GeoOrigin(), Area(500.0, 120.0, 10.0)
    for (items_json,) in missions:
        items = [item_from_dict(i) for i in json.loads(items_json)]
        validate_mission(items, origin, area, flavour)  # raises if not complete and safe
        assert items[-1].command == NAV_RTL

    gcs = GroundStation(f"udpout:127.0.0.1:{stack.mav_port}")
    try:
        gcs.wait_vehicle()
        held = gcs.download()
    finally:
        gcs.close()
    last = [item_from_dict(i) for i in json.loads(missions[-1][0])]
    assert len(held) == len(last) and held[-1].command == NAV_RTL
    if flavour == "px4":  # ArduPilot replaces item 0 with home
        assert [(i.command, i.x, i.y) for i in held] == [(i.command, i.x, i.y) for i in last]
    else:
        assert [(i.command, i.x, i.y) for i in held[1:]] == [(i.command, i.x, i.y) for i in last[1:]]
