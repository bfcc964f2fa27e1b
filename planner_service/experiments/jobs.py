"""One unit of work of an experiment: one sortie of one algorithm in one setting and seed.

A job is a frozen, hashable value (the scenario itself is a frozen dataclass), so that the
runner can share results between experiments that ask for the same sortie (``all`` runs
the paper-preset baseline once for six figures), and so that it pickles to a worker.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import Scenario, SortieEnv
from ..policy import PolicySpec
from ..sortie import run_sortie, seed_streams

TRAINED = ("mcts-paper", "ts-mcts", "mcts", "ql", "dqn")
"""Algorithms with a "training episodes" axis: MCTS iterations per decision, or the
learners' training episodes (the paper puts both on one axis)."""
STATIC = ("greedy", "random")
"""Algorithms without one: drawn as flat lines across the episodes axis."""
ALGOS = TRAINED + STATIC

METRICS = (
    "average_reward",
    "throughput_tasks_per_interval",
    "throughput_bits_per_interval",
    "intervals",
    "total_tasks",
    "energy_used_j",
    "fairness_violations",
    "energy_violation",
    "wall_s",
    "decision_ms_median",
)
"""The numbers of a sortie summary that are aggregated over seeds (``energy_violation``
as a 0/1 rate)."""


@dataclass(frozen=True)
class Setting:
    """One scenario an experiment varies (a speed, a phi, a K...), with its plot label."""

    label: str
    scenario: Scenario


@dataclass(frozen=True)
class Job:
    """One sortie. ``episodes`` is None for algorithms without training (``STATIC``);
    ``record_paths`` also returns every user's position at every interval (trajectory);
    ``repeats`` > 1 flies the (deterministic) sortie that many times and keeps the fastest
    wall time, the usual way to measure time on a machine shared with other work."""

    scenario: Scenario
    algo: str
    episodes: int | None
    seed: int
    record_paths: bool = False
    repeats: int = 1

    def describe(self) -> str:
        n = "" if self.episodes is None else f" n={self.episodes}"
        return f"{self.algo}{n} seed={self.seed} on {self.scenario.name}"

    def cost_estimate_s(self) -> float:
        """Rough single-core seconds (measured on the paper preset), to start the long jobs
        first so that two workers finish together."""
        n = self.episodes or 0
        per_episode = {"dqn": 4e-3, "ql": 5e-4, "mcts-paper": 2.5e-4, "ts-mcts": 2.5e-4, "mcts": 2.5e-4}
        return self.repeats * (1e-3 + per_episode.get(self.algo, 0.0) * n)


Record = dict[str, Any]


def run_job(job: Job) -> Record:
    """Fly ``job``'s sortie and keep the numbers the experiments need (no trace, unless
    ``record_paths``)."""
    spec = PolicySpec(iterations=job.episodes if job.episodes is not None else 1)
    summary = run_sortie(job.scenario, job.algo, job.seed, spec)
    for _ in range(job.repeats - 1):
        again = run_sortie(job.scenario, job.algo, job.seed, spec)
        if again["trace"] != summary["trace"]:  # the minimum of unequal sorties would mean nothing
            raise RuntimeError(f"{job.describe()} is not deterministic: a repeat flew another sortie")
        if again["wall_s"] < summary["wall_s"]:
            summary = again
    record: Record = {m: float(summary[m]) for m in METRICS}
    record.update(algo=job.algo, episodes=job.episodes, seed=job.seed)
    if job.record_paths:
        record["trace"] = summary["trace"]
        record["users_xyz"] = replay_users(job.scenario, job.seed, summary["trace"]).tolist()
    return record


def replay_users(scenario: Scenario, seed: int, trace: list[dict[str, Any]]) -> np.ndarray:
    """Every user's position at the start of each interval and after the last, (T + 1, I, 3).

    The world's draws do not depend on the actions, so replaying the sortie's actions on a
    fresh environment with the same world generator reproduces it exactly; the replay is
    checked against the trace, so a change in that contract fails loudly here instead of
    drawing users where they never were.
    """
    world_rng, _ = seed_streams(seed)
    env = SortieEnv(scenario)
    env.rng = world_rng
    env.reset()
    positions = []
    for record in trace:
        positions.append(env.state.users.copy())  # type: ignore[union-attr]
        _, _, _, _, info = env.step(int(record["hover_point"]))
        if info["user"] != record["user"] or info["tasks"] != record["tasks"]:
            raise RuntimeError(f"replay of seed {seed} diverged at interval {record['interval']}")
    positions.append(env.state.users.copy())  # type: ignore[union-attr]
    return np.stack(positions)


def warm_up() -> None:
    """Run every algorithm once on a tiny budget so that numba's compile (or cache load)
    happens before any timed sortie: ``wall_s`` then measures the search, not the JIT."""
    from ..model import preset

    for name in ("paper", "paper-3d", "field"):
        for algo in ALGOS:
            run_sortie(preset(name), algo, 0, PolicySpec(iterations=2))


__all__ = ["ALGOS", "Job", "METRICS", "Record", "STATIC", "Setting", "TRAINED", "replay_users", "run_job", "warm_up"]
