"""Every action's reward at a playout step, without scoring every point against every user.

A playout step needs, for the hovering points it considers, q and the user served there;
scanned plainly, K x I distances a step. What makes it cheaper without changing a result:

- **The futures fix the users.** The users' moves and task draws do not depend on what
  the UAV does, so along sampled future s the users' positions at step h are the same in
  every iteration that plays s. Only the service counts (and, under the backlog model,
  the served users' tasks) depend on the actions, and only for the users this iteration
  has served: at most one a step. So each future keeps *rows*: the users and their tasks
  after h steps (a playout's world reads the positions from there instead of moving every
  user itself) and the k-d tree of them (``model.user_tree``: built once on the root's
  users, a row only refits its boxes). Per hovering point, a row keeps the answer on the
  *trajectory* (the row's users with the root's service counts): the user served, the
  energy of its upload and its task term of q, and the reach of its tie window, computed
  the first time a step asks for that point.
- **Only the touched users can change an answer.** A user's eligibility can only fall
  when it is served (the fairness rule (3) is monotone in the service count, and a served
  backlog only shrinks), so the users eligible at (s, h) in an iteration are those of the
  trajectory, less some of the users the iteration served. An answer changes only if one
  of those lies inside its tie window; then, and only then, the point is asked again: from
  the row's list of the point's M nearest eligible users on the trajectory (skipping the
  touched users no longer eligible), or, when that list cannot settle it, through the
  row's tree, which answers exactly as the plain scan does. Upload energies are kept per
  listed user, computed when first needed.
- **Most steps need few points.** A greedy step needs only the point of largest q, and no
  service adds more to q than ``serve_ub`` (u_max tasks from straight below the point), so
  only the points whose bound, less the flight's share, reaches the best q found are asked
  (``greedy_future``). Whether a point is allowed depends on its user only through the
  service's energy, bounded above and below per point (``cost_ub``, ``cost_lb``), so a
  uniform step or a UCT step asks only the points those bounds cannot settle
  (``allowed_future``).

The flight energy between hovering points and home is a table. Every number is computed by
the same expressions as ``model.interval.evaluate_actions``, and the bounds carry margins
far above rounding, so the rewards are equal to the last bit and the search takes the same
decisions (``tests/mcts/test_futures.py`` compares every kernel here with the plain
evaluation along random playouts; ``mcts/reference.py`` stays the plain specification).

With no shared futures (``MctsConfig.futures = 0``) each step's chance is fresh: the step
refits the root's tree to the users where they are and asks every point through it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..model import params as P
from ..model._jit import jit_borrow, jit_inline
from ..model.channel import distance_sq_m2
from ..model.fairness import is_eligible
from ..model.interval import NO_USER, budget_ok, hop_energy_j, return_energy_j, service_cost, user_outcome
from ..model.reward import reward_of, task_reward
from ..model.user_tree import (UserTree, empty_tree, fill_tree, refit_tree, tree_nearest, tree_nearest_list,
                               tree_window_choice)
from ..model.world import Scene, World, advance


NEAREST = 6
"""M: users listed per point and row (the nearest eligible on the trajectory). Enough for
the tie window and the touched users in it almost always; the tree answers otherwise."""


class FutureIndex(NamedTuple):
    """The shared futures of one decision and the answers along them.

    S futures of H steps, I users, K points, N nodes of a users' tree, M = ``NEAREST``.
    Futures: ``moves`` (S, H, I, 3), ``news`` (S, H, I). Rows h = 1..H of each future are
    filled when a playout first reaches them (row 0 is the root, kept in ``root_*``), and
    a row answers each point when first asked: ``ready`` (S,) rows filled; ``row_users``
    (S, H + 1, I, 3), ``row_tasks`` (S, H + 1, I) the users on the trajectory at each row,
    ``row_eligible`` (S, H + 1) how many of them may be served; the users' tree built at
    the root (``tree``: its ``order`` and ``span`` serve every row) and each row's boxes
    ``box`` (S, H + 1, N, 6). Per point, on the trajectory: ``answered`` (S, H + 1, K) the
    answer is computed, ``user`` (S, H + 1, K) served, ``cost`` (e_hover + e_comp of that
    service), ``gain`` (its task term of q), ``reach_sq`` (its tie window); ``window`` how
    many listed users the window holds (-1: not all listed); ``near_user``, ``near_d2``,
    ``near_cost`` (S, H + 1, K, M) the nearest eligible users in (distance, index) order,
    their squared distance and upload energy (NaN until first needed), ``near_count``
    (S, H + 1, K) how many, ``near_cover`` every eligible user nearer than this squared
    distance is listed. Tables: ``hop`` (K, K) flight energy between points, ``home`` (K,)
    flight home, ``hop_q`` (K, K) the flight's share of q (``hop`` / w_max); bounds
    (``service_bounds``): ``serve_ub`` (K,) on what a service at each point adds to q,
    ``cost_ub`` and ``cost_lb`` (K,) on its energy. The root: ``root_q`` (K,), ``root_user`` (K,),
    ``root_allowed`` (1,). ``tree``: the root's tree (its boxes are refitted at a fresh
    step). ``served0`` (I,): the root's service counts; ``clock`` (1,): scratch for a
    row's interval.
    """

    moves: np.ndarray
    news: np.ndarray
    ready: np.ndarray
    row_users: np.ndarray
    row_tasks: np.ndarray
    row_eligible: np.ndarray
    box: np.ndarray
    answered: np.ndarray
    user: np.ndarray
    cost: np.ndarray
    gain: np.ndarray
    reach_sq: np.ndarray
    window: np.ndarray
    near_user: np.ndarray
    near_d2: np.ndarray
    near_cost: np.ndarray
    near_count: np.ndarray
    near_cover: np.ndarray
    hop: np.ndarray
    home: np.ndarray
    hop_q: np.ndarray
    serve_ub: np.ndarray
    cost_ub: np.ndarray
    cost_lb: np.ndarray
    root_q: np.ndarray
    root_user: np.ndarray
    root_allowed: np.ndarray
    tree: UserTree
    served0: np.ndarray
    clock: np.ndarray


@jit_borrow
def point_tables(p: np.ndarray, hover_points: np.ndarray, hop: np.ndarray, home: np.ndarray,
                 hop_q: np.ndarray) -> None:
    """``hop`` (K, K): flight energy from point j to point k, and ``hop_q`` its share of q
    (over w_max); ``home`` (K,): from each point back to base (``interval.hop_energy_j``,
    ``interval.return_energy_j``)."""
    for j in range(hover_points.shape[0]):
        home[j] = return_energy_j(p, hover_points[j])
        for k in range(hover_points.shape[0]):
            hop[j, k] = hop_energy_j(p, hover_points[j], hover_points[k])
            hop_q[j, k] = hop[j, k] / p[P.ENERGY_NORM]


@jit_borrow
def service_bounds(p: np.ndarray, hover_points: np.ndarray, tasks_cap: int, box: np.ndarray, at: np.ndarray,
                   out_gain: np.ndarray, out_cost: np.ndarray, out_cost_lb: np.ndarray) -> None:
    """Bounds on a service from each point by a user with at most ``tasks_cap`` tasks
    inside ``box`` (x lo, x hi, y lo, y hi, z lo, z hi). ``out_gain`` (K,): no service adds
    more to q (q = the task term less the interval's energy over w_max, the flight's
    included): the task term and the service's own energy (hover, computation) both grow in
    proportion to the tasks and the rate falls with the distance, so at most that of
    ``tasks_cap`` tasks from the nearest place in the box, or nothing. ``out_cost`` (K,):
    no service costs more energy than ``tasks_cap`` tasks from the box's farthest corner;
    ``out_cost_lb`` (K,): none costs less than one task (an eligible user has one at
    least) from the nearest place. ``at`` (3,) is scratch."""
    for k in range(hover_points.shape[0]):
        for a in range(3):
            at[a] = min(max(hover_points[k, a], box[2 * a]), box[2 * a + 1])
        bits, e_h, e_c = service_cost(p, hover_points[k], at, tasks_cap)
        out_gain[k] = max(task_reward(p, tasks_cap) - (e_h + e_c) / p[P.ENERGY_NORM], 0.0)
        bits, e_h, e_c = service_cost(p, hover_points[k], at, 1)
        out_cost_lb[k] = e_h + e_c
        for a in range(3):
            lo, hi = box[2 * a], box[2 * a + 1]
            at[a] = lo if abs(hover_points[k, a] - lo) > abs(hover_points[k, a] - hi) else hi
        bits, e_h, e_c = service_cost(p, hover_points[k], at, tasks_cap)
        out_cost[k] = e_h + e_c


@jit_borrow
def evaluate_tree(scene: Scene, w: World, t: UserTree, home: np.ndarray, out_q: np.ndarray,
                  out_user: np.ndarray) -> int:
    """``interval.evaluate_actions`` on ``w`` through the tree ``t`` of its users (already
    filled), also giving the user each point serves (``out_user``); returns how many
    points are allowed."""
    p = scene.p
    hp = scene.hover_points
    stay = p[P.ALLOW_STAY] > 0.5
    allowed = 0
    for k in range(hp.shape[0]):
        out_q[k] = -math.inf
        out_user[k] = NO_USER
        if k == w.hover[0] and not stay:
            continue
        user, _ = tree_nearest(p, hp[k], w.users, w.tasks, w.served, t)
        if user == NO_USER:
            continue
        bits, e_h, e_c, e_f, q = user_outcome(p, w.uav_xyz, hp[k], w.users[user], w.tasks[user])
        if not budget_ok(p, w.battery_j[0], e_h + e_c + e_f, home[k]):
            continue
        out_q[k] = q
        out_user[k] = user
        allowed += 1
    return allowed


@jit_inline
def fill_rows(scene: Scene, idx: FutureIndex, root: World, s: int, h: int) -> None:
    """Fill future s's rows up to h (``_fill_rows``), if not yet done."""
    if idx.ready[s] < h:
        _fill_rows(scene, idx, root, s, h)


