"""Tasks that arrive in time: the world the service flies, as the environment can simulate it.

Under ``task_model = "backlog"`` the model adds each user's new tasks once per interval
(``world.advance``), whatever the interval lasted; the planners' futures are built on that.
Real users (and ``sim_bridge users``) make their data in time: a draw of the model's
arrivals once every ``period_s`` seconds, each user at its own phase. An interval of the
model lasts its flight (distance at the scenario's speed) and its hold (the upload: e_h / P_h,
the time the hover energy pays for), so a short hop to a small backlog brings fewer new tasks
than a long one; the model's law gives both the same.

``TimedArrivals`` is that law for the environment (``SortieEnv.reset(options=
{"arrivals_every_s": ...})``): the world's tasks come in time while the planners go on
planning with their per-interval futures, so the gap between the two is measured offline,
in seconds, rather than only in flight (``bench --flight``).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from . import params as P
from .mobility import draw_arrivals


@dataclass
class TimedArrivals:
    """Each user's draws of the model's arrivals, one every ``period_s`` of flight time."""

    period_s: float
    due_s: np.ndarray
    """(I,) each user's next draw, seconds since the sortie began."""
    clock_s: float
    rng: np.random.Generator

    @classmethod
    def start(cls, period_s: float, num_users: int, rng: np.random.Generator) -> "TimedArrivals":
        """The law at the sortie's start: each user's first draw at a uniform phase within
        one period (its first backlog is the sortie's first draw, already made)."""
        if not (math.isfinite(period_s) and period_s > 0.0):
            raise ValueError(f"arrivals_every_s must be a positive number of seconds, got {period_s!r}")
        return cls(float(period_s), rng.uniform(0.0, period_s, num_users), 0.0, rng)

    def copy(self) -> "TimedArrivals":
        """A copy that goes on drawing the same numbers, apart from this one."""
        return TimedArrivals(self.period_s, self.due_s.copy(), self.clock_s, copy.deepcopy(self.rng))

    def run(self, p: np.ndarray, tasks: np.ndarray, duration_s: float) -> None:
        """Let ``duration_s`` pass: every draw now due adds its arrivals to its user's
        backlog, capped at u_max; ``tasks`` (I,) in place."""
        self.clock_s += duration_s
        one = np.zeros(1, dtype=np.int64)
        top = int(p[P.TASK_MAX])
        for i in range(tasks.shape[0]):
            while self.due_s[i] <= self.clock_s:
                draw_arrivals(p, one, self.rng)
                tasks[i] = min(tasks[i] + int(one[0]), top)
                self.due_s[i] += self.period_s


__all__ = ["TimedArrivals"]
