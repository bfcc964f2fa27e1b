"""The compiled search of the sound planner: open-loop MCTS over action sequences.

A node stands for a sequence of hovering points from the root, not for one sampled world
state. Every iteration starts from the root's real state and plays one sampled future of
the chance (users' moves, future task draws), so a node's value is an average over futures
rather than a single draw. The futures are drawn once per decision, and the n-th visit of
each root child plays future n mod S: the candidate actions are then compared on the same
futures (common random numbers), which removes most of the noise from their difference. With S = 0 every
iteration draws a fresh future instead. Each node backs up the return from its own step
onward (the mean, or the sum, of q from the step that enters it to the end of the sortie).
"""

from __future__ import annotations

import math

import numpy as np

from ..model._jit import jit
from ..model import params as P
from ..model.interval import apply_chance, draw_chance, evaluate_actions, remaining_intervals, take_interval
from .tree import ROOT_INDEX, UNVISITED

ROLLOUT_RANDOM = 0
"""Playout policy: uniform among allowed hovering points (the paper's)."""
ROLLOUT_EPSILON_GREEDY = 1
"""Playout policy: the largest immediate q, or with probability epsilon a uniform draw."""

RETURN_MEAN = 0
"""A node's return: the mean of q from its own step to the end (the paper's R)."""
RETURN_SUM = 1
"""A node's return: the sum of q from its own step to the end."""
RETURN_SORTIE = 2
"""Every node's return: the whole sortie's average q, the past intervals included (the
reported average reward). The sortie's length is then part of what is optimised."""


@jit
def _untried_best(children: np.ndarray, visits: np.ndarray, node: int, qvals: np.ndarray) -> int:
    """The allowed action not yet tried that has the largest immediate q; -1 if none.

    Untried: no child, or a child kept from a reused tree with its statistics decayed to
    nothing. Expanding the most promising action first is a cheap prior: with K children a
    level and few iterations, the tree then spends them where they matter."""
    best = -1
    best_q = -math.inf
    for a in range(qvals.shape[0]):
        child = children[node, a]
        untried = child == UNVISITED or visits[child] <= 0.0
        if untried and qvals[a] > best_q:
            best = a
            best_q = qvals[a]
    return best


@jit
def _uct_child(
    children: np.ndarray, node: int, qvals: np.ndarray, visits: np.ndarray, value_sum: np.ndarray, c: float
) -> int:
    """UCT (10) among the children whose action is allowed in this iteration's state.

    Mean values are min-max normalised over those children, so that c keeps its meaning
    whatever the scale of the reward; N is the visits of the allowed children."""
    lo = math.inf
    hi = -math.inf
    total = 0.0
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf:
            child = children[node, a]
            mean = value_sum[child] / visits[child]
            lo = min(lo, mean)
            hi = max(hi, mean)
            total += visits[child]
    spread = hi - lo
    log_total = math.log(max(total, 1.0))
    best = -1
    best_score = -math.inf
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf:
            child = children[node, a]
            mean = value_sum[child] / visits[child]
            exploit = (mean - lo) / spread if spread > 0.0 else 0.5
            score = exploit + c * math.sqrt(2.0 * log_total / visits[child])  # (10)
            if score > best_score:
                best = child
                best_score = score
    return best


@jit
def random_allowed(qvals: np.ndarray, allowed: int, rng: np.random.Generator) -> int:
    """A uniform draw among the ``allowed`` actions (those with a finite q)."""
    pick = rng.integers(0, allowed)
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf:
            if pick == 0:
                return a
            pick -= 1
    return -1


@jit
def rollout_action(qvals: np.ndarray, allowed: int, policy: int, epsilon: float, rng: np.random.Generator) -> int:
    """A playout step: uniform among allowed actions, or epsilon-greedy on q."""
    if policy == ROLLOUT_EPSILON_GREEDY and rng.random() >= epsilon:
        return int(np.argmax(qvals))
    return random_allowed(qvals, allowed, rng)


@jit
def node_return(
    kind: int, own_sum: float, own_steps: int, whole_sum: float, whole_steps: int, past_sum: float, past_count: int
) -> float:
    """What a node backs up: its own steps' mean or sum, or the whole sortie's average
    (``past_*``: the intervals flown before the root; ``whole_*``: this iteration's)."""
    if kind == RETURN_SUM:
        return own_sum
    if kind == RETURN_SORTIE:
        count = past_count + whole_steps
        return (past_sum + whole_sum) / count if count > 0 else 0.0
    return own_sum / own_steps if own_steps > 0 else 0.0


@jit
def _reset(uav, users, tasks, served, uav0, users0, tasks0, served0) -> None:  # noqa: ANN001
    """Copy the root state's arrays into an iteration's, in place."""
    uav[:] = uav0
    users[:] = users0
    tasks[:] = tasks0
    served[:] = served0