@jit_borrow
def _fill_rows(scene: Scene, idx: FutureIndex, root: World, s: int, h: int) -> None:
    """Fill future s's rows up to h: each steps the trajectory of the row before on
    (``world.advance``) and indexes it; its points are answered when first asked."""
    p = scene.p
    while idx.ready[s] < h:
        row = idx.ready[s] + 1
        users = idx.row_users[s, row]
        tasks = idx.row_tasks[s, row]
        before_users = idx.row_users[s, row - 1] if row > 1 else root.users
        before_tasks = idx.row_tasks[s, row - 1] if row > 1 else root.tasks
        for i in range(users.shape[0]):
            for a in range(3):
                users[i, a] = before_users[i, a]
            tasks[i] = before_tasks[i]
        idx.clock[0] = root.interval[0] + row  # the interval due after `row` steps (a task table's row)
        traj = World(root.uav_xyz, root.hover, users, tasks, idx.served0, root.battery_j, idx.clock,
                     root.energy_used_j, root.reward_sum)
        advance(scene, traj, idx.moves[s, row - 1], idx.news[s, row - 1])
        refit_tree(users, UserTree(idx.tree.order, idx.tree.span, idx.box[s, row], idx.tree.stack, idx.tree.bounds))
        eligible = 0
        for i in range(users.shape[0]):
            eligible += is_eligible(p, tasks[i], idx.served0[i])
        idx.row_eligible[s, row] = eligible
        for k in range(idx.answered.shape[2]):
            idx.answered[s, row, k] = False
        idx.ready[s] = row


