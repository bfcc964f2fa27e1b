"""The two policies without search: one-step greedy and uniform random."""

from __future__ import annotations

import numpy as np

from ..model import SortieEnv
from ..policy import Decision, PolicySpec


class GreedyPolicy:
    """The hovering point with the largest immediate reward q (11), ties to the lowest index."""

    name = "greedy"

    def begin(self, env: SortieEnv) -> None:
        pass

    def decide(self, env: SortieEnv) -> Decision:
        return Decision(int(np.argmax(env.action_values())))


class RandomPolicy:
    """A uniform draw among the allowed hovering points."""

    name = "random"

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def begin(self, env: SortieEnv) -> None:
        pass

    def decide(self, env: SortieEnv) -> Decision:
        allowed = np.flatnonzero(env.action_mask())
        return Decision(int(self.rng.choice(allowed)))


def greedy(spec: PolicySpec, rng: np.random.Generator) -> GreedyPolicy:
    return GreedyPolicy()


def uniform_random(spec: PolicySpec, rng: np.random.Generator) -> RandomPolicy:
    return RandomPolicy(rng)
