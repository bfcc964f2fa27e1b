"""Timing planner decisions on states met in real sorties."""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..baselines import GreedyPolicy
from ..model import Scenario, SortieEnv, SortieState
from ..policy import Decision


def decision_states(scenario: Scenario, count: int, first_seed: int = 0) -> tuple[np.ndarray, list[SortieState]]:
    """``count`` states at which a planner must decide, from greedy sorties on seeds
    ``first_seed``, ``first_seed + 1``, ...; with the hovering points (K, 3)."""
    env = SortieEnv(scenario)
    greedy = GreedyPolicy()
    states: list[SortieState] = []
    seed = first_seed
    while len(states) < count:
        env.reset(seed=seed)
        while not env.done and len(states) < count:
            states.append(env.state.copy())
            env.step(greedy.decide(env).action)
        seed += 1
    return env.hover_points, states


@dataclass(frozen=True)
class Timing:
    """Wall times of decisions (seconds) and what was decided."""

    seconds: list[float]
    actions: list[int]
    iterations: list[int]

    @property
    def median_ms(self) -> float:
        return float(np.median(self.seconds) * 1e3)

    @property
    def p99_ms(self) -> float:
        return float(np.percentile(self.seconds, 99) * 1e3)

    @property
    def playouts_per_s(self) -> float:
        return float(np.sum(self.iterations) / np.sum(self.seconds))

    @property
    def digest(self) -> str:
        """What was decided (each action and its iterations), as 12 hex digits: the same
        digest before and after a change to the planner's code means the same decisions on
        the same machine (a different CPU may round differently)."""
        return hashlib.sha256(repr(list(zip(self.actions, self.iterations))).encode()).hexdigest()[:12]


def time_decisions(states: list[SortieState], decide: Callable[[int, SortieState], Decision]) -> Timing:
    """Time ``decide(i, state)`` on each state; ``decide`` builds its own planner."""
    seconds, actions, iterations = [], [], []
    for i, state in enumerate(states):
        start = time.perf_counter()
        decision = decide(i, state)
        seconds.append(time.perf_counter() - start)
        actions.append(decision.action)
        iterations.append(decision.iterations)
    return Timing(seconds, actions, iterations)