@jit_borrow
def _answer_point(p: np.ndarray, hp: np.ndarray, idx: FutureIndex, s: int, h: int, k: int) -> None:
    """Point k's answer on row h of future s: its listed nearest eligible users on the
    trajectory and the one it serves."""
    users = idx.row_users[s, h]
    tasks = idx.row_tasks[s, h]
    served = idx.served0
    t = UserTree(idx.tree.order, idx.tree.span, idx.box[s, h], idx.tree.stack, idx.tree.bounds)
    idx.answered[s, h, k] = True
    near_user = idx.near_user[s, h, k]
    near_d2 = idx.near_d2[s, h, k]
    size = near_user.shape[0]
    for j in range(size):
        idx.near_cost[s, h, k, j] = math.nan
    count, cover = tree_nearest_list(p, hp[k], users, tasks, served, t, near_user, near_d2)
    idx.near_count[s, h, k] = count
    idx.near_cover[s, h, k] = cover
    if count == 0:
        idx.user[s, h, k] = NO_USER
        idx.reach_sq[s, h, k] = math.inf
        idx.window[s, h, k] = 0
        return
    reach = math.sqrt(near_d2[0]) + p[P.TIE_M]  # as interval.nearest_eligible
    reach_sq = reach * reach
    inside = 0
    while inside < count and near_d2[inside] <= reach_sq:
        inside += 1
    if inside < count or count < size or reach_sq < cover:  # the whole window is listed
        chosen = 0
        for j in range(1, inside):
            u, c = near_user[j], near_user[chosen]
            if tasks[u] > tasks[c] or (tasks[u] == tasks[c] and u < c):
                chosen = j
        user = near_user[chosen]
        idx.window[s, h, k] = inside
    else:  # a crowd within the window: choose among it through the tree
        user = tree_window_choice(p, hp[k], users, tasks, served, t, reach_sq)
        chosen = -1
        idx.window[s, h, k] = -1
    bits, e_h, e_c = service_cost(p, hp[k], users[user], tasks[user])
    idx.user[s, h, k] = user
    idx.reach_sq[s, h, k] = reach_sq
    idx.cost[s, h, k] = e_h + e_c
    idx.gain[s, h, k] = task_reward(p, tasks[user])
    if chosen >= 0:
        idx.near_cost[s, h, k, chosen] = e_h + e_c


