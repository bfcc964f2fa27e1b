"""Tabular Q-learning, the paper's weakest baseline (Section IV).

State encoding: (interval index, current hovering point or base). The paper says only
that "the actions are stored as a single row in the Q-table, and each action maps several
different states": a table with one column per hovering point. Where the UAV is sets the
flight energy of every next hop, and the interval index stands for how far the sortie has
gone: along a route it fixes, coarsely, the battery left and how many users are used up.
The exact state (positions, tasks, 3^I service counts, battery) cannot be tabulated, and
anything finer than this would leave most cells unvisited after 10-1000 episodes of about
10 steps. Several real states (different served sets, tasks, positions) share one cell:
that is the aliasing the paper's sentence describes, and why QL trails the search.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from ..model import SortieEnv
from ..policy import Decision, PolicySpec
from .learning import (
    TrainingReport, TrainingWorld, epsilon_greedy, linear_schedule, masked_argmax, td_target, training_episodes,
)


@dataclass(frozen=True)
class QLearningConfig:
    """Hyperparameters of the tabular learner (logged with every decision)."""

    learning_rate: float = 0.1
    """[alpha] step size of the update; constant because moves and task draws make the
    transitions random, so the table tracks an average."""
    gamma: float = 1.0
    """Discount. The sortie lasts at most ``max_intervals`` steps and the paper's return
    is undiscounted, so there is nothing to discount."""
    start_e: float = 1.0
    """Exploration epsilon at the first training episode."""
    end_e: float = 0.05
    """Exploration epsilon at the end of the schedule."""
    exploration_fraction: float = 0.5
    """Fraction of the training episodes over which epsilon falls from start to end; a
    fraction rather than a count so that 10 and 1000 episodes both explore, then exploit."""
    interval_cap: int = 16
    """Rows of the table when the scenario has no interval limit (``max_intervals`` 0):
    later intervals share the last row."""

    def __post_init__(self) -> None:
        if not 0.0 < self.learning_rate <= 1.0:
            raise ValueError(f"learning_rate must lie in (0, 1], got {self.learning_rate}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {self.gamma}")
        if not (0.0 <= self.end_e <= 1.0 and 0.0 <= self.start_e <= 1.0):
            raise ValueError("start_e and end_e must lie in [0, 1]")
        if self.exploration_fraction < 0.0 or self.interval_cap < 1:
            raise ValueError("exploration_fraction must be >= 0 and interval_cap >= 1")


class QTable:
    """Q[interval row, hovering point + 1 (0 = base), action]."""

    def __init__(self, env: SortieEnv, interval_cap: int) -> None:
        limit = env.scenario.max_intervals
        self.rows = limit if limit > 0 else interval_cap
        self.values = np.zeros((self.rows, env.num_actions + 1, env.num_actions))

    def index(self, env: SortieEnv) -> tuple[int, int]:
        """The table cell of the environment's current state."""
        st = env.state
        return min(st.interval, self.rows - 1), st.hover_index + 1

    def update(
        self, s: tuple[int, int], a: int, reward: float, s_next: tuple[int, int],
        next_mask: np.ndarray, done: bool, config: QLearningConfig,
    ) -> None:
        """Q(s, a) += alpha (r + gamma max_a' Q(s', a') - Q(s, a))."""
        target = td_target(reward, self.values[s_next], next_mask, done, config.gamma)
        self.values[s][a] += config.learning_rate * (float(target) - self.values[s][a])


class QLearningPolicy:
    """Trains a Q-table for ``episodes`` episodes in ``begin``, then flies greedily on it."""

    name = "ql"

    def __init__(self, config: QLearningConfig, episodes: int, rng: np.random.Generator) -> None:
        if episodes < 0:
            raise ValueError(f"episodes must not be negative, got {episodes}")
        self.config = config
        self.episodes = episodes
        self.rng = rng
        self.table: QTable | None = None
        self.report = TrainingReport()

    def begin(self, env: SortieEnv) -> None:
        # One seeding block: the training future, the exploration and the greedy tie-breaks
        # each get their own stream of the policy's generator.
        world_rng, explore_rng, self._tie_rng = self.rng.spawn(3)
        cfg = self.config
        start = time.perf_counter()
        self.table = table = QTable(env, cfg.interval_cap)
        self.report = report = TrainingReport()
        if env.done:
            return
        world = TrainingWorld(env, world_rng)
        for episode in range(self.episodes):
            epsilon = linear_schedule(cfg.start_e, cfg.end_e, cfg.exploration_fraction * self.episodes, episode)
            train_env = world.reset()
            total = 0.0
            while not train_env.done:
                s = table.index(train_env)
                a = epsilon_greedy(table.values[s], train_env.action_mask(), epsilon, explore_rng)
                _, reward, terminated, truncated, info = train_env.step(a)
                table.update(s, a, reward, table.index(train_env), info["action_mask"],
                             terminated or truncated, cfg)
                total += reward
                report.steps += 1
                report.updates += 1
            report.returns.append(total)
            report.episodes += 1
        report.wall_s = time.perf_counter() - start

    def decide(self, env: SortieEnv) -> Decision:
        if self.table is None:
            raise ValueError("call begin(env) before decide(env)")
        values = self.table.values[self.table.index(env)]
        action = masked_argmax(values, env.action_mask(), self._tie_rng)
        return Decision(
            action,
            iterations=self.episodes,
            extra={"q": float(values[action]), "config": asdict(self.config), "training": self.report.summary()},
        )


def q_learning(spec: PolicySpec, rng: np.random.Generator) -> QLearningPolicy:
    """``ql``: ``spec.iterations`` training episodes (the budget in ms does not apply)."""
    return QLearningPolicy(QLearningConfig(), training_episodes(spec, "ql"), rng)
