"""``mcts-paper`` and ``ts-mcts``: Algorithm 1 and Section III-C as written, flaws included.

What the paper's algorithm does, and this code reproduces:
- Closed loop: a node holds the state reached when it was expanded, with the chance (users'
  moves, task draws) drawn once at that moment and never again. A node's value trusts that
  one draw.
- Selection by UCT (10) on raw values, Q/N + c sqrt(2 ln N(parent) / N(child)); expansion of
  one untried hovering point drawn at random; a uniform random playout until no action is
  allowed (the battery threshold); R = mean of q from the newly expanded node to the end of
  the playout; R added to the new node and to every ancestor (lines 25-28).
- So once a first-level child has descendants, its own step's q no longer enters the R
  backed up through it, and the value of a first-level action drifts toward the value of
  the playouts below it: more iterations can make decisions worse.
- The decision (line 31) is the root child with the largest UCT value, exploration term
  included.
- A new tree is built from the observed state at each decision (the flight-side reading of
  the outer loop: the UAV acts, observes, and searches again).

``ts-mcts`` runs the same search with n - (l - 1) n / m iterations at the l-th decision of
the sortie (Section III-C), at least n / m.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..model import Scenario, SortieState, pack
from ..model import params as P
from ..model._jit import jit
from ..model.interval import advance_chance, evaluate_actions, take_interval
from ..policy import Decision
from .open_loop import random_allowed
from .tree import ROOT_INDEX, UNVISITED, Tree


@jit
def _random_untried(children: np.ndarray, node: int, qvals: np.ndarray, rng: np.random.Generator) -> int:
    count = 0
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf and children[node, a] == UNVISITED:
            count += 1
    if count == 0:
        return -1
    pick = rng.integers(0, count)
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf and children[node, a] == UNVISITED:
            if pick == 0:
                return a
            pick -= 1
    return -1


@jit
def uct_best(children: np.ndarray, node: int, qvals: np.ndarray, visits: np.ndarray, value_sum: np.ndarray, c: float) -> int:
    """argmax over allowed children of Q/N + c sqrt(2 ln N(node) / N(child)) (10)."""
    best = UNVISITED
    best_score = -math.inf
    log_n = math.log(max(visits[node], 1.0))
    for a in range(qvals.shape[0]):
        child = children[node, a]
        if qvals[a] > -math.inf and child != UNVISITED and visits[child] > 0:
            score = value_sum[child] / visits[child] + c * math.sqrt(2.0 * log_n / visits[child])
            if score > best_score:
                best = child
                best_score = score
    return best


@jit
def search_closed_loop(
    p: np.ndarray,
    hover_points: np.ndarray,
    parent: np.ndarray,
    action: np.ndarray,
    children: np.ndarray,
    visits: np.ndarray,
    value_sum: np.ndarray,
    node_uav: np.ndarray,
    node_hover: np.ndarray,
    node_users: np.ndarray,
    node_tasks: np.ndarray,
    node_served: np.ndarray,
    node_battery: np.ndarray,
    node_interval: np.ndarray,
    node_q: np.ndarray,
    task_table: np.ndarray,
    iterations: int,
    c: float,
    rng: np.random.Generator,
) -> int:
    """Algorithm 1's inner loop, ``iterations`` times from the root (node 0, whose state
    arrays hold the observed state). Node states are (N, ...) arrays; returns the node count."""
    limit = int(p[P.MAX_INTERVALS])
    qvals = np.empty(hover_points.shape[0])
    users = node_users[0].copy()
    tasks = node_tasks[0].copy()
    served = node_served[0].copy()
    uav = node_uav[0].copy()
    num_nodes = 1
    for _ in range(iterations):
        node = ROOT_INDEX
        leaf = -1
        while True:
            allowed = 0
            if limit <= 0 or node_interval[node] < limit:
                allowed = evaluate_actions(
                    p, hover_points, node_hover[node], node_uav[node], node_users[node],
                    node_tasks[node], node_served[node], node_battery[node], qvals,
                )
            if allowed == 0:
                break  # a terminal node: nothing to expand or play out
            a = _random_untried(children, node, qvals, rng)
            if a < 0:
                node = uct_best(children, node, qvals, visits, value_sum, c)
                continue
            child = num_nodes
            num_nodes += 1
            parent[child] = node
            action[child] = a
            children[child, :] = UNVISITED
            children[node, a] = child
            visits[child] = 0.0
            value_sum[child] = 0.0
            users[:] = node_users[node]
            tasks[:] = node_tasks[node]
            served[:] = node_served[node]
            uav[:] = node_uav[node]
            outcome = take_interval(p, hover_points, a, uav, users, tasks, served)
            t = node_interval[node] + 1
            advance_chance(p, users, tasks, t, task_table, rng)  # drawn once, frozen in the node
            node_uav[child] = uav
            node_hover[child] = a
            node_users[child] = users
            node_tasks[child] = tasks
            node_served[child] = served
            node_battery[child] = node_battery[node] - (outcome[2] + outcome[3] + outcome[4])
            node_interval[child] = t
            node_q[child] = outcome[5]
            leaf = child
            break
        if leaf < 0:
            if node == ROOT_INDEX:
                break
            leaf = node
            ret = node_q[node]  # a terminal leaf: its own step is all there is
        else:
            ret = _random_playout(p, hover_points, leaf, node_hover, node_battery, node_interval,
                                  node_q, uav, users, tasks, served, task_table, limit, qvals, rng)
        n = leaf
        while n != -1:  # lines 25-28: the same R into the new node and every ancestor
            visits[n] += 1.0
            value_sum[n] += ret
            n = parent[n]
    return num_nodes


@jit
def _random_playout(p, hover_points, leaf, node_hover, node_battery, node_interval, node_q,
                    uav, users, tasks, served, task_table, limit, qvals, rng) -> float:
    """Lines 18-24: uniform random actions from the new node's state until none is allowed;
    R = mean of q over the new node's step and the playout's steps. ``uav``, ``users``,
    ``tasks``, ``served`` hold the new node's state and are used up."""
    total = node_q[leaf]
    count = 1
    hover = node_hover[leaf]
    battery = node_battery[leaf]
    t = node_interval[leaf]
    while limit <= 0 or t < limit:
        allowed = evaluate_actions(p, hover_points, hover, uav, users, tasks, served, battery, qvals)
        if allowed == 0:
            break
        a = random_allowed(qvals, allowed, rng)
        outcome = take_interval(p, hover_points, a, uav, users, tasks, served)
        battery -= outcome[2] + outcome[3] + outcome[4]
        hover = a
        t += 1
        advance_chance(p, users, tasks, t, task_table, rng)
        total += outcome[5]
        count += 1
    return total / count