@jit_borrow
def _listed_choice(p: np.ndarray, idx: FutureIndex, s: int, h: int, k: int, w: World, flag: np.ndarray) -> int:
    """The listed user point k serves in ``w`` (as ``interval.nearest_eligible`` would):
    its list position, -1 for nobody, or -2 when the list cannot tell."""
    near_user = idx.near_user[s, h, k]
    near_d2 = idx.near_d2[s, h, k]
    count = idx.near_count[s, h, k]
    chosen = -1
    reach_sq = math.inf
    for j in range(count):
        if chosen >= 0 and near_d2[j] > reach_sq:
            return chosen  # every farther user, listed or not, is outside the window
        u = near_user[j]
        if flag[u] and not is_eligible(p, w.tasks[u], w.served[u]):
            continue
        if chosen < 0:
            reach = math.sqrt(near_d2[j]) + p[P.TIE_M]
            reach_sq = reach * reach
            chosen = j
        else:
            c = near_user[chosen]
            if w.tasks[u] > w.tasks[c] or (w.tasks[u] == w.tasks[c] and u < c):
                chosen = j
    if count < near_user.shape[0] or (chosen >= 0 and reach_sq < idx.near_cover[s, h, k]):
        return chosen
    return -2


@jit_inline
def _future_value(p: np.ndarray, hp: np.ndarray, idx: FutureIndex, s: int, h: int, k: int, w: World,
                  touched: np.ndarray, flag: np.ndarray) -> tuple[float, int, float]:
    """Point k's q, user and the interval's energy (service and flight) in ``w`` (see
    ``evaluate_future``); (-inf, ``NO_USER``, 0) where the action is not allowed. The
    caller excludes staying where staying is not allowed."""
    if not idx.answered[s, h, k]:
        _answer_point(p, hp, idx, s, h, k)
    user = idx.user[s, h, k]
    if user == NO_USER:  # nobody eligible on the trajectory: nobody now either
        return -math.inf, NO_USER, 0.0
    window = idx.window[s, h, k]
    dirty = False
    if window >= 0:
        for j in range(window):
            if flag[idx.near_user[s, h, k, j]]:
                dirty = True
                break
    else:
        for j in range(h):
            if distance_sq_m2(hp[k], w.users[touched[j]]) <= idx.reach_sq[s, h, k]:
                dirty = True
                break
    if not dirty:
        cost = idx.cost[s, h, k]
        gain = idx.gain[s, h, k]
    else:
        j = _listed_choice(p, idx, s, h, k, w, flag)
        if j == -1:
            return -math.inf, NO_USER, 0.0
        if j >= 0:
            user = idx.near_user[s, h, k, j]
            cost = idx.near_cost[s, h, k, j]
        else:
            user, _ = tree_nearest(p, hp[k], w.users, w.tasks, w.served,
                                   UserTree(idx.tree.order, idx.tree.span, idx.box[s, h], idx.tree.stack,
                                            idx.tree.bounds))
            if user == NO_USER:
                return -math.inf, NO_USER, 0.0
            cost = math.nan
        same = w.tasks[user] == idx.row_tasks[s, h, user]  # a served user's tasks may differ from the trajectory's
        if not same or cost != cost:
            bits, e_h, e_c = service_cost(p, hp[k], w.users[user], w.tasks[user])
            cost = e_h + e_c
            if j >= 0 and same:
                idx.near_cost[s, h, k, j] = cost
        gain = task_reward(p, w.tasks[user])
    prev = w.hover[0]
    energy = cost + idx.hop[prev, k]
    if not budget_ok(p, w.battery_j[0], energy, idx.home[k]):
        return -math.inf, NO_USER, 0.0
    return reward_of(p, gain, energy), user, energy


