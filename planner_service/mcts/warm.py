"""Compile every kernel a planner uses before its first decision in flight.

numba compiles a kernel for each new combination of argument types the first time it is
called (or loads it from its on-disk cache), which takes from milliseconds to seconds. In
flight that is a stall at the worst moment; ``warm_up`` makes those calls on a small state
built with the same array types as the service's (``service.planning.assemble``), so that
the first real decision compiles nothing. ``tests/service/test_warm_up.py`` checks it
through the service's planner: no compiled function gains a signature in a first decision.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np

from ..model import AT_BASE, NO_MOVES, NO_NEWS, Scenario, SortieState, hover_points, pack
from ..model.channel import channel_gain, upload_rate_bps
from ..model.energy import flight_energy_j
from ..model.interval import remaining_intervals, return_energy_j, served_user, user_outcome, within_budget
from ..model.world import clone, evaluate, in_time, scene_of, step
from .futures import index_of, point_tables_of, root_values_of
from .open_loop import SearchSettings, draw_futures, paired_fresh, paired_rollouts
from .paper import PaperMctsPlanner
from .planner import MctsConfig, MctsPlanner

ALGOS = ("mcts", "greedy", "random", "ts-mcts", "mcts-paper")
"""Every algorithm ``warm_up`` knows (those the service flies)."""


def warm_state(scenario: Scenario) -> SortieState:
    """Three users with tasks, one served once, the UAV in the air part-way through its
    battery: the array types of a state the service assembles."""
    users = np.array([[100.0, 150.0, 0.0], [250.0, 250.0, 0.0], [400.0, 350.0, 0.0]])
    return SortieState(
        uav_xyz=np.array([50.0, 50.0, scenario.altitude_m]), hover_index=AT_BASE, users=users,
        tasks=np.array([18, 9, 10], dtype=np.int64), served=np.array([1, 0, 0], dtype=np.int64),
        battery_j=0.9 * scenario.battery_j, interval=1, energy_used_j=0.1 * scenario.battery_j,
        task_table=np.zeros((0, 3), dtype=np.int64), reward_sum=0.1)


def warm_up(scenario: Scenario, algos: Iterable[str] = ALGOS, config: MctsConfig | None = None) -> None:
    """Run every kernel ``algos`` use on ``scenario`` once (the search, the confirmation
    against greedy, Algorithm 1's closed loop, the one-step rules, the path prediction's
    kernels), with the array types of flight. Cheap once compiled: tens of milliseconds."""
    algos = tuple(algos)
    unknown = sorted(set(algos) - set(ALGOS))
    if unknown:
        raise ValueError(f"warm_up: unknown algorithms {unknown}; choose from {ALGOS}")
    scenario = scenario.replace(num_users=3)
    points = hover_points(scenario)
    state = warm_state(scenario)
    rng = np.random.default_rng(0)
    if "mcts" in algos:
        config = config or MctsConfig()
        MctsPlanner(scenario, points, config.__class__(**{**vars(config), "iterations": 24, "budget_ms": None}),
                    rng).plan(state)
        _confirmation(scenario, points, state, rng)
    for algo, schedule in (("mcts-paper", "paper"), ("ts-mcts", "timesaving")):
        if algo in algos:
            PaperMctsPlanner(scenario, points, 8, rng, schedule=schedule).plan(state)
    _one_step_and_path(scenario, points, state)


def _confirmation(scenario: Scenario, points: np.ndarray, state: SortieState, rng: np.random.Generator) -> None:
    """The paired playouts ``MctsPlanner`` runs only when the search leaves greedy (on
    shared futures, or fresh ones when tasks arrive in time)."""
    p = pack(scenario)
    scene = scene_of(p, points, state.task_table)
    root = state.world()
    tables = point_tables_of(p, points)
    values = root_values_of(scene, root, tables)
    horizon = remaining_intervals(p, len(state.users), state.interval)
    moves = np.empty((2, horizon, len(state.users), 3))
    news = np.empty((2, horizon, len(state.users)), dtype=np.int64)
    draw_futures(p, moves, news, rng)
    settings = SearchSettings(1.0, 1, 0.1, 2, float(state.reward_sum), int(state.interval), 10)
    allowed = np.flatnonzero(np.isfinite(values.q))
    first, second, out = int(allowed[0]), int(allowed[-1]), np.empty((2, 2))
    if in_time(p):
        index = index_of(scene, root, moves[:0], news[:0], tables, values)
        paired_fresh(scene, root, first, second, settings, index, moves, rng.random(news.shape), out)
    else:
        paired_rollouts(scene, root, first, second, settings, index_of(scene, root, moves, news, tables, values), out)


def _one_step_and_path(scenario: Scenario, points: np.ndarray, state: SortieState) -> None:
    """The kernels the one-step rules and the service's path prediction call."""
    p = pack(scenario)
    scene = scene_of(p, points, state.task_table)
    w = clone(state.world())
    q = np.empty(len(points))
    evaluate(scene, w, q)
    k = int(np.argmax(q))
    user = served_user(p, points[k], w.users, w.tasks, w.served)
    bits, e_h, e_c, e_f, _ = user_outcome(p, w.uav_xyz, points[k], w.users[user], w.tasks[user])
    within_budget(p, float(w.battery_j[0]), e_h + e_c + e_f, points[k])
    upload_rate_bps(p, channel_gain(p, points[k], w.users[user]))
    step(scene, w, k, NO_MOVES, NO_NEWS)
    return_energy_j(p, w.uav_xyz)
    flight_energy_j(p, float(scenario.speed_mps))


__all__ = ["ALGOS", "warm_state", "warm_up"]
