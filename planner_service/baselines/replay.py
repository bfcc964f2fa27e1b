"""Experience replay as preallocated arrays (a ring buffer), for the DQN baseline."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Batch:
    """Sampled transitions. Shapes: ``obs``/``next_obs`` (B, D), ``actions`` (B,) int,
    ``rewards`` (B,), ``next_masks`` (B, A) bool, ``dones`` (B,) bool."""

    obs: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    next_obs: np.ndarray
    next_masks: np.ndarray
    dones: np.ndarray


class ReplayBuffer:
    """The last ``capacity`` transitions; older ones are overwritten first.

    The next state's action mask is stored with each transition because the TD target
    maximises only over the actions allowed there.
    """

    def __init__(self, capacity: int, obs_dim: int, num_actions: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be positive, got {capacity}")
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_dim))
        self.actions = np.zeros(capacity, dtype=np.int64)
        self.rewards = np.zeros(capacity)
        self.next_obs = np.zeros((capacity, obs_dim))
        self.next_masks = np.zeros((capacity, num_actions), dtype=bool)
        self.dones = np.zeros(capacity, dtype=bool)
        self.size = 0
        self._next = 0

    def add(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, next_mask: np.ndarray, done: bool
    ) -> None:
        i = self._next
        self.obs[i] = obs
        self.actions[i] = action
        self.rewards[i] = reward
        self.next_obs[i] = next_obs
        self.next_masks[i] = next_mask
        self.dones[i] = done
        self._next = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator) -> Batch:
        """``batch_size`` transitions drawn uniformly with replacement."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = rng.integers(0, self.size, size=batch_size)
        return Batch(
            self.obs[idx], self.actions[idx], self.rewards[idx],
            self.next_obs[idx], self.next_masks[idx], self.dones[idx],
        )
