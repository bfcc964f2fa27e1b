"""Random-waypoint user moves (1)-(2) and the per-interval task draws."""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import jit


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
def move_users(p: np.ndarray, users: np.ndarray, rng: np.random.Generator) -> None:
    """x_i(t) = clip(x_i(t-1) + alpha, 0, R), the same for y (1)-(2); in the 3-D variant
    z moves too, within [0, user_max_altitude]. ``users`` (I, 3) is updated in place."""
    side = p[P.AREA]
    axes = 3 if p[P.DIMENSIONS] > 2.5 else 2
    for i in range(users.shape[0]):
        for a in range(axes):
            top = side if a < 2 else p[P.USER_ZMAX]
            users[i, a] = min(max(users[i, a] + _step(p, rng), 0.0), top)


@jit
def draw_tasks(p: np.ndarray, tasks: np.ndarray, rng: np.random.Generator) -> None:
    """u_i(t) ~ N(mean, phi^2), rounded half up and clipped to [0, u_max]; in place."""
    top = p[P.TASK_MAX]
    for i in range(tasks.shape[0]):
        value = math.floor(rng.normal(p[P.TASK_MEAN], p[P.TASK_STD]) + 0.5)
        tasks[i] = int(min(max(value, 0.0), top))
