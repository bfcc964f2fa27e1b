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
from ..model._jit import jit, jit_borrow
from ..model.mobility import draw_int
from ..model.world import Scene, World, clone, copy_into, draw_chance, evaluate, scene_of, step
from ..policy import Decision
from .objective import RETURN_MEAN, node_return
from .open_loop import random_allowed
from .tree import ROOT_INDEX, UNVISITED, Tree, TreeArrays


@jit
def _random_untried(children: np.ndarray, node: int, qvals: np.ndarray, rng: np.random.Generator) -> int:
    count = 0
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf and children[node, a] == UNVISITED:
            count += 1
    if count == 0:
        return -1
    pick = draw_int(rng, 0, count)
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf and children[node, a] == UNVISITED:
            if pick == 0:
                return a
            pick -= 1
    return -1


@jit_borrow
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


def node_states(capacity: int, num_users: int) -> World:
    """Room for the states of ``capacity`` nodes: a ``World`` whose arrays have a leading
    node axis (N, ...)."""
    return World(np.zeros((capacity, 3)), np.full(capacity, -1, dtype=np.int64), np.zeros((capacity, num_users, 3)),
                 np.zeros((capacity, num_users), dtype=np.int64), np.zeros((capacity, num_users), dtype=np.int64),
                 np.zeros(capacity), np.zeros(capacity, dtype=np.int64), np.zeros(capacity), np.zeros(capacity))


@jit
def node_world(nodes: World, n: int) -> World:
    """The state held by node ``n`` (views into ``nodes``)."""
    return World(nodes.uav_xyz[n], nodes.hover[n:n + 1], nodes.users[n], nodes.tasks[n], nodes.served[n],
                 nodes.battery_j[n:n + 1], nodes.interval[n:n + 1], nodes.energy_used_j[n:n + 1],
                 nodes.reward_sum[n:n + 1])


@jit
def search_closed_loop(scene: Scene, tree: TreeArrays, nodes: World, node_q: np.ndarray, iterations: int, c: float,
                       rng: np.random.Generator) -> int:
    """Algorithm 1's inner loop, ``iterations`` times from the root (node 0, whose state
    ``nodes`` holds the observed state). ``nodes``: every node's state (``node_states``),
    ``node_q`` (N,): the reward of the step into each node. Returns the node count."""
    p = scene.p
    parent, action, children, visits, value_sum = tree
    limit = int(p[P.MAX_INTERVALS])
    qvals = np.empty(scene.hover_points.shape[0])
    w = clone(node_world(nodes, ROOT_INDEX))
    moves = np.empty_like(w.users)
    news = np.empty_like(w.tasks)
    num_nodes = 1
    for _ in range(iterations):
        node = ROOT_INDEX
        leaf = -1
        while True:
            allowed = 0
            state = node_world(nodes, node)
            if limit <= 0 or state.interval[0] < limit:
                allowed = evaluate(scene, state, qvals)
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
            copy_into(w, state)
            draw_chance(p, moves, news, rng)  # drawn once, frozen in the node
            node_q[child] = step(scene, w, a, moves, news).reward
            copy_into(node_world(nodes, child), w)
            leaf = child
            break
        if leaf < 0:
            if node == ROOT_INDEX:
                break
            leaf = node
            ret = node_q[node]  # a terminal leaf: its own step is all there is
        else:
            ret = _random_playout(scene, w, node_q[leaf], limit, qvals, moves, news, rng)
        n = leaf
        while n != -1:  # lines 25-28: the same R into the new node and every ancestor
            visits[n] += 1.0
            value_sum[n] += ret
            n = parent[n]
    return num_nodes


@jit
def _random_playout(scene: Scene, w: World, first_q: float, limit: int, qvals: np.ndarray, moves: np.ndarray,
                    news: np.ndarray, rng: np.random.Generator) -> float:
    """Lines 18-24: uniform random actions from the new node's state ``w`` (used up) until
    none is allowed; R = mean of q over the new node's step (``first_q``) and the
    playout's steps."""
    total = first_q
    count = 1
    while limit <= 0 or w.interval[0] < limit:
        allowed = evaluate(scene, w, qvals)
        if allowed == 0:
            break
        a = random_allowed(qvals, allowed, rng)
        draw_chance(scene.p, moves, news, rng)
        total += step(scene, w, a, moves, news).reward
        count += 1
    return node_return(RETURN_MEAN, total, count, total, count, 0.0, 0)


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
        scene = scene_of(self.params, self.hover_points, state.task_table)
        nodes = node_states(cap, i)
        node_q = np.zeros(cap)
        copy_into(node_world(nodes, ROOT_INDEX), state.world())
        tree.num_nodes = search_closed_loop(scene, tree.arrays(), nodes, node_q, n, self.scenario.uct_c, self.rng)
        q = np.empty(k)
        evaluate(scene, state.world(), q)
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
