"""How good the planners are on the paper preset (the issue's quality criteria)."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.model import preset
from planner_service.policy import PolicySpec
from planner_service.sortie import run_sortie


def rewards(preset_name: str, algo: str, seeds: range) -> np.ndarray:
    runs = [run_sortie(preset(preset_name), algo, s, PolicySpec(1000)) for s in seeds]
    assert all(r["fairness_violations"] == 0 and not r["energy_violation"] for r in runs), algo
    return np.array([r["average_reward"] for r in runs])


def test_mcts_beats_the_paper_algorithm_over_30_seeds():
    sound, literal = rewards("paper", "mcts", range(30)), rewards("paper", "mcts-paper", range(30))
    diff = sound - literal
    assert diff.mean() > 5 * diff.std(ddof=1) / np.sqrt(len(diff))


@pytest.mark.slow
def test_mcts_beats_greedy_on_held_out_seeds():
    """Seeds 100-299 were never used to choose the planner's settings (0-99 were). The
    paired difference (same seed, same world) must be positive by two standard errors.
    (On the field preset the same run gives +0.0015 +- 0.0009: not significant, so not
    asserted; docs/PLANNER.md reports it.)"""
    seeds = range(100, 300)
    diff = rewards("paper", "mcts", seeds) - rewards("paper", "greedy", seeds)
    print(f"paper: mcts - greedy = {diff.mean():+.4f} +- {diff.std(ddof=1) / np.sqrt(len(diff)):.4f}")
    assert diff.mean() > 2 * diff.std(ddof=1) / np.sqrt(len(diff))