class PaperMctsPlanner:
    """Algorithm 1 (``schedule="paper"``) or TS-MCTS (``schedule="timesaving"``)."""

    def __init__(self, scenario: Scenario, hover_points: np.ndarray, iterations: int,
                 rng: np.random.Generator, schedule: str = "paper") -> None:
        if iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {iterations}")
        if schedule not in ("paper", "timesaving"):
            raise ValueError(f"schedule must be 'paper' or 'timesaving', got {schedule!r}")
        self.scenario = scenario
        self.params = pack(scenario)
        self.hover_points = np.ascontiguousarray(hover_points, dtype=np.float64)
        self.iterations = iterations
        self.schedule = schedule
        self.rng = rng

    def iterations_at(self, interval: int) -> int:
        """n at every decision, or TS-MCTS's n - (l - 1) n / m at decision l = interval + 1."""
        n, m = self.iterations, self.scenario.tree_depth
        if self.schedule == "paper":
            return n
        return max(n - interval * n // m, max(n // m, 1))

    def plan(self, state: SortieState) -> Decision:
        start = time.perf_counter()
        n = self.iterations_at(state.interval)
        cap = n + 1
        k, i = len(self.hover_points), len(state.users)
        tree = Tree.empty(k, cap)
        node_uav = np.zeros((cap, 3))
        node_hover = np.full(cap, -1, dtype=np.int64)
        node_users = np.zeros((cap, i, 3))
        node_tasks = np.zeros((cap, i), dtype=np.int64)
        node_served = np.zeros((cap, i), dtype=np.int64)
        node_battery = np.zeros(cap)
        node_interval = np.zeros(cap, dtype=np.int64)
        node_q = np.zeros(cap)
        node_uav[0], node_hover[0], node_users[0] = state.uav_xyz, state.hover_index, state.users
        node_tasks[0], node_served[0] = state.tasks, state.served
        node_battery[0], node_interval[0] = state.battery_j, state.interval
        tree.num_nodes = search_closed_loop(
            self.params, self.hover_points, tree.parent, tree.action, tree.children, tree.visits,
            tree.value_sum, node_uav, node_hover, node_users, node_tasks, node_served, node_battery,
            node_interval, node_q, state.task_table, n, self.scenario.uct_c, self.rng,
        )
        q = np.empty(k)
        evaluate_actions(self.params, self.hover_points, state.hover_index, state.uav_xyz, state.users,
                         state.tasks, state.served, state.battery_j, q)
        if not np.isfinite(q).any():
            raise ValueError("no hovering point is allowed in this state: the sortie is over")
        child = uct_best(tree.children, ROOT_INDEX, q, tree.visits, tree.value_sum, self.scenario.uct_c)  # line 31
        action = int(tree.action[child])
        return Decision(
            action=action,
            line=(action, *tree.principal_line(child)),
            iterations=n,
            wall_s=time.perf_counter() - start,
            extra={"nodes": tree.num_nodes},
        )
