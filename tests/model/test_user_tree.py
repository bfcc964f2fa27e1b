"""The users' k-d tree answers exactly what the plain scan answers."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.model import NO_USER, hover_points, pack, paper, paper_3d, user_rows
from planner_service.model.interval import served_user
from planner_service.model.user_tree import LEAF, empty_tree, fill_tree, refit_tree, tree_nearest, tree_nearest_list, tree_size


def random_state(rng: np.random.Generator, scenario, num_users: int, spread: float = 1.0):
    side = scenario.area_side_m
    users = np.zeros((num_users, 3))
    users[:, :2] = rng.integers(0, int(side * spread) + 1, size=(num_users, 2))  # whole metres: many exact ties
    users[:, :2] -= side * (spread - 1.0) / 2  # spread > 1: some users outside the area
    if scenario.dimensions == 3:
        users[:, 2] = rng.integers(0, 21, size=num_users)
    tasks = rng.integers(0, scenario.task_max + 1, size=num_users)
    served = rng.choice([0, 0, 0, 1, 2], size=num_users)
    return users, tasks.astype(np.int64), served.astype(np.int64)


@pytest.mark.parametrize("scenario", [paper(), paper().replace(nearest_tie_m=25.0), paper_3d()],
                         ids=["paper", "wide-tie", "3d"])
@pytest.mark.parametrize("num_users", [1, 3, 10, 57, 400, 2000])
def test_tree_serves_whom_the_scan_serves(scenario, num_users):
    rng = np.random.default_rng(num_users)
    scenario = scenario.replace(num_hover_points=40) if scenario.dimensions == 2 else scenario
    p = pack(scenario)
    points = hover_points(scenario)
    tree = empty_tree(num_users)
    checked = 0
    for trial in range(6):
        users, tasks, served = random_state(rng, scenario, num_users, spread=1.0 if trial % 2 else 1.3)
        if trial == 4:  # the paper's two neat rows, crowded, a few moves later
            users = user_rows(num_users, scenario.area_side_m) + np.pad(rng.integers(-30, 31, size=(num_users, 2)), ((0, 0), (0, 1)))
        if trial == 5:  # clusters: many users on the same spot
            users[:, :2] = np.round(users[:, :2] / 50.0) * 50.0
        fill_tree(users, tree)
        for k in range(len(points)):
            expected = served_user(p, points[k], users, tasks, served)
            user, reach_sq = tree_nearest(p, points[k], users, tasks, served, tree)
            assert user == expected, (trial, k)
            if expected == NO_USER:
                assert reach_sq == np.inf
            else:
                assert ((users[expected] - points[k]) ** 2).sum() <= reach_sq
            checked += 1
    assert checked == 6 * len(points)


def test_tree_nodes_hold_every_user():
    """Every leaf holds at most LEAF users, and the heap has room for every node."""
    rng = np.random.default_rng(3)
    for num_users in (0, 1, LEAF, LEAF + 1, 1000, 5000):
        tree = empty_tree(num_users)
        users = rng.uniform(0, 500, size=(num_users, 3))
        fill_tree(users, tree)
        assert sorted(tree.order) == list(range(num_users))
        size = tree_size(num_users)
        assert tree.box.shape == (size, 6)
        # the root box bounds every user
        if num_users:
            assert (tree.box[0, 0::2] <= users.min(axis=0)).all() and (tree.box[0, 1::2] >= users.max(axis=0)).all()


@pytest.mark.parametrize("num_users", [3, 10, 57, 400, 2000])
def test_tree_lists_the_nearest_eligible_in_order(num_users):
    scenario = paper().replace(num_hover_points=40)
    rng = np.random.default_rng(100 + num_users)
    p = pack(scenario)
    points = hover_points(scenario)
    tree = empty_tree(num_users)
    users, tasks, served = random_state(rng, scenario, num_users, spread=1.2)
    fill_tree(users, tree)
    eligible = np.array([served[i] == 0 and tasks[i] > 0 or served[i] == 1 and tasks[i] > 15 for i in range(num_users)])
    for k in range(len(points)):
        out_user, out_d2 = np.zeros(6, dtype=np.int64), np.zeros(6)
        count, cover = tree_nearest_list(p, points[k], users, tasks, served, tree, out_user, out_d2)
        d2 = ((users - points[k]) ** 2).sum(axis=1)
        expected = sorted((d2[i], i) for i in np.flatnonzero(eligible))
        assert count == min(6, len(expected))
        assert list(out_user[:count]) == [i for _, i in expected[:count]]
        assert list(out_d2[:count]) == pytest.approx([d for d, _ in expected[:count]])
        assert cover == (np.inf if len(expected) < 6 else out_d2[5])


@pytest.mark.parametrize("num_users", [10, 300, 3000])
def test_a_refitted_tree_answers_for_the_moved_users(num_users):
    """The search builds a tree at the root and only refits its boxes as the users move."""
    scenario = paper().replace(num_hover_points=40)
    rng = np.random.default_rng(num_users)
    p = pack(scenario)
    points = hover_points(scenario)
    users = user_rows(num_users, scenario.area_side_m)
    tree = empty_tree(num_users)
    fill_tree(users, tree)
    tasks = rng.integers(0, 21, size=num_users).astype(np.int64)
    served = rng.choice([0, 0, 1, 2], size=num_users).astype(np.int64)
    for _ in range(10):
        users[:, :2] = np.clip(users[:, :2] + rng.integers(-10, 11, size=(num_users, 2)), 0, 500)
        refit_tree(users, tree)
        for k in range(len(points)):
            assert tree_nearest(p, points[k], users, tasks, served, tree)[0] == \
                served_user(p, points[k], users, tasks, served)
