"""What the two learners share: the TD target, the epsilon schedule, masked greedy
choice, and the training copies of the sortie.

"Training episodes" sit on the same axis as MCTS iterations (the paper puts both on one axis): a learner
given N trains on N episodes in ``begin`` and then flies the real sortie greedily.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import Snapshot, SortieEnv
from ..policy import PolicySpec


def td_target(
    rewards: np.ndarray | float,
    next_values: np.ndarray,
    next_masks: np.ndarray,
    dones: np.ndarray | bool,
    gamma: float,
) -> np.ndarray:
    """r + gamma * max over allowed a' of Q(s', a'), with no bootstrap past the end.

    ``next_values`` (B, A) or (A,), ``next_masks`` the same shape (bool). "Done" covers
    both ends of a sortie: no allowed action left, and the ``max_intervals`` limit, which
    is part of the problem here (nothing is earned after it), not an outside cut.
    """
    allowed = np.where(next_masks, next_values, -np.inf).max(axis=-1)
    next_value = np.where(np.asarray(dones) | ~np.isfinite(allowed), 0.0, allowed)
    return np.asarray(rewards) + gamma * next_value


def linear_schedule(start_e: float, end_e: float, duration: float, t: int) -> float:
    """Epsilon at episode ``t``: ``start_e`` falling linearly to ``end_e`` over
    ``duration`` episodes, then flat (cleanrl's schedule)."""
    if duration <= 0:
        return end_e
    slope = (end_e - start_e) / duration
    return max(slope * t + start_e, end_e)


def masked_argmax(values: np.ndarray, mask: np.ndarray, rng: np.random.Generator | None = None) -> int:
    """The allowed action of largest value. With ``rng``, exact ties are broken uniformly
    (a fresh Q-table is all zeros, and "lowest index" would bias the whole route)."""
    allowed = np.flatnonzero(mask)
    if len(allowed) == 0:
        raise ValueError("no action is allowed")
    vals = values[allowed]
    best = allowed[vals == vals.max()]
    if rng is None or len(best) == 1:
        return int(best[0])
    return int(rng.choice(best))


def epsilon_greedy(
    values: np.ndarray, mask: np.ndarray, epsilon: float, rng: np.random.Generator
) -> int:
    """With probability ``epsilon`` a uniform allowed action, else the masked argmax."""
    if rng.random() < epsilon:
        return int(rng.choice(np.flatnonzero(mask)))
    return masked_argmax(values, mask, rng)


class TrainingWorld:
    """Fresh copies of a sortie for a learner to train on.

    Every episode starts from what the UAV observes when the real sortie begins (users'
    positions, the tasks requested now, service counts, battery, and a known task schedule
    when the caller gave one), and its future (moves, later task draws) comes from the
    learner's own generator, never from the real environment's: training must not see the
    random future it will be evaluated on.
    """

    def __init__(self, env: SortieEnv, rng: np.random.Generator) -> None:
        self.env = SortieEnv(env.scenario)
        self.start = env.state.copy() if env.state is not None else None
        self.rng = rng

    def reset(self) -> SortieEnv:
        """The training environment at the start state, drawing from the learner's rng."""
        if self.start is None:
            raise ValueError("the real environment has not been reset")
        self.env.rng = self.rng
        # The snapshot's generator state is the learner's own, so restore leaves it as is.
        self.env.restore(Snapshot(self.start, self.rng.bit_generator.state, False))
        return self.env


@dataclass
class TrainingReport:
    """What a learner did in ``begin``: episodes, steps, wall time and per-episode returns."""

    episodes: int = 0
    steps: int = 0
    updates: int = 0
    wall_s: float = 0.0
    returns: list[float] = field(default_factory=list)

    def summary(self) -> dict[str, float | int]:
        """JSON-ready figures (the returns as the mean of the first and last tenth)."""
        n = len(self.returns)
        tenth = max(1, n // 10)
        return {
            "episodes": self.episodes,
            "steps": self.steps,
            "updates": self.updates,
            "wall_s": self.wall_s,
            "return_first_tenth": float(np.mean(self.returns[:tenth])) if n else 0.0,
            "return_last_tenth": float(np.mean(self.returns[-tenth:])) if n else 0.0,
        }


def training_episodes(spec: PolicySpec, algo: str) -> int:
    """The training-episode count a learner takes from ``spec``. A wall-clock budget
    alone is refused: training happens once, before the sortie, not per decision."""
    if spec.iterations is None:
        raise ValueError(f"{algo} needs a number of training episodes (--iterations); --budget-ms does not apply")
    if spec.iterations < 0:
        raise ValueError(f"{algo}: training episodes must not be negative, got {spec.iterations}")
    return int(spec.iterations)
