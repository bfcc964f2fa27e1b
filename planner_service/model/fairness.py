"""The fairness rule (3) with the limit of (9c)."""

from __future__ import annotations

import numpy as np

from . import params as P
from ._jit import jit_borrow


@jit_borrow
def is_eligible(p: np.ndarray, tasks: int, served_count: int) -> bool:
    """b_i(t) may be 1: never served, or served once and u_i(t) > beta (3); never past
    the (9c) limit. A user with no task has nothing to offload and is not eligible."""
    if tasks <= 0 or served_count >= p[P.MAX_SERVICES]:
        return False
    return served_count == 0 or tasks > p[P.BETA]
