"""The per-interval reward (11) and the playout return R."""

from __future__ import annotations

import numpy as np

from . import params as P
from ._jit import jit


@jit
def interval_reward(p: np.ndarray, tasks: int, energy_j: float) -> float:
    """q = u / u_max - w / w_max (11); the task term carries an optional weight."""
    return p[P.TASK_WEIGHT] * tasks / p[P.TASK_MAX] - energy_j / p[P.ENERGY_NORM]


@jit
def playout_return(rewards: np.ndarray, start: int, stop: int) -> float:
    """R = sum of q over steps [start, stop) / (stop - start): the paper's mean return."""
    if stop <= start:
        return 0.0
    total = 0.0
    for k in range(start, stop):
        total += rewards[k]
    return total / (stop - start)
