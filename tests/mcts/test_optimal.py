"""On small static instances every path can be enumerated: mcts must find the optimum."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.mcts import MctsConfig, MctsPlanner
from planner_service.model import SortieEnv, paper


def static_scenario():
    """K=5, I=3, four intervals, no mobility, a budget that binds."""
    return paper().replace(num_hover_points=5, num_users=3, hover_layout="uniform", user_move_range_m=0.0,
                           max_intervals=4, battery_j=330_000.0, fairness_threshold_tasks=12)


def best_average(env: SortieEnv) -> float:
    """The largest sortie-average reward over every allowed path from ``env``'s state."""
    best = -np.inf
    for action in np.flatnonzero(env.action_mask()):
        snap = env.snapshot()
        env.step(int(action))
        if env.done:
            value = env.state.reward_sum / env.state.interval
        else:
            value = best_average(env)
        best = max(best, value)
        env.restore(snap)
    return best


def fly(env: SortieEnv, choose) -> float:
    while not env.done:
        env.step(choose(env))
    return env.state.reward_sum / env.state.interval


@pytest.mark.parametrize("instance", range(6))
def test_mcts_finds_the_enumerated_optimum(instance):
    scenario = static_scenario()
    table = np.random.default_rng(instance).integers(1, 21, size=(4, 3))
    env = SortieEnv(scenario)
    env.reset(seed=instance, options={"task_table": table})
    start = env.snapshot()
    optimum = best_average(env)
    greedy = fly(env, lambda e: int(np.argmax(e.action_values())))
    env.restore(start)
    planner = MctsPlanner(scenario, env.hover_points, MctsConfig(iterations=2000), np.random.default_rng(instance))
    found = fly(env, lambda e: planner.plan(e.state).action)
    assert found == pytest.approx(optimum, abs=1e-12)
    assert greedy <= optimum + 1e-12


def test_the_instances_are_not_all_solved_by_greedy():
    """The enumeration test above would pass for greedy too if greedy were optimal on all of them."""
    scenario = static_scenario()
    gaps = []
    for instance in range(6):
        table = np.random.default_rng(instance).integers(1, 21, size=(4, 3))
        env = SortieEnv(scenario)
        env.reset(seed=instance, options={"task_table": table})
        start = env.snapshot()
        optimum = best_average(env)
        env.restore(start)
        gaps.append(optimum - fly(env, lambda e: int(np.argmax(e.action_values()))))
    assert max(gaps) > 1e-3
