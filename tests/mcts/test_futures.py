"""The futures' index gives every action the reward the plain evaluation gives, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.mcts.futures import (allowed_future, evaluate_step, fill_rows, greedy_future, index_of,
                                          point_tables_of, point_user, root_values_of)
from planner_service.mcts.open_loop import draw_futures
from planner_service.model import SortieEnv, field, pack, paper, paper_3d
from planner_service.model.interval import remaining_intervals, served_user
from planner_service.model.world import advance, clone, draw_chance, evaluate, scene_of, serve

CASES = {
    "paper": paper(),
    "field-reserve": field(),
    "3d": paper_3d(),
    "backlog": paper().replace(task_model="backlog", task_arrival_mean=2.0),
    "stay-wide-tie": paper().replace(allow_stay=True, nearest_tie_m=30.0),
    "crowd": paper().replace(num_hover_points=40, num_users=300),
    "few-users": field().replace(num_users=3, fairness_threshold_tasks=5),
}


def priced_by_serve(scene, w, action: int, user: int) -> float:
    """The interval's energy as ``serve`` computes it (on a copy of ``w``)."""
    out = serve(scene, clone(w), action, user)
    return out.e_hover_j + out.e_comp_j + out.e_flight_j


@pytest.mark.parametrize("name", sorted(CASES))
def test_index_matches_the_plain_evaluation_along_random_playouts(name):
    scenario = CASES[name]
    rng = np.random.default_rng(11)
    env = SortieEnv(scenario)
    env.reset(seed=3)
    if name != "few-users":  # a state part-way through a sortie: some users served already
        for _ in range(2):
            env.step(int(rng.choice(np.flatnonzero(env.action_mask()))))
    p = pack(scenario)
    scene = scene_of(p, env.hover_points, env.state.task_table)
    root = env.state.world()
    tables = point_tables_of(p, env.hover_points)
    values = root_values_of(scene, root, tables)
    plain = np.empty(len(env.hover_points))
    evaluate(scene, clone(root), plain)
    assert np.array_equal(values.q, plain)
    num_users = len(root.users)
    horizon = remaining_intervals(p, num_users, int(root.interval[0]))
    moves = np.empty((4, horizon, num_users, 3))
    news = np.empty((4, horizon, num_users), dtype=np.int64)
    draw_futures(p, moves, news, rng)
    index = index_of(scene, root, moves, news, tables, values)
    asked = index_of(scene, root, moves, news, tables, values)  # asked only what the lean kernels ask
    k = len(env.hover_points)
    q, users = np.empty(k), np.empty(k, dtype=np.int64)
    mask, skip = np.empty(k), np.zeros(k, dtype=np.bool_)
    touched = np.zeros(horizon + 1, dtype=np.int64)
    flag = np.zeros(num_users, dtype=np.bool_)
    compared = 0
    for playout in range(24):
        future = playout % 4
        w = clone(root)
        flag[:] = False
        steps = 0
        while scenario.max_intervals <= 0 or w.interval[0] < scenario.max_intervals:
            allowed = evaluate_step(scene, index, root, w, future, steps, touched, flag, q, users)
            evaluate(scene, clone(w), plain)
            assert np.array_equal(q, plain), (playout, steps)
            assert allowed == np.isfinite(plain).sum()
            for a in np.flatnonzero(np.isfinite(plain)):
                assert users[a] == served_user(p, scene.hover_points[a], w.users, w.tasks, w.served)
            if steps > 0:  # the lean kernels: the greedy step, the allowed set, one point's user
                fill_rows(scene, asked, root, future, steps)
                skip[:] = rng.random(k) < 0.3 if playout % 2 else False
                among = np.where(skip, -np.inf, plain)
                best, user, energy, best_q = greedy_future(scene, asked, root, future, steps, w, touched, flag, skip)
                expected = int(np.argmax(among)) if np.isfinite(among).any() else -1
                assert best == expected, (playout, steps)
                assert best < 0 or (user == users[best] and best_q == plain[best]
                                    and energy == priced_by_serve(scene, w, best, user))
                assert allowed_future(scene, asked, root, future, steps, w, touched, flag, mask) == allowed
                assert np.array_equal(np.isfinite(mask), np.isfinite(plain))
                for a in np.flatnonzero(np.isfinite(plain)):
                    user, energy, point_q = point_user(scene, asked, future, steps, a, w, touched, flag)
                    assert user == users[a] and point_q == plain[a]
                    assert energy == priced_by_serve(scene, w, a, user)  # to the last bit: ``settle`` takes it
            compared += 1
            if allowed == 0:
                break
            # greedy now and then, else a random allowed point: both kinds of paths
            a = int(np.argmax(q)) if playout % 3 == 0 else int(rng.choice(np.flatnonzero(np.isfinite(q))))
            out = serve(scene, w, a, users[a])
            touched[steps], flag[out.user] = out.user, True
            advance(scene, w, moves[future, steps], news[future, steps])
            steps += 1
    assert compared > 24


def test_fresh_steps_match_the_plain_evaluation():
    """Without shared futures each step refits the root's tree to where the users are."""
    scenario = paper().replace(num_hover_points=30, num_users=120)
    rng = np.random.default_rng(5)
    env = SortieEnv(scenario)
    env.reset(seed=8)
    p = pack(scenario)
    scene = scene_of(p, env.hover_points, env.state.task_table)
    root = env.state.world()
    tables = point_tables_of(p, env.hover_points)
    values = root_values_of(scene, root, tables)
    index = index_of(scene, root, np.empty((0, 0, 120, 3)), np.empty((0, 0, 120), dtype=np.int64), tables, values)
    w = clone(root)
    q, users, plain = np.empty(30), np.empty(30, dtype=np.int64), np.empty(30)
    moves, news = np.empty((120, 3)), np.empty(120, dtype=np.int64)
    for steps in range(8):
        allowed = evaluate_step(scene, index, root, w, -1, steps, np.zeros(9, dtype=np.int64),
                                np.zeros(120, dtype=np.bool_), q, users)
        evaluate(scene, clone(w), plain)
        assert np.array_equal(q, plain) and allowed == np.isfinite(plain).sum()
        if allowed == 0:
            break
        a = int(rng.choice(np.flatnonzero(np.isfinite(q))))
        serve(scene, w, a, users[a])
        draw_chance(p, moves, news, rng)
        advance(scene, w, moves, news)