@jit
def search(
    p: np.ndarray,
    hover_points: np.ndarray,
    parent: np.ndarray,
    action: np.ndarray,
    children: np.ndarray,
    visits: np.ndarray,
    value_sum: np.ndarray,
    num_nodes: int,
    uav0: np.ndarray,
    hover0: int,
    users0: np.ndarray,
    tasks0: np.ndarray,
    served0: np.ndarray,
    battery0: float,
    interval0: int,
    task_table: np.ndarray,
    iterations: int,
    c: float,
    rollout: int,
    epsilon: float,
    return_kind: int,
    past_sum: float,
    past_count: int,
    future_moves: np.ndarray,
    future_tasks: np.ndarray,
    max_depth: int,
    rng: np.random.Generator,
) -> int:
    """Run ``iterations`` iterations from the root state; returns the new node count.

    ``future_moves`` (S, H, I, 3) and ``future_tasks`` (S, H, I): the S futures of the
    decision (``draw_futures``); the n-th visit of a root child plays future n mod S. With
    S = 0 each step draws from ``rng``. The tree grows at most ``max_depth`` levels below
    the root; past them the playout policy decides. The tree arrays must have room for ``iterations``
    more nodes (one expansion per iteration at most). The root state is not changed."""
    users = users0.copy()
    tasks = tasks0.copy()
    served = served0.copy()
    uav = uav0.copy()
    qvals = np.empty(hover_points.shape[0])
    horizon = 1 + remaining_intervals(p, users0.shape[0], interval0)
    rewards = np.empty(horizon)
    suffix = np.empty(horizon + 1)
    path = np.empty(horizon + 1, dtype=np.int64)
    limit = int(p[P.MAX_INTERVALS])
    num_futures = future_moves.shape[0]
    moves = np.empty_like(users0)
    new_tasks = np.empty_like(tasks0)
    for _ in range(iterations):
        future = -1
        _reset(uav, users, tasks, served, uav0, users0, tasks0, served0)
        hover = hover0
        battery = battery0
        t = interval0
        node = ROOT_INDEX
        path[0] = ROOT_INDEX
        depth = 1
        steps = 0
        in_tree = True
        while limit <= 0 or t < limit:
            allowed = evaluate_actions(p, hover_points, hover, uav, users, tasks, served, battery, qvals)
            if allowed == 0:
                break
            if in_tree and depth > max_depth:
                in_tree = False
            if in_tree:
                a = _untried_best(children, visits, node, qvals)
                if a >= 0:
                    child = children[node, a]
                    if child == UNVISITED:
                        child = num_nodes
                        num_nodes += 1
                        parent[child] = node
                        action[child] = a
                        children[child, :] = UNVISITED
                        visits[child] = 0.0
                        value_sum[child] = 0.0
                        children[node, a] = child
                    in_tree = False
                else:
                    child = _uct_child(children, node, qvals, visits, value_sum, c)
                    a = action[child]
                if depth == 1 and num_futures > 0:
                    future = int(visits[child] + 0.5) % num_futures
                node = child
                path[depth] = node
                depth += 1
            else:
                a = rollout_action(qvals, allowed, rollout, epsilon, rng)
            outcome = take_interval(p, hover_points, a, uav, users, tasks, served)
            battery -= outcome[2] + outcome[3] + outcome[4]
            hover = a
            t += 1
            rewards[steps] = outcome[5]
            if future >= 0:
                apply_chance(p, users, tasks, t, task_table, future_moves[future, steps], future_tasks[future, steps])
            else:
                draw_chance(p, moves, new_tasks, rng)
                apply_chance(p, users, tasks, t, task_table, moves, new_tasks)
            steps += 1
        suffix[steps] = 0.0
        for k in range(steps - 1, -1, -1):
            suffix[k] = suffix[k + 1] + rewards[k]
        for j in range(depth):
            first = j - 1 if j > 0 else 0  # node path[j] is entered by step j - 1
            ret = node_return(return_kind, suffix[first], steps - first, suffix[0], steps, past_sum, past_count)
            visits[path[j]] += 1.0
            value_sum[path[j]] += ret
    return num_nodes



@jit
def draw_futures(p: np.ndarray, future_moves: np.ndarray, future_tasks: np.ndarray, rng: np.random.Generator) -> None:
    """Fill S futures of H steps of chance: ``future_moves`` (S, H, I, 3), ``future_tasks``
    (S, H, I), each step drawn as the environment draws it."""
    for s in range(future_moves.shape[0]):
        for h in range(future_moves.shape[1]):
            draw_chance(p, future_moves[s, h], future_tasks[s, h], rng)


@jit
def paired_rollouts(
    p: np.ndarray,
    hover_points: np.ndarray,
    actions: np.ndarray,
    uav0: np.ndarray,
    hover0: int,
    users0: np.ndarray,
    tasks0: np.ndarray,
    served0: np.ndarray,
    battery0: float,
    interval0: int,
    task_table: np.ndarray,
    return_kind: int,
    past_sum: float,
    past_count: int,
    future_moves: np.ndarray,
    future_tasks: np.ndarray,
    out: np.ndarray,
) -> None:
    """Each of ``actions`` (A,) first, then the greedy policy, on each of the S futures:
    ``out`` (S, A) receives the returns (of the first step's node, as ``search`` backs up)."""
    users = users0.copy()
    tasks = tasks0.copy()
    served = served0.copy()
    uav = uav0.copy()
    qvals = np.empty(hover_points.shape[0])
    limit = int(p[P.MAX_INTERVALS])
    for s in range(future_moves.shape[0]):
        for k in range(actions.shape[0]):
            _reset(uav, users, tasks, served, uav0, users0, tasks0, served0)
            hover = hover0
            battery = battery0
            t = interval0
            total = 0.0
            steps = 0
            while limit <= 0 or t < limit:
                allowed = evaluate_actions(p, hover_points, hover, uav, users, tasks, served, battery, qvals)
                if allowed == 0:
                    break
                a = actions[k] if steps == 0 else int(np.argmax(qvals))
                outcome = take_interval(p, hover_points, a, uav, users, tasks, served)
                battery -= outcome[2] + outcome[3] + outcome[4]
                hover = a
                t += 1
                total += outcome[5]
                apply_chance(p, users, tasks, t, task_table, future_moves[s, steps], future_tasks[s, steps])
                steps += 1
            out[s, k] = node_return(return_kind, total, steps, total, steps, past_sum, past_count)
