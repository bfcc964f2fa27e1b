"""Random-waypoint user moves (1)-(2) and the per-interval task draws.

Drawing and applying are separate so a planner can draw many futures up front and apply
them later (common random numbers); ``move_users`` does both in the environment's order.
"""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import jit


@jit
def _axes(p: np.ndarray) -> int:
    return 3 if p[P.DIMENSIONS] > 2.5 else 2


@jit
def _step(p: np.ndarray, rng: np.random.Generator) -> float:
    reach = p[P.MOVE_RANGE]
    if reach <= 0.0:
        return 0.0
    if p[P.MOVE_INTEGER] > 0.5:
        r = int(reach)
        return float(rng.integers(-r, r + 1))
    return rng.uniform(-reach, reach)


@jit
def draw_moves(p: np.ndarray, moves: np.ndarray, rng: np.random.Generator) -> None:
    """alpha_1, alpha_2 (and the 3-D variant's vertical step) of every user, uniform in
    [-epsilon, epsilon]; ``moves`` (I, 3) is filled in place, user by user."""
    axes = _axes(p)
    for i in range(moves.shape[0]):
        for a in range(3):
            moves[i, a] = _step(p, rng) if a < axes else 0.0


@jit
def apply_moves(p: np.ndarray, users: np.ndarray, moves: np.ndarray) -> None:
    """x_i(t) = clip(x_i(t-1) + alpha_1, 0, R), the same for y (1)-(2); in the 3-D variant
    z stays within [0, user_max_altitude]. ``users`` (I, 3) is updated in place."""
    side = p[P.AREA]
    for i in range(users.shape[0]):
        for a in range(_axes(p)):
            top = side if a < 2 else p[P.USER_ZMAX]
            users[i, a] = min(max(users[i, a] + moves[i, a], 0.0), top)


@jit
def move_users(p: np.ndarray, users: np.ndarray, rng: np.random.Generator) -> None:
    """Draw and apply one interval's moves (1)-(2); ``users`` (I, 3) in place."""
    moves = np.empty_like(users)
    draw_moves(p, moves, rng)
    apply_moves(p, users, moves)


@jit
def draw_tasks(p: np.ndarray, tasks: np.ndarray, rng: np.random.Generator) -> None:
    """u_i(t) ~ N(mean, phi^2), rounded half up and clipped to [0, u_max]; in place."""
    top = p[P.TASK_MAX]
    for i in range(tasks.shape[0]):
        value = math.floor(rng.normal(p[P.TASK_MEAN], p[P.TASK_STD]) + 0.5)
        tasks[i] = int(min(max(value, 0.0), top))