@jit_borrow
def evaluate_future(scene: Scene, idx: FutureIndex, root: World, s: int, h: int, w: World, touched: np.ndarray,
                    flag: np.ndarray, out_q: np.ndarray, out_user: np.ndarray) -> int:
    """``evaluate_tree`` for ``w``, the state after h >= 1 steps of future s from ``root``
    in which the users ``touched[:h]`` (``flag`` set) were served."""
    fill_rows(scene, idx, root, s, h)
    p = scene.p
    hp = scene.hover_points
    stay = p[P.ALLOW_STAY] > 0.5
    prev = w.hover[0]
    allowed = 0
    for k in range(hp.shape[0]):
        out_q[k] = -math.inf
        out_user[k] = NO_USER
        if k == prev and not stay:
            continue
        q, user, _ = _future_value(p, hp, idx, s, h, k, w, touched, flag)
        if q > -math.inf:
            out_q[k] = q
            out_user[k] = user
            allowed += 1
    return allowed


@jit_inline
def greedy_future(scene: Scene, idx: FutureIndex, root: World, s: int, h: int, w: World, touched: np.ndarray,
                  flag: np.ndarray, skip: np.ndarray) -> tuple[int, int, float, float]:
    """The point of largest q in ``w`` (the first of equals, as ``np.argmax`` over
    ``evaluate_future``'s q), its user, the interval's energy and q, among the points
    ``skip`` (K,) does not mark; (-1, ``NO_USER``, 0, -inf) if none of them is allowed.

    A point's q is at most ``serve_ub`` less its flight's share, so only the points whose
    bound reaches the best q found so far, and whose budget holds with the least a service
    there can cost, are evaluated: the one with the largest bound first, then every other
    in order. With many points most are never asked."""
    fill_rows(scene, idx, root, s, h)
    p = scene.p
    hp = scene.hover_points
    stay = p[P.ALLOW_STAY] > 0.5
    prev = w.hover[0]
    hop_q = idx.hop_q[prev]
    first = -1
    first_ub = -math.inf
    for k in range(hp.shape[0]):
        ub = idx.serve_ub[k] - hop_q[k]
        if ub > first_ub and (k != prev or stay) and not skip[k]:
            first = k
            first_ub = ub
    best = -1
    best_q = -math.inf
    best_user = NO_USER
    best_energy = 0.0
    if first >= 0:
        q, user, energy = _future_value(p, hp, idx, s, h, first, w, touched, flag)
        if q > -math.inf:
            best, best_q, best_user, best_energy = first, q, user, energy
    battery = w.battery_j[0]
    for k in range(hp.shape[0]):
        if k == first or (k == prev and not stay) or skip[k] or idx.serve_ub[k] - hop_q[k] < best_q:
            continue  # q < best_q: not the largest, nor tied with it
        if not budget_ok(p, battery, idx.cost_lb[k] + idx.hop[prev, k], idx.home[k]):
            continue  # not allowed whoever it serves
        q, user, energy = _future_value(p, hp, idx, s, h, k, w, touched, flag)
        if q > best_q or (q == best_q and q > -math.inf and k < best):
            best, best_q, best_user, best_energy = k, q, user, energy
    return best, best_user, best_energy, best_q


