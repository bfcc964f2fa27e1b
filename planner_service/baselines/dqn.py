"""Deep Q-network (Mnih et al., 2015) on numpy, the paper's middle baseline (Section IV).

Laid out after cleanrl's ``dqn.py``: a flat hyperparameter dataclass, one seeding block,
an epsilon schedule, a replay buffer, a target network synced every N steps, and the TD
target in three lines. Unlike cleanrl it is a library class: ``begin`` trains, ``decide``
acts greedily.

State encoding (the paper's DQN reference uses situation maps, images of the area; a
feature vector carries the same information without a convolution), concatenated:
- one-hot of the current hovering point, or the base (K + 1);
- battery left above the threshold, as a fraction of the usable budget (1);
- interval index over the sortie limit (1);
- per user: x / R, y / R, tasks / u_max, services / limit (4 I): where the users are,
  what they ask and what the fairness rule (3), (9c) still allows;
- per hovering point: the immediate reward q (11) where allowed (0 elsewhere) and the
  allowed flag (2 K). The model is known to the UAV, so this is computable from the
  observation; it is the numeric form of a situation map, and it spares the network from
  relearning the channel and energy equations from a few thousand transitions.
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
from .mlp import MLP, Adam
from .replay import ReplayBuffer


@dataclass(frozen=True)
class DQNConfig:
    """Hyperparameters of the DQN learner (logged with every decision)."""

    learning_rate: float = 1e-3
    """Adam step size."""
    gamma: float = 1.0
    """Discount. The sortie has at most ``max_intervals`` steps, the paper's return is
    undiscounted, and the interval index is in the state, so the values stay bounded."""
    hidden_sizes: tuple[int, ...] = (64, 64)
    """Widths of the ReLU hidden layers."""
    buffer_size: int = 10_000
    """Replay capacity in transitions: 1000 episodes of about 10 steps fit whole."""
    batch_size: int = 32
    """Transitions per gradient step."""
    learning_starts: int = 64
    """Environment steps collected before the first gradient step (about 6 episodes), so
    that even a 10-episode budget trains a little."""
    train_frequency: int = 1
    """Environment steps between gradient steps."""
    target_network_frequency: int = 100
    """Environment steps between hard copies of the online network into the target."""
    start_e: float = 1.0
    """Exploration epsilon at the first training episode."""
    end_e: float = 0.05
    """Exploration epsilon at the end of the schedule."""
    exploration_fraction: float = 0.5
    """Fraction of the training episodes over which epsilon falls from start to end."""
    interval_cap: int = 16
    """Interval scale of the state when the scenario has no interval limit."""

    def __post_init__(self) -> None:
        if not self.learning_rate > 0 or not 0.0 <= self.gamma <= 1.0:
            raise ValueError("learning_rate must be positive and gamma in [0, 1]")
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"hidden_sizes must be positive widths, got {self.hidden_sizes}")
        counts = (self.buffer_size, self.batch_size, self.train_frequency, self.target_network_frequency, self.interval_cap)
        if min(counts) < 1 or self.learning_starts < 0:
            raise ValueError("buffer, batch, frequencies and interval_cap must be >= 1; learning_starts >= 0")
        if not (0.0 <= self.end_e <= 1.0 and 0.0 <= self.start_e <= 1.0) or self.exploration_fraction < 0:
            raise ValueError("start_e and end_e must lie in [0, 1], exploration_fraction >= 0")


class Features:
    """The state vector of the module docstring, for one scenario."""

    def __init__(self, env: SortieEnv, interval_cap: int) -> None:
        s = env.scenario
        self.num_actions = env.num_actions
        self.num_users = s.num_users
        self.area_m = s.area_side_m
        self.task_max = s.task_max
        self.max_services = s.max_services_per_user
        self.floor_j = s.energy_floor_j
        self.usable_j = s.battery_j - s.energy_floor_j
        self.intervals = s.max_intervals if s.max_intervals > 0 else interval_cap
        self.dim = (self.num_actions + 1) + 2 + 4 * self.num_users + 2 * self.num_actions

    def __call__(self, env: SortieEnv) -> tuple[np.ndarray, np.ndarray]:
        """The state vector (D,) and the action mask (K,) of ``env`` now."""
        st = env.state
        q = env.action_values()
        mask = np.isfinite(q)
        k = self.num_actions
        x = np.zeros(self.dim)
        x[st.hover_index + 1] = 1.0
        x[k + 1] = (st.battery_j - self.floor_j) / self.usable_j
        x[k + 2] = min(st.interval, self.intervals) / self.intervals
        users = x[k + 3 : k + 3 + 4 * self.num_users].reshape(self.num_users, 4)
        users[:, 0:2] = st.users[:, 0:2] / self.area_m
        users[:, 2] = st.tasks / self.task_max
        users[:, 3] = st.served / self.max_services
        tail = x[k + 3 + 4 * self.num_users :]
        tail[:k] = np.where(mask, q, 0.0)
        tail[k:] = mask
        return x, mask


class DQNPolicy:
    """Trains a Q-network for ``episodes`` episodes in ``begin``, then flies greedily on it."""

    name = "dqn"

    def __init__(self, config: DQNConfig, episodes: int, rng: np.random.Generator) -> None:
        if episodes < 0:
            raise ValueError(f"episodes must not be negative, got {episodes}")
        self.config = config
        self.episodes = episodes
        self.rng = rng
        self.q_network: MLP | None = None
        self.features: Features | None = None
        self.report = TrainingReport()

    def begin(self, env: SortieEnv) -> None:
        cfg = self.config
        # One seeding block: weights, training future, exploration and minibatches each
        # draw from their own stream of the policy's generator.
        init_rng, world_rng, explore_rng, batch_rng = self.rng.spawn(4)
        start = time.perf_counter()
        self.features = features = Features(env, cfg.interval_cap)
        sizes = (features.dim, *cfg.hidden_sizes, env.num_actions)
        self.q_network = q_network = MLP(sizes, init_rng)
        target_network = MLP(sizes, init_rng)
        target_network.copy_from(q_network)
        optimizer = Adam(q_network.params, cfg.learning_rate)
        rb = ReplayBuffer(cfg.buffer_size, features.dim, env.num_actions)
        self.report = report = TrainingReport()
        if env.done:
            return
        world = TrainingWorld(env, world_rng)
        global_step = 0
        for episode in range(self.episodes):
            epsilon = linear_schedule(cfg.start_e, cfg.end_e, cfg.exploration_fraction * self.episodes, episode)
            train_env = world.reset()
            obs, mask = features(train_env)
            total = 0.0
            while not train_env.done:
                values = q_network.forward(obs[None, :])[0]
                action = epsilon_greedy(values, mask, epsilon, explore_rng)
                _, reward, terminated, truncated, _ = train_env.step(action)
                next_obs, next_mask = features(train_env)
                rb.add(obs, action, reward, next_obs, next_mask, terminated or truncated)
                obs, mask = next_obs, next_mask
                total += reward
                global_step += 1

                if global_step > cfg.learning_starts and global_step % cfg.train_frequency == 0:
                    data = rb.sample(cfg.batch_size, batch_rng)
                    next_values = target_network.forward(data.next_obs)
                    y = td_target(data.rewards, next_values, data.next_masks, data.dones, cfg.gamma)
                    _, grads = q_network.loss_and_grad(data.obs, data.actions, y)
                    optimizer.step(grads)
                    report.updates += 1
                if global_step % cfg.target_network_frequency == 0:
                    target_network.copy_from(q_network)
            report.returns.append(total)
            report.episodes += 1
        report.steps = global_step
        report.wall_s = time.perf_counter() - start

    def q_values(self, env: SortieEnv) -> tuple[np.ndarray, np.ndarray]:
        """The network's Q-values (K,) at ``env``'s state, and the action mask (K,)."""
        if self.q_network is None or self.features is None:
            raise ValueError("call begin(env) before asking for Q-values")
        obs, mask = self.features(env)
        return self.q_network.forward(obs[None, :])[0], mask

    def decide(self, env: SortieEnv) -> Decision:
        values, mask = self.q_values(env)
        action = masked_argmax(values, mask)
        return Decision(
            action,
            iterations=self.episodes,
            extra={"q": float(values[action]), "config": asdict(self.config), "training": self.report.summary()},
        )


def dqn(spec: PolicySpec, rng: np.random.Generator) -> DQNPolicy:
    """``dqn``: ``spec.iterations`` training episodes (the budget in ms does not apply)."""
    return DQNPolicy(DQNConfig(), training_episodes(spec, "dqn"), rng)
