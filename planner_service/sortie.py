"""One simulated sortie of a planner on the model, and its JSON summary (the ``plan --json``
contract of docs/DESIGN.md)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .model import Scenario, SortieEnv
from .model.fairness import fairness_violations
from .policy import Policy, PolicySpec
from .registry import make_policy


def seed_streams(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """Independent generators for the world and the planner, both fixed by ``seed``."""
    world, planner = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(world), np.random.default_rng(planner)


def run_sortie(
    scenario: Scenario,
    algo: str,
    seed: int,
    spec: PolicySpec | None = None,
    options: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Fly one sortie with planner ``algo`` and return the summary of docs/DESIGN.md."""
    spec = spec or PolicySpec()
    world_rng, planner_rng = seed_streams(seed)
    env = SortieEnv(scenario)
    env.rng = world_rng
    env.reset(options=options)
    policy = make_policy(algo, spec, planner_rng)
    start = time.perf_counter()
    trace, decision_s = fly(env, policy)
    wall = time.perf_counter() - start
    summary = summarize(scenario, trace)
    summary.update(
        algo=algo,
        preset=scenario.name,
        seed=seed,
        iterations=spec.iterations,
        budget_ms=spec.budget_ms,
        wall_s=wall,
        decision_ms_median=float(np.median(decision_s) * 1e3) if decision_s else 0.0,
    )
    return summary


def fly(env: SortieEnv, policy: Policy) -> tuple[list[dict[str, Any]], list[float]]:
    """Let ``policy`` fly ``env`` (already reset) to the end; the per-interval trace and
    each decision's wall time."""
    policy.begin(env)
    trace: list[dict[str, Any]] = []
    decision_s: list[float] = []
    while not env.done:
        t0 = time.perf_counter()
        decision = policy.decide(env)
        decision_s.append(time.perf_counter() - t0)
        _, _, _, _, info = env.step(decision.action)
        info.pop("action_mask", None)
        trace.append(info)
    return trace, decision_s


def summarize(scenario: Scenario, trace: list[dict[str, Any]]) -> dict[str, Any]:
    """Throughput, reward, energy and constraint checks of a finished sortie's trace."""
    n = len(trace)
    tasks = [r["tasks"] for r in trace]
    energy = sum(r["e_hover_j"] + r["e_comp_j"] + r["e_flight_j"] for r in trace)
    budget = (1.0 - scenario.battery_threshold) * scenario.battery_j
    return {
        "intervals": n,
        "throughput_tasks_per_interval": float(np.mean(tasks)) if n else 0.0,
        "throughput_bits_per_interval": float(np.mean([r["bits"] for r in trace])) if n else 0.0,
        "total_tasks": int(sum(tasks)),
        "average_reward": float(np.mean([r["reward"] for r in trace])) if n else 0.0,
        "energy_used_j": float(energy),
        "energy_budget_j": float(budget),
        "served": [r["user"] for r in trace],
        "hover_points": [r["hover_point"] for r in trace],
        "fairness_violations": fairness_violations(scenario, [(r["user"], r["tasks"]) for r in trace]),
        "energy_violation": bool(energy > budget + 1e-6),
        "scenario": scenario.as_dict(),
        "trace": trace,
    }