@jit_borrow
def allowed_future(scene: Scene, idx: FutureIndex, root: World, s: int, h: int, w: World, touched: np.ndarray,
                   flag: np.ndarray, out_allowed: np.ndarray) -> int:
    """Which points ``evaluate_future`` would allow (``out_allowed`` (K,): 0.0 where
    allowed, -inf where not), and how many, asking as few points as it can.

    Whether a point is allowed depends on its user only through the service's energy: if
    anyone may be served, every point serves someone, and the budget then decides. Nobody
    eligible on the row means nobody now; otherwise the users this playout served are the
    only ones who may have left the row's eligible. A point whose budget holds with the
    most a service there can cost (``cost_ub``) is allowed, one whose budget fails with
    the least (``cost_lb``) is not; only the points in between are asked."""
    fill_rows(scene, idx, root, s, h)
    p = scene.p
    hp = scene.hover_points
    stay = p[P.ALLOW_STAY] > 0.5
    prev = w.hover[0]
    battery = w.battery_j[0]
    eligible = idx.row_eligible[s, h]
    for j in range(h):  # each served user once: was it eligible on the row, and is it no longer?
        u = touched[j]
        first = True
        for i in range(j):
            if touched[i] == u:
                first = False
                break
        if first and is_eligible(p, idx.row_tasks[s, h, u], idx.served0[u]) and not is_eligible(p, w.tasks[u], w.served[u]):
            eligible -= 1
    allowed = 0
    for k in range(hp.shape[0]):
        out_allowed[k] = -math.inf
        if eligible == 0 or (k == prev and not stay):
            continue
        hop = idx.hop[prev, k]
        if budget_ok(p, battery, idx.cost_ub[k] + hop, idx.home[k]):
            ok = True
        elif not budget_ok(p, battery, idx.cost_lb[k] + hop, idx.home[k]):
            ok = False
        else:
            q, user, _ = _future_value(p, hp, idx, s, h, k, w, touched, flag)
            ok = q > -math.inf
        if ok:
            out_allowed[k] = 0.0
            allowed += 1
    return allowed


@jit_borrow
def point_user(scene: Scene, idx: FutureIndex, s: int, h: int, k: int, w: World, touched: np.ndarray,
               flag: np.ndarray) -> tuple[int, float, float]:
    """The user point k serves in ``w`` (``evaluate_future``'s), the interval's energy and
    q; row h already filled."""
    q, user, energy = _future_value(scene.p, scene.hover_points, idx, s, h, k, w, touched, flag)
    return user, energy, q


@jit_inline
def evaluate_step(scene: Scene, idx: FutureIndex, root: World, w: World, future: int, steps: int,
                  touched: np.ndarray, flag: np.ndarray, out_q: np.ndarray, out_user: np.ndarray) -> int:
    """Every point's q and user at a playout step: the root's (step 0), along a shared
    future, or (no future) through a fresh tree of the users where they are. ``touched``
    lists the users served at the steps so far, ``flag`` (I,) marks them."""
    if steps == 0:
        for k in range(out_q.shape[0]):
            out_q[k] = idx.root_q[k]
            out_user[k] = idx.root_user[k]
        return idx.root_allowed[0]
    if future >= 0:
        return evaluate_future(scene, idx, root, future, steps, w, touched, flag, out_q, out_user)
    refit_tree(w.users, idx.tree)
    return evaluate_tree(scene, w, idx.tree, idx.home, out_q, out_user)


@jit_borrow
def root_values(scene: Scene, root: World, tree: UserTree, home: np.ndarray, out_q: np.ndarray,
                out_user: np.ndarray) -> int:
    """Every point's q and user in the root state (``evaluate_tree``)."""
    fill_tree(root.users, tree)
    return evaluate_tree(scene, root, tree, home, out_q, out_user)


class PointTables(NamedTuple):
    """What depends only on the hovering points: ``hop`` (K, K), ``home`` (K,), ``hop_q``
    (K, K) (``point_tables``)."""

    hop: np.ndarray
    home: np.ndarray
    hop_q: np.ndarray


def point_tables_of(p: np.ndarray, hover_points: np.ndarray) -> PointTables:
    k = len(hover_points)
    tables = PointTables(np.empty((k, k)), np.empty(k), np.empty((k, k)))
    point_tables(p, hover_points, tables.hop, tables.home, tables.hop_q)
    return tables


