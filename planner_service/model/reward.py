"""The per-interval reward (11)."""

from __future__ import annotations

import numpy as np

from . import params as P
from ._jit import jit_borrow


@jit_borrow
def task_reward(p: np.ndarray, tasks: int) -> float:
    """The task term of (11): u / u_max, times an optional weight."""
    return p[P.TASK_WEIGHT] * tasks / p[P.TASK_MAX]


@jit_borrow
def reward_of(p: np.ndarray, task_term: float, energy_j: float) -> float:
    """q from the task term and the interval's energy: task term - w / w_max (11)."""
    return task_term - energy_j / p[P.ENERGY_NORM]


@jit_borrow
def interval_reward(p: np.ndarray, tasks: int, energy_j: float) -> float:
    """q = u / u_max - w / w_max (11); the task term carries an optional weight."""
    return reward_of(p, task_reward(p, tasks), energy_j)
