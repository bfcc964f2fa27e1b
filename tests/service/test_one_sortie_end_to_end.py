"""A whole sortie, end to end: vehicle stub + service + simulated users as real processes,
real zenoh and real MAVLink on loopback, with each MAVLink backend.

Proves (``sortie_checks.check_sortie``): every accepted request is served or reported not
served (or replaced) with a reason; fairness (3)/(9c) held; the energy reserve held (the
vehicle lands above the threshold and its battery failsafe never fires); every mission the
service uploaded is valid and ends in return to launch, the vehicle committed exactly
those, and holds the last of them at the end."""

from __future__ import annotations

import pytest

from planner_service.model import field
from tests.support.sortie_checks import check_sortie
from tests.support.stack import Stack

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
    stack.wait_disarmed(10.0)
    assert any(e.event == "plan_updated" for e in stack.events), "no plan announced"
    # the autopilot's disarming at the service's own landing is explained: no authority ended
    assert not [e.detail for e in stack.events if e.event == "authority_revoked"]
    assert users.stop() == 0 and service.stop() == 0

    (probe_status,) = stack.rows(f"SELECT status FROM requests WHERE request_id = {probe.request_id}")[0]
    assert probe_status in ("served", "not_served", "replaced")
    check_sortie(stack, scenario, flavour, [stack.children[0].log()])
