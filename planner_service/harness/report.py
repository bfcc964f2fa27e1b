"""A finished (or running) sortie's figures, read from the journal: the same spirit as the
``plan --json`` summary (throughput, reward, energy, served users, violations), plus what
happened to every request."""

from __future__ import annotations

from collections import Counter
from typing import Any

from ..model import Scenario
from ..model.fairness import fairness_violations
from ..service.journal import Journal


def planned_requests(services: list[Any], missions: list[Any]) -> int:
    """Services whose request is the one the plan was made for: the request id of the user's
    point in the last mission accepted before the service (a newer request of the user, sent
    since, was bound instead when the vehicle arrived)."""
    accepted = sorted((m for m in missions if m.result == "accepted"), key=lambda m: m.time_s)
    n = 0
    for s in services:
        before = [m for m in accepted if m.time_s <= s.time_s]
        for m in reversed(before):
            planned = next((p["request_id"] for p in m.points if p["user_id"] == s.user_id), None)
            if planned is not None:
                n += planned == s.request_id
                break
    return n


def sortie_summary(journal: Journal, scenario: Scenario, final_battery_j: float | None,
                   sortie: int | None = None) -> dict[str, Any]:
    """The figures of one sortie (None: the journal's current one)."""
    number = journal.sortie if sortie is None else sortie
    row = journal.sortie_row(number)
    services = journal.services(number)
    requests = journal.requests(number)
    n = len(services)
    tasks = [s.tasks for s in services]
    statuses = Counter(r.status for r in requests)
    reasons = Counter(r.reason for r in requests if r.status == "not_served")
    missions = journal.missions(number)
    floor = scenario.energy_floor_j
    return {
        "sortie": number,
        "intervals": n,
        "throughput_tasks_per_interval": sum(tasks) / n if n else 0.0,
        "throughput_bits_per_interval": sum(s.bits for s in services) / n if n else 0.0,
        "total_tasks": int(sum(tasks)),
        "average_reward": sum(s.reward for s in services) / n if n else 0.0,
        "energy_used_j": None if final_battery_j is None else float(scenario.battery_j - final_battery_j),
        "energy_budget_j": float((1.0 - scenario.battery_threshold) * scenario.battery_j),
        "final_battery_j": final_battery_j,
        "served": [s.user_id for s in services],
        "served_users": len({s.user_id for s in services}),
        "hover_points": [s.hover_index for s in services],
        "fairness_violations": fairness_violations(scenario, [(s.user_id, s.bound) for s in services]),
        "energy_violation": None if final_battery_j is None else bool(final_battery_j < floor),
        "requests": {"accepted": len(requests), **{k: statuses.get(k, 0) for k in ("served", "replaced", "not_served", "pending")}},
        "not_served_reasons": dict(reasons),
        "missions_uploaded": sum(1 for m in missions if m.result == "accepted"),
        "services_of_the_planned_request": planned_requests(services, missions),
        "upload_failures": sum(1 for m in missions if m.result != "accepted"),
        "sortie_over": row.why if row is not None and row.over else None,
    }
