"""The benchmark behind ``python -m planner_service bench``."""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
from dataclasses import replace
from typing import Any

import numpy as np

from ..mcts import MctsConfig, MctsPlanner
from ..model import HAVE_NUMBA, Scenario, paper
from .decisions import Timing, decision_states, time_decisions

SIZES = ((20, 10), (40, 100), (200, 1000), (400, 5000))
"""(K hovering points, I users): the paper's scenario, then larger ones to show growth, up to
a fleet-sized one (a town's users)."""
DECISIONS = {(20, 10): 50, (40, 100): 50, (200, 1000): 20, (400, 5000): 10}
"""Decisions timed at each size unless ``decisions`` is given (the large ones take seconds
each to set up: the greedy sorties that give their states)."""


def scenario_of(k: int, i: int) -> Scenario:
    """The paper preset with K hovering points and I users (original layout extended)."""
    return paper().replace(num_hover_points=k, num_users=i)


def fast_timing(scenario: Scenario, hover_points, states, config: MctsConfig, seeds: list[int]) -> Timing:
    def decide(i, state):
        return MctsPlanner(scenario, hover_points, config, np.random.default_rng(seeds[i])).plan(state)

    decide(0, states[0])  # compile (cached on disk) and warm up outside the timing
    return time_decisions(states, decide)


def reference_timing(scenario: Scenario, hover_points, states, config: MctsConfig, seeds: list[int]) -> Timing:
    """The plain reference in a child process with a pure-Python model."""
    env = dict(os.environ, UAV_PLANNER_NO_NUMBA="1")
    payload = pickle.dumps((scenario, hover_points, states, config, seeds))
    out = subprocess.run(
        [sys.executable, "-m", "planner_service.bench.reference_worker"],
        input=payload, capture_output=True, env=env, check=True, timeout=3600,
    )
    data = json.loads(out.stdout)
    return Timing(data["seconds"], data["actions"], data["iterations"])


def run_bench(decisions: int | None, iterations: int, reference_decisions: int, sizes=SIZES,
              progress=None) -> dict[str, Any]:
    """Latency of ``mcts`` decisions at each size (``decisions`` each, or ``DECISIONS``),
    and the reference at the paper's size."""
    config = replace(MctsConfig(), iterations=iterations)
    results: dict[str, Any] = {
        "numba": HAVE_NUMBA,
        "iterations": iterations,
        "config": {k: v for k, v in vars(config).items()},
        "sizes": [],
    }
    for k, i in sizes:
        scenario = scenario_of(k, i)
        count = decisions or DECISIONS.get((k, i), 20)
        hover_points, states = decision_states(scenario, count)
        seeds = list(range(1000, 1000 + count))
        if progress:
            progress(f"K={k} I={i}: {count} decisions")
        fast = fast_timing(scenario, hover_points, states, config, seeds)
        row: dict[str, Any] = {
            "K": k, "I": i, "decisions": count, "median_ms": fast.median_ms, "p99_ms": fast.p99_ms,
            "playouts_per_s": fast.playouts_per_s, "decisions_digest": fast.digest,
        }
        if (k, i) == SIZES[0] and reference_decisions > 0:
            n = min(reference_decisions, count)
            if progress:
                progress(f"K={k} I={i}: reference on {n} decisions (pure Python)")
            ref = reference_timing(scenario, hover_points, states[:n], config, seeds[:n])
            same = sum(a == b for a, b in zip(ref.actions, fast.actions[:n]))
            fast_same = float(np.median(fast.seconds[:n]) * 1e3)
            row["reference"] = {
                "decisions": n, "median_ms": ref.median_ms, "p99_ms": ref.p99_ms,
                "playouts_per_s": ref.playouts_per_s, "same_decisions": same,
                "speedup_median": ref.median_ms / fast_same,
            }
        results["sizes"].append(row)
    return results


def format_table(results: dict[str, Any]) -> str:
    lines = [
        f"mcts decision latency, {results['iterations']} iterations per decision (numba: {results['numba']})",
        f"{'K':>5} {'I':>6} {'decisions':>9} {'median ms':>10} {'p99 ms':>9} {'playouts/s':>11}  decisions' digest",
    ]
    for row in results["sizes"]:
        lines.append(f"{row['K']:>5} {row['I']:>6} {row['decisions']:>9} {row['median_ms']:>10.2f} "
                     f"{row['p99_ms']:>9.2f} {row['playouts_per_s']:>11.0f}  {row['decisions_digest']}")
        ref = row.get("reference")
        if ref:
            lines.append(f"{'reference':>12} {ref['decisions']:>9} {ref['median_ms']:>10.2f} {ref['p99_ms']:>9.2f} "
                         f"{ref['playouts_per_s']:>11.0f}   speed-up x{ref['speedup_median']:.1f} (median ratio, "
                         f"same run), same decisions {ref['same_decisions']}/{ref['decisions']}")
    return "\n".join(lines)
