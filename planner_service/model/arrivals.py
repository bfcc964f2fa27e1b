"""The users' own arrival law, as the environment can simulate it whatever the planners assume.

Under ``task_model = "backlog"`` the model adds each user's new tasks once per interval,
whatever it lasted (``task_arrival_period_s`` 0), or in time, Poisson of mean lambda d /
period for an interval of d seconds (``task_arrival_period_s`` > 0; ``world.in_time``).
Real users (and ``sim_bridge users``) make their data in time too, but as a draw of the
model's arrivals once every ``period_s`` seconds, each user at its own phase: the same rate,
not the same draws.

``TimedArrivals`` is that law for the environment (``SortieEnv.reset(options=
{"arrivals_every_s": ...})``): the world's tasks come as the users make them while the
planners plan with the scenario's law, so what a planner's law costs or gains against the
users' is measured offline, in seconds, rather than only in flight (``bench --flight``).
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
