"""The compiled search of the sound planner: open-loop MCTS over action sequences.

A node stands for a sequence of hovering points from the root, not for one sampled world
state. Every iteration starts from the root's real state and plays one sampled future of
the chance (users' moves, future task draws), so a node's value is an average over futures
rather than a single draw. The futures are drawn once per decision, and the n-th visit of
each root child plays future n mod S: the candidate actions are then compared on the same
futures (common random numbers), which removes most of the noise from their difference. With S = 0 every
iteration draws a fresh future instead, as it must when tasks arrive in time
(``model.world.in_time``): an interval's arrivals then depend on how long it lasted, so on
the path, which the shared futures' rows cannot follow. Each node backs up the objective of
``objective.py`` (by default the sortie's average reward).

Each step is the world's own ``serve`` and ``advance`` (``model.world``), the users' moves
made once for every iteration, in the future's rows; a step asks the futures' index
(``futures.py``) only for the points it needs (the best one, or which are allowed), with
values equal to the plain evaluation's to the last bit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..model._jit import jit, jit_borrow, jit_inline
from ..model import params as P
from ..model.interval import NO_USER, interval_duration_s, remaining_intervals
from ..model.mobility import arrival_mean, draw_int, poisson_quantile
from ..model.user_tree import refit_tree
from ..model.world import Scene, World, advance, clone, copy_into, draw_chance, draw_chance_after, in_time, serve, settle
from .futures import FutureIndex, allowed_future, evaluate_step, evaluate_tree, fill_rows, greedy_future, point_user
from .objective import node_return
from .tree import ROOT_INDEX, UNVISITED, TreeArrays

ROLLOUT_RANDOM = 0
"""Playout policy: uniform among allowed hovering points (the paper's)."""
ROLLOUT_EPSILON_GREEDY = 1
"""Playout policy: the largest immediate q, or with probability epsilon a uniform draw."""


class SearchSettings(NamedTuple):
    """How a search runs: UCT constant ``c`` (10), the ``rollout`` policy and its
    ``epsilon``, the objective's ``return_kind`` (``objective.py``) with the sum and count
    of q over the intervals flown before the root (``past_sum``, ``past_count``), and the
    levels the tree may grow below the root (``max_depth``)."""

    c: float
    rollout: int
    epsilon: float
    return_kind: int
    past_sum: float
    past_count: int
    max_depth: int


@jit_borrow
def _untried(children: np.ndarray, visits: np.ndarray, node: int, a: int) -> bool:
    """Action a has not been tried at ``node``: no child, or a child kept from a reused
    tree with its statistics decayed to nothing."""
    child = children[node, a]
    return child == UNVISITED or visits[child] <= 0.0


@jit_borrow
def _untried_best(children: np.ndarray, visits: np.ndarray, node: int, qvals: np.ndarray) -> int:
    """The allowed action not yet tried that has the largest immediate q; -1 if none.

    Expanding the most promising action first is a cheap prior: with K children a level
    and few iterations, the tree then spends them where they matter."""
    best = -1
    best_q = -math.inf
    for a in range(qvals.shape[0]):
        if _untried(children, visits, node, a) and qvals[a] > best_q:
            best = a
            best_q = qvals[a]
    return best


@jit_borrow
def _expand(tree: TreeArrays, num_nodes: int, node: int, a: int) -> int:
    """The child of ``node`` for action a, made (as node ``num_nodes``) if it has none."""
    child = tree.children[node, a]
    if child == UNVISITED:
        child = num_nodes
        tree.parent[child] = node
        tree.action[child] = a
        tree.children[child, :] = UNVISITED
        tree.visits[child] = 0.0
        tree.value_sum[child] = 0.0
        tree.children[node, a] = child
    return child


@jit_borrow
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


@jit_borrow
def random_allowed(qvals: np.ndarray, allowed: int, rng: np.random.Generator) -> int:
    """A uniform draw among the ``allowed`` actions (those with a finite q)."""
    pick = draw_int(rng, 0, allowed)
    for a in range(qvals.shape[0]):
        if qvals[a] > -math.inf:
            if pick == 0:
                return a
            pick -= 1
    return -1


@jit_borrow
def rollout_action(qvals: np.ndarray, allowed: int, policy: int, epsilon: float, rng: np.random.Generator) -> int:
    """A playout step: uniform among allowed actions, or epsilon-greedy on q."""
    if policy == ROLLOUT_EPSILON_GREEDY and rng.random() >= epsilon:
        return int(np.argmax(qvals))
    return random_allowed(qvals, allowed, rng)


class Scratch(NamedTuple):
    """A search's working arrays: the playout's world ``w``, every action's q and user at
    a step (``qvals``, ``users_at`` (K,)), the steps' rewards (``rewards`` (H,)) and their
    suffix sums (``suffix`` (H + 1,)), the nodes entered (``path`` (H + 1,)), the users
    served (``touched`` (H,)) and their marks (``flag`` (I,)), a fresh step's chance
    (``moves`` (I, 3), ``news`` (I,)), the points a step leaves out (``skip`` (K,)) and
    where a fresh step's flight began (``origin`` (3,))."""

    w: World
    qvals: np.ndarray
    users_at: np.ndarray
    rewards: np.ndarray
    suffix: np.ndarray
    path: np.ndarray
    touched: np.ndarray
    flag: np.ndarray
    moves: np.ndarray
    news: np.ndarray
    skip: np.ndarray
    origin: np.ndarray


@jit
def search(scene: Scene, tree: TreeArrays, num_nodes: int, root: World, settings: SearchSettings,
           index: FutureIndex, iterations: int, rng: np.random.Generator) -> int:
    """Run ``iterations`` iterations from ``root`` (not changed); returns the new node count.

    ``index`` holds the S futures of the decision (S may be 0: each step then draws its
    chance from ``rng``); the n-th visit of a root child plays future n mod S. The tree
    grows at most ``settings.max_depth`` levels below the root; past them the playout policy
    decides. The tree arrays must have room for ``iterations`` more nodes (one expansion
    per iteration at most)."""
    num_actions = scene.hover_points.shape[0]
    horizon = 1 + remaining_intervals(scene.p, root.users.shape[0], root.interval[0])
    scratch = Scratch(clone(root), np.empty(num_actions), np.empty(num_actions, dtype=np.int64), np.empty(horizon),
                      np.empty(horizon + 1), np.empty(horizon + 1, dtype=np.int64), np.zeros(horizon, dtype=np.int64),
                      np.zeros(root.users.shape[0], dtype=np.bool_), np.empty_like(root.users),
                      np.empty_like(root.tasks), np.zeros(num_actions, dtype=np.bool_), np.empty(3))
    return _iterate(scene, tree, num_nodes, root, settings, index, iterations, rng, scratch)


@jit_borrow
def _iterate(scene: Scene, tree: TreeArrays, num_nodes: int, root: World, settings: SearchSettings,
             index: FutureIndex, iterations: int, rng: np.random.Generator, scratch: Scratch) -> int:
    """``search``'s iterations, in the arrays of ``scratch`` (allocated by ``search``: in
    here nothing is reference-counted, see ``model._jit.jit_borrow``). Each step is played by
    ``_play`` and each iteration's returns backed up by ``_backup``, both compiled into this
    loop (``jit_inline``, scalars and arrays): measured at no cost. Selection and the
    playout's choice stay inline: as inlined functions too they measured 1.05-1.10x slower."""
    p = scene.p
    parent, action, children, visits, value_sum = tree
    w, qvals, users_at, rewards, suffix, path, touched, flag, moves, news, skip, origin = scratch
    limit = int(p[P.MAX_INTERVALS])
    num_futures = index.moves.shape[0]
    steps = 0
    for _ in range(iterations):
        future = -1
        for j in range(steps):  # forget the last iteration's served users
            flag[touched[j]] = False
        copy_into(w, root)
        node = ROOT_INDEX
        path[0] = ROOT_INDEX
        depth = 1
        steps = 0
        in_tree = True
        energy, q = 0.0, 0.0
        while limit <= 0 or w.interval[0] < limit:
            if future >= 0 and steps > 0:  # the users are where the future's row has them
                fill_rows(scene, index, root, future, steps)
                ws = World(w.uav_xyz, w.hover, index.row_users[future, steps], w.tasks, w.served, w.battery_j,
                           w.interval, w.energy_used_j, w.reward_sum)
            else:
                ws = w
            if in_tree and depth > settings.max_depth:
                in_tree = False
            priced = future >= 0 and steps > 0  # the index gives the step's energy and q
            if priced and in_tree:  # the tree's step, asking as few points as it can
                for b in range(skip.shape[0]):
                    skip[b] = not _untried(children, visits, node, b)
                a, user, energy, q = greedy_future(scene, index, root, future, steps, ws, touched, flag, skip)
                if a >= 0:  # the untried allowed point of largest q (``_untried_best``)
                    child = _expand(tree, num_nodes, node, a)
                    num_nodes += child == num_nodes
                    in_tree = False
                else:  # every allowed point tried: UCT needs to know only which are allowed
                    allowed = allowed_future(scene, index, root, future, steps, ws, touched, flag, qvals)
                    if allowed == 0:
                        break
                    child = _uct_child(children, node, qvals, visits, value_sum, settings.c)
                    a = action[child]
                    user, energy, q = point_user(scene, index, future, steps, a, ws, touched, flag)
                node = child
                path[depth] = node
                depth += 1
            elif priced and settings.rollout == ROLLOUT_EPSILON_GREEDY:
                # the greedy step needs only the best point (``greedy_future``), the
                # uniform one (drawn as ``rollout_action`` draws it) which points are allowed
                for b in range(skip.shape[0]):
                    skip[b] = False
                a, user, energy, q = greedy_future(scene, index, root, future, steps, ws, touched, flag, skip)
                if a < 0:
                    break
                if rng.random() < settings.epsilon:
                    allowed = allowed_future(scene, index, root, future, steps, ws, touched, flag, qvals)
                    a = random_allowed(qvals, allowed, rng)
                    user, energy, q = point_user(scene, index, future, steps, a, ws, touched, flag)
            else:
                priced = False
                allowed = evaluate_step(scene, index, root, ws, future, steps, touched, flag, qvals, users_at)
                if allowed == 0:
                    break
                if in_tree:
                    a = _untried_best(children, visits, node, qvals)
                    if a >= 0:
                        child = _expand(tree, num_nodes, node, a)
                        num_nodes += child == num_nodes
                        in_tree = False
                    else:
                        child = _uct_child(children, node, qvals, visits, value_sum, settings.c)
                        a = action[child]
                    if depth == 1 and num_futures > 0:
                        future = int(visits[child] + 0.5) % num_futures
                    node = child
                    path[depth] = node
                    depth += 1
                else:
                    a = rollout_action(qvals, allowed, settings.rollout, settings.epsilon, rng)
                user = users_at[a]
            _play(scene, index, w, ws, a, user, energy, q, priced, future, steps, touched, flag, rewards, moves, news,
                  origin, rng)
            steps += 1
        _backup(visits, value_sum, path, rewards, suffix, depth, steps, settings)
    return num_nodes


@jit_inline
def _play(scene: Scene, index: FutureIndex, w: World, ws: World, a: int, user: int, energy: float, q: float,
          priced: bool, future: int, steps: int, touched: np.ndarray, flag: np.ndarray, rewards: np.ndarray,
          moves: np.ndarray, news: np.ndarray, origin: np.ndarray, rng: np.random.Generator) -> None:
    """Step ``steps`` played at point a in ``ws`` (the iteration's world ``w``, or its view
    on the future's row of users): served (``settle`` with the index's energy and q when
    ``priced``, else ``serve``), its user and reward recorded, then the world advanced by
    the future's chance, or by a fresh draw for the interval's duration."""
    p = scene.p
    if priced:
        settle(scene, ws, a, user, energy, q)
        duration = 0.0  # unused: the shared futures hold the arrivals
    else:
        for c in range(3):
            origin[c] = ws.uav_xyz[c]
        out = serve(scene, ws, a, user)
        user, q = out.user, out.reward
        duration = _duration(p, origin, scene.hover_points[a], ws.users, user, out.bits)
    touched[steps] = user
    flag[user] = True
    rewards[steps] = q
    if future >= 0:  # only the tasks: the next row has the users' moves
        advance(scene, ws, index.moves[future, steps, :0], index.news[future, steps])
    else:
        draw_chance_after(p, moves, news, duration, rng)
        advance(scene, w, moves, news)


@jit_inline
def _backup(visits: np.ndarray, value_sum: np.ndarray, path: np.ndarray, rewards: np.ndarray, suffix: np.ndarray,
            depth: int, steps: int, settings: SearchSettings) -> None:
    """The iteration's returns backed up the ``depth`` nodes of ``path``, from the ``steps``
    rewards: node ``path[j]`` is entered by step j - 1 and gets the objective from there."""
    suffix[steps] = 0.0
    for k in range(steps - 1, -1, -1):
        suffix[k] = suffix[k + 1] + rewards[k]
    for j in range(depth):
        first = j - 1 if j > 0 else 0
        ret = node_return(settings.return_kind, suffix[first], steps - first, suffix[0], steps,
                          settings.past_sum, settings.past_count)
        visits[path[j]] += 1.0
        value_sum[path[j]] += ret


@jit_borrow
def _duration(p: np.ndarray, origin: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, user: int,
              bits: float) -> float:
    """How long a fresh step's interval lasted (only read when tasks arrive in time)."""
    if not in_time(p):
        return 0.0
    return interval_duration_s(p, origin, hover_xyz, users[user] if user != NO_USER else hover_xyz, bits)


@jit
def draw_futures(p: np.ndarray, moves: np.ndarray, news: np.ndarray, rng: np.random.Generator) -> None:
    """Fill S futures of H steps of chance: ``moves`` (S, H, I, 3), ``news`` (S, H, I),
    each step drawn as the environment draws it."""
    for s in range(moves.shape[0]):
        for h in range(moves.shape[1]):
            draw_chance(p, moves[s, h], news[s, h], rng)


@jit
def paired_rollouts(scene: Scene, root: World, first: int, second: int, settings: SearchSettings,
                    index: FutureIndex, out: np.ndarray) -> None:
    """Action ``first``, then the greedy policy, and action ``second``, then the greedy
    policy, on each of the index's S futures: ``out`` (S, 2) receives the two returns (of
    the first step's node, as ``search`` backs up)."""
    horizon = 1 + remaining_intervals(scene.p, root.users.shape[0], root.interval[0])
    _paired(scene, root, first, second, settings, index, out, clone(root), np.zeros(horizon, dtype=np.int64),
            np.zeros(root.users.shape[0], dtype=np.bool_), np.zeros(scene.hover_points.shape[0], dtype=np.bool_))


@jit_borrow
def _paired(scene: Scene, root: World, first: int, second: int, settings: SearchSettings, index: FutureIndex,
            out: np.ndarray, w: World, touched: np.ndarray, flag: np.ndarray, skip: np.ndarray) -> None:
    """``paired_rollouts`` in the world and arrays it is given (``skip`` (K,) all False)."""
    limit = int(scene.p[P.MAX_INTERVALS])
    steps = 0
    for s in range(index.moves.shape[0]):
        for k in range(2):
            for j in range(steps):
                flag[touched[j]] = False
            copy_into(w, root)
            total = 0.0
            steps = 0
            while limit <= 0 or w.interval[0] < limit:
                if steps == 0:  # the root's step: the action paired, priced by ``serve``
                    if index.root_allowed[0] == 0:
                        break
                    ws = w
                    a = first if k == 0 else second
                    step_out = serve(scene, ws, a, index.root_user[a])
                    user, q = step_out.user, step_out.reward
                else:  # greedy along the future, priced by the index
                    fill_rows(scene, index, root, s, steps)
                    ws = World(w.uav_xyz, w.hover, index.row_users[s, steps], w.tasks, w.served, w.battery_j,
                               w.interval, w.energy_used_j, w.reward_sum)
                    a, user, energy, q = greedy_future(scene, index, root, s, steps, ws, touched, flag, skip)
                    if a < 0:
                        break
                    settle(scene, ws, a, user, energy, q)
                touched[steps] = user
                flag[user] = True
                total += q
                advance(scene, ws, index.moves[s, steps, :0], index.news[s, steps])
                steps += 1
            out[s, k] = node_return(settings.return_kind, total, steps, total, steps, settings.past_sum,
                                    settings.past_count)


@jit
def paired_fresh(scene: Scene, root: World, first: int, second: int, settings: SearchSettings, index: FutureIndex,
                 moves: np.ndarray, uniforms: np.ndarray, out: np.ndarray) -> None:
    """``paired_rollouts`` when the futures cannot be shared (tasks that arrive in time):
    each step evaluated afresh (``evaluate_tree``), on S futures given as the users' moves
    ``moves`` (S, H, I, 3) and the arrivals' uniforms ``uniforms`` (S, H, I), which both
    actions of a pair use: each interval's arrivals are the Poisson quantiles of its
    duration's mean (``poisson_quantile``), common random numbers whatever the timings.
    ``index`` gives the root's values and a tree to refit (its futures are not read)."""
    num_actions = scene.hover_points.shape[0]
    _paired_fresh(scene, root, first, second, settings, index, moves, uniforms, out, clone(root),
                  np.empty(num_actions), np.empty(num_actions, dtype=np.int64),
                  np.empty(root.users.shape[0], dtype=np.int64), np.empty(3))


@jit_borrow
def _paired_fresh(scene: Scene, root: World, first: int, second: int, settings: SearchSettings, index: FutureIndex,
                  moves: np.ndarray, uniforms: np.ndarray, out: np.ndarray, w: World, qvals: np.ndarray,
                  users_at: np.ndarray, news: np.ndarray, origin: np.ndarray) -> None:
    """``paired_fresh`` in the world and arrays it is given."""
    p = scene.p
    limit = int(p[P.MAX_INTERVALS])
    horizon = moves.shape[1]
    for s in range(moves.shape[0]):
        for k in range(2):
            copy_into(w, root)
            total = 0.0
            steps = 0
            while (limit <= 0 or w.interval[0] < limit) and steps <= horizon:
                if steps == 0:  # the root's step: the action paired
                    if index.root_allowed[0] == 0:
                        break
                    a = first if k == 0 else second
                    user = index.root_user[a]
                else:  # greedy: the largest q, the first of equals
                    refit_tree(w.users, index.tree)
                    if evaluate_tree(scene, w, index.tree, index.home, qvals, users_at) == 0:
                        break
                    a = int(np.argmax(qvals))
                    user = users_at[a]
                for c in range(3):
                    origin[c] = w.uav_xyz[c]
                step_out = serve(scene, w, a, user)
                total += step_out.reward
                if steps < horizon:
                    mean = arrival_mean(p, _duration(p, origin, scene.hover_points[a], w.users, user, step_out.bits))
                    for i in range(news.shape[0]):
                        news[i] = poisson_quantile(mean, uniforms[s, steps, i])
                    advance(scene, w, moves[s, steps], news)
                steps += 1
            out[s, k] = node_return(settings.return_kind, total, steps, total, steps, settings.past_sum,
                                    settings.past_count)
