"""One fleet sortie of the fleet experiment as a frozen, hashable, picklable value, and the
numbers kept from it (no trace, unless its paths are asked for)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...fleet import MessageLink, run_fleet_sortie
from ...model import Scenario
from ...model.interval import NO_USER
from ...model.fleet import Fleet
from ...policy import PolicySpec

FLEET_METRICS = (
    "throughput_tasks_per_interval",
    "total_tasks",
    "average_reward",
    "energy_used_j",
    "fairness_violations",
    "jain_index",
    "users_served",
    "double_services",
    "double_holds",
    "blocked_choices",
)
"""The fleet's numbers aggregated over seeds (``model.fleet`` figures, and ``jain_index``)."""

Record = dict[str, Any]


@dataclass(frozen=True)
class FleetJob:
    """One fleet sortie: ``uavs`` UAVs planned by fleet planner ``algo`` (each UAV ``mcts``
    at ``iterations`` a decision) on ``scenario`` with ``seed``; ``loss`` and
    ``late_intervals`` the message link (None: the planner's own default, no link given);
    ``record_paths`` also keeps each UAV's path for the figure."""

    scenario: Scenario
    uavs: int
    algo: str
    iterations: int
    seed: int
    link: tuple[float, int] | None = None
    record_paths: bool = False

    def describe(self) -> str:
        link = "" if self.link is None else f" loss={self.link[0]:g} late={self.link[1]}"
        return f"{self.algo} N={self.uavs}{link} seed={self.seed} on {self.scenario.name}"

    def cost_estimate_s(self) -> float:
        """Rough single-core seconds: a fleet's sortie has about N times one UAV's decisions."""
        return self.uavs * (0.2 + 4e-4 * self.iterations)


def jain_index(served_tasks: np.ndarray) -> float:
    """Jain's fairness index (sum x)^2 / (n sum x^2) over every user's tasks served: 1 when
    all users got the same, 1/n when one got everything (how the multi-UAV offloading
    literature reports fairness; the paper's rule (3) is counted apart, as violations)."""
    x = np.asarray(served_tasks, dtype=np.float64)
    total = float(np.sum(x * x))
    return float(np.sum(x) ** 2 / (x.size * total)) if total > 0 else 0.0


def run_fleet_job(job: FleetJob) -> Record:
    """Fly ``job``'s sortie and keep the experiment's numbers."""
    link = None if job.link is None else MessageLink(job.link[0], job.link[1])
    summary = run_fleet_sortie(job.scenario, Fleet(uavs=job.uavs), job.algo, job.seed,
                               PolicySpec(iterations=job.iterations), link=link)
    fleet = summary["fleet"]
    served = np.zeros(job.scenario.num_users)
    for event in summary["events"]:
        if event["user"] != NO_USER:
            served[event["user"]] += event["tasks"]
    record: Record = {m: float(fleet[m]) for m in FLEET_METRICS if m in fleet}
    record["jain_index"] = jain_index(served)
    record.update(
        algo=job.algo, uavs=job.uavs, seed=job.seed, link=job.link,
        per_uav_throughput=[float(s["throughput_tasks_per_interval"]) for s in summary["per_uav"]],
        per_uav_energy_j=[float(s["energy_used_j"]) for s in summary["per_uav"]],
        message_bytes_max=summary["messages"]["bytes_max"], messages_sent=summary["messages"]["sent"],
        wall_s=float(summary["wall_s"]),
    )
    if job.record_paths:
        record["paths"] = [[[float(c) for c in t["uav_xyz"]] for t in s["trace"]] for s in summary["per_uav"]]
        record["served_xyz"] = [[t["user_xyz"] for t in s["trace"] if t["user"] != NO_USER] for s in summary["per_uav"]]
    return record


__all__ = ["FLEET_METRICS", "FleetJob", "Record", "jain_index", "run_fleet_job"]
