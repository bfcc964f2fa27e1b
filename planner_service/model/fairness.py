"""The fairness rule (3) with the limit of (9c), and the audit of a sortie against it."""

from __future__ import annotations

from typing import Hashable, Iterable

import numpy as np

from . import params as P
from ._jit import jit_borrow, py
from .params import pack
from .scenario import Scenario


@jit_borrow
def is_eligible(p: np.ndarray, tasks: int, served_count: int) -> bool:
    """b_i(t) may be 1: never served, or served once and u_i(t) > beta (3); never past
    the (9c) limit. A user with no task has nothing to offload and is not eligible."""
    if tasks <= 0 or served_count >= p[P.MAX_SERVICES]:
        return False
    return served_count == 0 or tasks > p[P.BETA]


def fairness_violations(scenario: Scenario, services: Iterable[tuple[Hashable, int]]) -> int:
    """Services ``(user, tasks)``, in the order flown, that ``is_eligible`` would have
    refused when they were made: the one rule every audit (the ``plan`` summary, the
    service's report, the tests) counts against, so that none can drift from the model's."""
    p = pack(scenario)
    eligible = py(is_eligible)  # a handful of calls: not worth compiling for
    counts: dict[Hashable, int] = {}
    bad = 0
    for user, tasks in services:
        seen = counts.get(user, 0)
        if not eligible(p, tasks, seen):
            bad += 1
        counts[user] = seen + 1
    return bad
