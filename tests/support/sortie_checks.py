"""The checks of a whole sortie flown end to end (tests/service/test_one_sortie_end_to_end.py,
test_faults.py): every request accounted for, fairness, the energy reserve, the missions,
and the journal against the vehicle stub's own log.

The vehicle logs every mission it commits with its digest (``protocol.mission_digest``) and
writes its own flight to a track file; from those and the journal the missions it really
held and the holds it really flew are known, whatever the service saw of them."""

from __future__ import annotations

import json
import re
from collections import Counter
from dataclasses import dataclass

from planner_service.model import Scenario
from planner_service.model.fairness import fairness_violations
from planner_service.service.sortie import item_from_dict
from protocol import Area, GeoOrigin, mission_digest, validate_mission
from protocol.mission import NAV_RTL
from tests.support.gcs import GroundStation
from tests.support.stack import Stack
from tests.support.truth import false_services, recorded_services, stub_track

HOLD_RADIUS_M = 5.0
"""The service's ``safety.hold_radius_m`` (its default)."""
TOLERANCE_S = 1.0 + 4.0
"""A hold is judged from position reports: one second (ArduPilot's whole seconds) and one
reporting gap (the stub streams at about 10 Hz of wall time: 4 s apart at x40, the fastest
these sorties fly)."""

COMMIT = re.compile(r"mission of \d+ items accepted \(digest ([0-9a-f]{8})\)")


@dataclass
class Sortie:
    """What the vehicle did, read from its logs and the journal."""

    commits: list[str]
    """Digests of the missions the vehicle committed, in order."""
    accepted: list[str]
    """Digests of the journal's missions accepted by their upload's ACK, in order."""
    read_back: list[str]
    """Digests of those accepted on reading the vehicle's mission back after their upload
    failed or went silent: ArduPilot writes items as they arrive, so it may hold one it
    never committed (an upload that failed for want of the last item, an RTL it already
    had there), or one whose ACK was lost."""
    services: list[tuple[str, int, float]]
    """(user, tasks, battery_j) of every service in the journal, in order."""


def read_sortie(stack: Stack, vehicle_logs: list[str], flavour: str) -> Sortie:
    accepted: list[str] = []
    read_back: list[str] = []
    doubted = set()
    for plan_id, items_json, result in stack.rows("SELECT plan_id, items, result FROM missions ORDER BY mission_id"):
        if result != "accepted":
            doubted.add(plan_id)
            continue
        digest = mission_digest([item_from_dict(i) for i in json.loads(items_json)], flavour)  # type: ignore[arg-type]
        (read_back if plan_id in doubted else accepted).append(digest)
    commits = [m.group(1) for m in COMMIT.finditer("\n".join(vehicle_logs))]
    services = [(u, t, b) for u, t, b in stack.rows("SELECT user_id, tasks, battery_j FROM services ORDER BY service_id")]
    return Sortie(commits, accepted, read_back, services)


def check_sortie(stack: Stack, scenario: Scenario, flavour: str, vehicle_logs: list[str],
                 unjournaled_commits: int = 0) -> Sortie:
    """Every check of a clean sortie, and the journal against what the vehicle did:
    - every request closed (served, replaced, not_served with a reason);
    - fairness (3)/(9c) held in the journal, and no user served beyond the limit;
    - every service recorded is borne out by the vehicle's own flight log (``--track``): it
      stayed within the hold radius of the point for the hold the tasks recorded need
      (``tests/support/truth.py``);
    - the energy reserve held (no failsafe on the vehicle nor the service, landed above
      the threshold);
    - every upload in the journal accepted or failed with its result; the vehicle
      committed exactly the ones its ACK accepted (``unjournaled_commits`` more at most: a
      service killed between the vehicle's ACK and its journal write; a mission accepted on
      reading it back after a failed or silent upload may or may not be among its commits),
      each valid and ending in return to launch; the vehicle holds the last at the end."""
    statuses = Counter(s for (s,) in stack.rows("SELECT status FROM requests"))
    assert statuses["pending"] == 0, statuses
    for rid, status, reason in stack.rows("SELECT request_id, status, reason FROM requests"):
        assert status in ("served", "replaced", "not_served")
        if status != "served":
            assert reason, f"request {rid} {status} without a reason"

    sortie = read_sortie(stack, vehicle_logs, flavour)
    services = sortie.services
    assert len(services) >= 3, services
    # Truth: every service recorded is borne out by the vehicle's own flight log.
    false = false_services(recorded_services(stack.journal_path), stub_track(stack.track), scenario,
                           HOLD_RADIUS_M, TOLERANCE_S)
    assert not false, "services the vehicle did not fly as recorded:\n" + "\n".join(false)
    # (3) on the backlog each hold was bound to: a hold cut short carries fewer tasks
    bound = stack.rows("SELECT user_id, COALESCE(bound_tasks, tasks) FROM services ORDER BY service_id")
    assert fairness_violations(scenario, bound) == 0, (bound, services)
    assert max(Counter(u for u, _, _ in services).values()) <= scenario.max_services_per_user
    assert all(b >= scenario.energy_floor_j for _, _, b in services)

    joined = "\n".join(vehicle_logs)
    assert ": returning" not in joined, "the vehicle's battery failsafe fired"
    assert not any(e.event == "returning" and "battery at" in e.detail for e in stack.events), "the service's RTL fired"
    landed = [line for line in joined.splitlines() if "landed at" in line]
    assert landed, joined[-2000:]
    battery_pct = float(landed[-1].rsplit("battery", 1)[1].strip().rstrip("%"))
    assert battery_pct >= 100 * scenario.battery_threshold

    for plan_id, result in stack.rows("SELECT plan_id, result FROM missions ORDER BY mission_id"):
        assert result == "accepted" or (result.split(": ", 1)[0] in ("failed", "unknown") and result.split(": ", 1)[1]), \
            f"plan {plan_id}: {result!r}"
    # The read-back's missions are the vehicle's own word, committed or written item by item:
    # the ACK-accepted ones must match the commits exactly, apart from those.
    commits = [c for c in sortie.commits if c not in sortie.read_back]
    if unjournaled_commits:
        extra = Counter(commits) - Counter(sortie.accepted)
        assert sum(extra.values()) <= unjournaled_commits, (sortie.commits, sortie.accepted)
        assert not Counter(sortie.accepted) - Counter(commits), (sortie.commits, sortie.accepted)
    else:
        assert commits == sortie.accepted, (sortie.commits, sortie.accepted, sortie.read_back)

    missions = stack.rows("SELECT items FROM missions WHERE result = 'accepted' ORDER BY mission_id")
    assert len(missions) >= 2
    origin, area = GeoOrigin(), Area(500.0, 120.0, 10.0)
    for (items_json,) in missions:
        items = [item_from_dict(i) for i in json.loads(items_json)]
        validate_mission(items, origin, area, flavour)  # type: ignore[arg-type]  # raises if not complete and safe
        assert items[-1].command == NAV_RTL

    gcs = GroundStation(f"udpout:127.0.0.1:{stack.mav_port}")
    try:
        gcs.wait_vehicle()
        held = gcs.download()
    finally:
        gcs.close()
    last = [item_from_dict(i) for i in json.loads(missions[-1][0])]
    assert len(held) == len(last) and held[-1].command == NAV_RTL
    assert mission_digest(held, flavour) == mission_digest(last, flavour)  # type: ignore[arg-type]
    return sortie
