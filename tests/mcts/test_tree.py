"""The tree arrays: growth, best child, principal line, subtree compaction."""

from __future__ import annotations

import numpy as np

from planner_service.mcts.tree import NO_PARENT, ROOT_INDEX, UNVISITED, Tree


def small_tree() -> Tree:
    """root -a0-> 1 (10 visits) -a2-> 3 (6 visits); root -a1-> 2 (4 visits)."""
    t = Tree.empty(num_actions=3, capacity=2)
    t.reserve(3)
    for node, parent, action, visits, value in ((1, 0, 0, 10, 5.0), (2, 0, 1, 4, 3.0), (3, 1, 2, 6, 2.4)):
        t.parent[node], t.action[node] = parent, action
        t.children[parent, action] = node
        t.visits[node], t.value_sum[node] = visits, value
    t.visits[0], t.value_sum[0] = 14, 8.0
    t.num_nodes = 4
    return t


def test_reserve_grows_and_keeps_contents():
    t = small_tree()
    assert t.capacity >= 4
    before = t.children[:4].copy()
    t.reserve(100)
    assert t.capacity >= 104
    np.testing.assert_array_equal(t.children[:4], before)
    assert (t.children[4:] == UNVISITED).all() and (t.parent[4:] == NO_PARENT).all()


def test_best_child_and_principal_line():
    t = small_tree()
    assert t.best_child(ROOT_INDEX) == 1  # 10 visits beat 4
    assert t.best_child(ROOT_INDEX, allowed=np.array([False, True, True])) == 2
    assert t.principal_line() == [0, 2]
    assert t.mean_value(1) == 0.5


def test_subtree_compacts_and_decays():
    t = small_tree()
    sub = t.subtree(1, decay=0.5)
    assert sub.num_nodes == 2
    assert sub.parent.tolist() == [NO_PARENT, 0]
    assert sub.children[0].tolist() == [UNVISITED, UNVISITED, 1]
    assert sub.action.tolist() == [-1, 2]
    assert sub.visits.tolist() == [5.0, 3.0]
    assert sub.value_sum.tolist() == [2.5, 1.2]
    assert sub.principal_line() == [2]
