"""A spatial index of the users: who is served from a hovering point, without scanning all.

``interval.nearest_eligible`` scans every user; for K hovering points that is K x I
distances per evaluation. ``UserTree`` is a k-d tree of the users' positions (median splits
along the widest side, leaves of at most ``LEAF`` users, each node's bounding box), and the
queries visit the nodes nearest first, skipping every node whose box is farther than what
is already known. A tree adapts to how the users are spread: the paper's "two neat rows"
put a thousand users on two lines, where a uniform grid of cells is mostly empty and
partly crowded.

``tree_nearest`` returns exactly what ``nearest_eligible`` returns (the same user, by the
same tie rule, from squared distances computed by the same expression), so the two are
interchangeable; ``tests/model/test_user_tree.py`` checks that on random states. A box's
lower bound is computed with the same floating-point operations as a distance, from
coordinates that bound the users' own, so it never exceeds a computed distance of a user
inside it.

Layout: the tree is implicit (heap order: node n has children 2n + 1 and 2n + 2; node n
holds the users ``order[span[n, 0]:span[n, 1]]``, split at the middle). Users who move keep
their leaves: ``refit_tree`` only recomputes the boxes, in O(I), and the tree stays exact
(a query relies on the boxes alone), only a little less tight.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import params as P
from ._jit import jit_borrow
from .fairness import is_eligible
from .interval import NO_USER

LEAF = 16
"""Users per leaf at most."""
STACK = 128
"""Room of the traversal stack (three numbers per pending node); the depth is about
log2(I / LEAF), so this holds far more users than any sortie has."""


class UserTree(NamedTuple):
    """A k-d tree of I users in N nodes: ``order`` (I,) int64, the users by leaf; ``span``
    (N, 2) int64, the range of ``order`` each node holds; ``box`` (N, 6) the bounding box of
    each node's users (x lo, x hi, y lo, y hi, z lo, z hi); ``stack`` (STACK,) int64 and
    ``bounds`` (STACK // 3,) scratch of the traversals (pending nodes and their boxes'
    lower bounds)."""

    order: np.ndarray
    span: np.ndarray
    box: np.ndarray
    stack: np.ndarray
    bounds: np.ndarray


@jit_borrow
def tree_size(num_users: int) -> int:
    """Nodes of the heap-ordered tree of ``num_users`` users."""
    depth = 0
    n = num_users
    while n > LEAF:
        n = (n + 1) // 2
        depth += 1
    return (1 << (depth + 1)) - 1


def empty_tree(num_users: int) -> UserTree:
    """Room for the tree of ``num_users`` users (filled by ``fill_tree``)."""
    nodes = tree_size(num_users)
    return UserTree(np.zeros(num_users, dtype=np.int64), np.zeros((nodes, 2), dtype=np.int64), np.zeros((nodes, 6)),
                    np.zeros(STACK, dtype=np.int64), np.zeros(STACK // 3))


@jit_borrow
def _select(order: np.ndarray, users: np.ndarray, axis: int, lo: int, hi: int, nth: int) -> None:
    """Reorder ``order[lo:hi]`` so that position ``nth`` holds the user it would hold if
    sorted by coordinate ``axis``, none after it smaller, none before it larger."""
    while hi - lo > 1:
        a, b, c = users[order[lo], axis], users[order[(lo + hi) // 2], axis], users[order[hi - 1], axis]
        pivot = max(min(a, b), min(max(a, b), c))  # median of three
        i, j = lo, hi - 1
        while i <= j:
            while users[order[i], axis] < pivot:
                i += 1
            while users[order[j], axis] > pivot:
                j -= 1
            if i <= j:
                order[i], order[j] = order[j], order[i]
                i += 1
                j -= 1
        # now [lo, j] <= pivot <= [i, hi), and anything between equals the pivot
        if nth <= j:
            hi = j + 1
        elif nth >= i:
            lo = i
        else:
            return


@jit_borrow
def _fit_leaf(users: np.ndarray, t: UserTree, node: int) -> None:
    """The box of ``node`` from its users."""
    box = t.box
    for a in range(3):
        box[node, 2 * a] = math.inf
        box[node, 2 * a + 1] = -math.inf
    for m in range(t.span[node, 0], t.span[node, 1]):
        i = t.order[m]
        for a in range(3):
            box[node, 2 * a] = min(box[node, 2 * a], users[i, a])
            box[node, 2 * a + 1] = max(box[node, 2 * a + 1], users[i, a])


@jit_borrow
def fill_tree(users: np.ndarray, t: UserTree) -> None:
    """Build ``t`` (made for I users) over ``users`` (I, 3), in place; O(I log I)."""
    order, span, box, stack = t.order, t.span, t.box, t.stack
    num = users.shape[0]
    for i in range(num):
        order[i] = i
    for n in range(span.shape[0]):
        span[n, 0] = 0
        span[n, 1] = 0  # a node no range reaches stays empty
    if num == 0:
        return
    stack[0], stack[1], stack[2] = 0, 0, num
    top = 3
    while top > 0:
        top -= 3
        node, lo, hi = stack[top], stack[top + 1], stack[top + 2]
        span[node, 0] = lo
        span[node, 1] = hi
        _fit_leaf(users, t, node)
        if hi - lo <= LEAF:
            continue
        axis = 0
        for a in range(1, 3):
            if box[node, 2 * a + 1] - box[node, 2 * a] > box[node, 2 * axis + 1] - box[node, 2 * axis]:
                axis = a
        mid = (lo + hi) // 2
        _select(order, users, axis, lo, hi, mid)
        stack[top], stack[top + 1], stack[top + 2] = 2 * node + 1, lo, mid
        stack[top + 3], stack[top + 4], stack[top + 5] = 2 * node + 2, mid, hi
        top += 6


@jit_borrow
def refit_tree(users: np.ndarray, t: UserTree) -> None:
    """Recompute the boxes of ``t`` (built by ``fill_tree``) for ``users`` (I, 3), the
    same users moved: every node keeps its users. O(I + N)."""
    box, span = t.box, t.span
    for node in range(span.shape[0] - 1, -1, -1):
        lo, hi = span[node, 0], span[node, 1]
        if hi - lo <= LEAF:
            _fit_leaf(users, t, node)
        else:
            left, right = 2 * node + 1, 2 * node + 2
            for a in range(3):
                box[node, 2 * a] = min(box[left, 2 * a], box[right, 2 * a])
                box[node, 2 * a + 1] = max(box[left, 2 * a + 1], box[right, 2 * a + 1])


@jit_borrow
def _gap(lo: float, hi: float, x: float) -> float:
    """Distance from ``x`` to [lo, hi], at least 0."""
    if x < lo:
        return lo - x
    if x > hi:
        return x - hi
    return 0.0


@jit_borrow
def _box_sq(box: np.ndarray, node: int, hx: float, hy: float, hz: float) -> float:
    """A lower bound of the squared distance from (hx, hy, hz) to any user of ``node``."""
    gx = _gap(box[node, 0], box[node, 1], hx)
    gy = _gap(box[node, 2], box[node, 3], hy)
    gz = _gap(box[node, 4], box[node, 5], hz)
    return gx * gx + gy * gy + gz * gz


@jit_borrow
def _push(t: UserTree, top: int, node: int, lo: int, hi: int, lower: float) -> int:
    """Put ``node`` (users ``order[lo:hi]``, no nearer than ``lower``) on the stack."""
    t.stack[top] = node
    t.stack[top + 1] = lo
    t.stack[top + 2] = hi
    t.bounds[top // 3] = lower
    return top + 3


@jit_borrow
def _push_children(t: UserTree, top: int, node: int, lo: int, hi: int, hx: float, hy: float, hz: float,
                   bound: float) -> int:
    """Push the children of ``node`` within ``bound``, the farther first so that the nearer
    pops next."""
    mid = (lo + hi) // 2  # as fill_tree split it
    left, right = 2 * node + 1, 2 * node + 2
    lower_left = _box_sq(t.box, left, hx, hy, hz)
    lower_right = _box_sq(t.box, right, hx, hy, hz)
    if lower_left <= lower_right:
        if lower_right <= bound:
            top = _push(t, top, right, mid, hi, lower_right)
        if lower_left <= bound:
            top = _push(t, top, left, lo, mid, lower_left)
    else:
        if lower_left <= bound:
            top = _push(t, top, left, lo, mid, lower_left)
        if lower_right <= bound:
            top = _push(t, top, right, mid, hi, lower_right)
    return top


@jit_borrow
def _walk(p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray, served: np.ndarray,
          t: UserTree, bound: float, choose: bool) -> tuple[float, int]:
    """Visit the nodes nearest first, skipping those whose box is beyond ``bound``: the
    least squared distance of an eligible user below ``bound`` (``choose`` false, lowered
    as users are found), or the user chosen among the eligible within ``bound``."""
    hx, hy, hz = hover_xyz[0], hover_xyz[1], hover_xyz[2]
    order, stack = t.order, t.stack
    chosen = NO_USER
    if users.shape[0] == 0:
        return bound, chosen
    top = _push(t, 0, 0, 0, users.shape[0], _box_sq(t.box, 0, hx, hy, hz))
    while top > 0:
        top -= 3
        if t.bounds[top // 3] > bound:  # the bound tightened since it was pushed
            continue
        node, lo, hi = stack[top], stack[top + 1], stack[top + 2]
        if hi - lo > LEAF:
            top = _push_children(t, top, node, lo, hi, hx, hy, hz, bound)
            continue
        for m in range(lo, hi):
            i = order[m]
            if not is_eligible(p, tasks[i], served[i]):
                continue
            dx = hx - users[i, 0]  # distance_sq_m2(hover_xyz, users[i]), term for term
            dy = hy - users[i, 1]
            dz = hz - users[i, 2]
            d = dx * dx + dy * dy + dz * dz
            if not choose:
                if d < bound:
                    bound = d
            elif d <= bound:
                # the larger task wins, then the lower index (nearest_eligible's scan order)
                if chosen == NO_USER or tasks[i] > tasks[chosen] or (tasks[i] == tasks[chosen] and i < chosen):
                    chosen = i
    return bound, chosen


@jit_borrow
def tree_window_choice(p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray, served: np.ndarray,
                       t: UserTree, reach_sq: float) -> int:
    """The user ``interval.nearest_eligible`` chooses among the eligible users within the
    squared reach ``reach_sq`` of its tie window, the nearest distance being known."""
    _, chosen = _walk(p, hover_xyz, users, tasks, served, t, reach_sq, True)
    return chosen


@jit_borrow
def tree_nearest(p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray, served: np.ndarray,
                 t: UserTree) -> tuple[int, float]:
    """The user ``interval.nearest_eligible`` serves from ``hover_xyz`` (``NO_USER`` if
    nobody is eligible), found through ``t`` (filled from ``users``); and the squared reach
    of the tie window: every eligible user within it was compared (``inf`` for nobody)."""
    nearest_sq, _ = _walk(p, hover_xyz, users, tasks, served, t, math.inf, False)
    if nearest_sq == math.inf:
        return NO_USER, math.inf
    reach = math.sqrt(nearest_sq) + p[P.TIE_M]
    reach_sq = reach * reach
    return tree_window_choice(p, hover_xyz, users, tasks, served, t, reach_sq), reach_sq


@jit_borrow
def tree_nearest_list(p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray,
                      served: np.ndarray, t: UserTree, out_user: np.ndarray, out_d2: np.ndarray) -> tuple[int, float]:
    """The M = len(out_user) nearest eligible users of ``hover_xyz`` in (squared distance,
    index) order, into ``out_user`` and ``out_d2``. Returns how many (fewer than M: every
    eligible user) and the list's cover: every eligible user with a squared distance below
    it is in the list (``inf`` when the list holds them all)."""
    size = out_user.shape[0]
    hx, hy, hz = hover_xyz[0], hover_xyz[1], hover_xyz[2]
    order, stack = t.order, t.stack
    count = 0
    bound = math.inf  # the M-th distance once the list is full
    if users.shape[0] == 0:
        return 0, bound
    top = _push(t, 0, 0, 0, users.shape[0], _box_sq(t.box, 0, hx, hy, hz))
    while top > 0:
        top -= 3
        if t.bounds[top // 3] > bound:  # the bound tightened since it was pushed
            continue
        node, lo, hi = stack[top], stack[top + 1], stack[top + 2]
        if hi - lo > LEAF:
            top = _push_children(t, top, node, lo, hi, hx, hy, hz, bound)
            continue
        for m in range(lo, hi):
            i = order[m]
            if not is_eligible(p, tasks[i], served[i]):
                continue
            dx = hx - users[i, 0]
            dy = hy - users[i, 1]
            dz = hz - users[i, 2]
            d = dx * dx + dy * dy + dz * dz
            if count == size and (d > bound or (d == bound and i > out_user[size - 1])):
                continue
            # insert in (distance, index) order; the last one falls off a full list
            j = count if count < size else size - 1
            while j > 0 and (out_d2[j - 1] > d or (out_d2[j - 1] == d and out_user[j - 1] > i)):
                out_d2[j] = out_d2[j - 1]
                out_user[j] = out_user[j - 1]
                j -= 1
            out_d2[j] = d
            out_user[j] = i
            if count < size:
                count += 1
            if count == size:
                bound = out_d2[size - 1]
    return count, bound


__all__ = ["LEAF", "UserTree", "empty_tree", "fill_tree", "refit_tree", "tree_nearest", "tree_nearest_list",
           "tree_size", "tree_window_choice"]