def service_bounds_of(scene: Scene, root: World, tables: PointTables) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``service_bounds`` for the futures of ``root`` (``serve_ub``, ``cost_ub``,
    ``cost_lb``): no user
    has more tasks than u_max, the root's or the task table's largest count (a draw is
    capped at u_max, a backlog too), nor lies outside the root's users' box and the area
    where the users move ([0, area]^2, and in 3-D altitudes [0, user_max_altitude]). A
    margin far above rounding makes each a bound in floating point too."""
    p = scene.p
    tasks_cap = max(int(p[P.TASK_MAX]), int(root.tasks.max(initial=0)), int(scene.task_table.max(initial=0)))
    box = np.array([0.0, p[P.AREA], 0.0, p[P.AREA], 0.0, 0.0])
    if p[P.DIMENSIONS] > 2.5:
        box[5] = p[P.USER_ZMAX]
    if len(root.users):
        box[0::2] = np.minimum(box[0::2], root.users.min(axis=0))
        box[1::2] = np.maximum(box[1::2], root.users.max(axis=0))
    if p[P.DIMENSIONS] <= 2.5 and len(root.users):  # the users keep their altitudes
        box[4:] = root.users[:, 2].min(), root.users[:, 2].max()
    k = len(scene.hover_points)
    gain, cost, cost_lb = np.empty(k), np.empty(k), np.empty(k)
    service_bounds(p, scene.hover_points, tasks_cap, box, np.empty(3), gain, cost, cost_lb)
    margin = 1e-9 * (1.0 + np.abs(gain) + float(np.abs(tables.hop_q).max(initial=0.0)))
    return gain + margin, cost * (1.0 + 1e-9), cost_lb * (1.0 - 1e-9)


class RootValues(NamedTuple):
    """The root state's q (K,), users served (K,) and allowed count (1,), and the k-d tree
    of its users."""

    q: np.ndarray
    user: np.ndarray
    allowed: np.ndarray
    tree: UserTree


def root_values_of(scene: Scene, root: World, tables: PointTables) -> RootValues:
    k = len(scene.hover_points)
    values = RootValues(np.empty(k), np.empty(k, dtype=np.int64), np.zeros(1, dtype=np.int64),
                        empty_tree(len(root.users)))
    values.allowed[0] = root_values(scene, root, values.tree, tables.home, values.q, values.user)
    return values


def index_of(scene: Scene, root: World, moves: np.ndarray, news: np.ndarray, tables: PointTables,
             values: RootValues) -> FutureIndex:
    """An empty index of the futures ``moves`` (S, H, I, 3) and ``news`` (S, H, I) from
    ``root``; rows are filled as playouts reach them, and answer each point when asked."""
    s, h, i = news.shape
    k = len(scene.hover_points)
    nodes = len(values.tree.box)
    rows = (s, h + 1)
    serve_ub, cost_ub, cost_lb = service_bounds_of(scene, root, tables)
    return FutureIndex(
        moves=moves, news=news, ready=np.zeros(s, dtype=np.int64),
        row_users=np.empty((*rows, i, 3)), row_tasks=np.empty((*rows, i), dtype=np.int64),
        row_eligible=np.zeros(rows, dtype=np.int64), box=np.empty((*rows, nodes, 6)),
        answered=np.zeros((*rows, k), dtype=np.bool_), user=np.empty((*rows, k), dtype=np.int64),
        cost=np.empty((*rows, k)), gain=np.empty((*rows, k)), reach_sq=np.empty((*rows, k)),
        window=np.empty((*rows, k), dtype=np.int64), near_user=np.empty((*rows, k, NEAREST), dtype=np.int64),
        near_d2=np.empty((*rows, k, NEAREST)), near_cost=np.empty((*rows, k, NEAREST)),
        near_count=np.empty((*rows, k), dtype=np.int64), near_cover=np.empty((*rows, k)), hop=tables.hop,
        home=tables.home, hop_q=tables.hop_q, serve_ub=serve_ub, cost_ub=cost_ub, cost_lb=cost_lb,
        root_q=values.q, root_user=values.user, root_allowed=values.allowed,
        tree=values.tree._replace(box=values.tree.box.copy()),
        served0=root.served.copy(), clock=np.zeros(1, dtype=np.int64),
    )


__all__ = ["FutureIndex", "PointTables", "RootValues", "evaluate_future", "evaluate_step", "evaluate_tree",
           "allowed_future", "fill_rows", "greedy_future", "index_of", "point_user", "point_tables_of", "root_values_of"]
