"""The sortie's state: what the UAV knows at the start of an interval."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .world import World, world_from


@dataclass
class SortieState:
    """Mutable state of one sortie. ``copy()`` is the cheap snapshot playouts use.

    Shapes: ``uav_xyz`` (3,), ``users`` (I, 3), ``tasks`` and ``served`` (I,) int64,
    ``task_table`` (T, I) int64 (T may be 0: tasks are drawn).
    """

    uav_xyz: np.ndarray
    hover_index: int
    users: np.ndarray
    tasks: np.ndarray
    served: np.ndarray
    battery_j: float
    interval: int
    energy_used_j: float
    task_table: np.ndarray
    reward_sum: float = 0.0
    """Sum of q over the intervals flown so far (the sortie average's numerator)."""

    def copy(self) -> "SortieState":
        return SortieState(
            uav_xyz=self.uav_xyz.copy(),
            hover_index=self.hover_index,
            users=self.users.copy(),
            tasks=self.tasks.copy(),
            served=self.served.copy(),
            battery_j=self.battery_j,
            interval=self.interval,
            energy_used_j=self.energy_used_j,
            task_table=self.task_table,  # never written: shared
            reward_sum=self.reward_sum,
        )

    def world(self) -> World:
        """This state as the kernels' ``World`` record. Its arrays are this state's own where
        they already have the kernels' type, so a step changes both; ``absorb`` then brings
        the rest (the scalars) back."""
        return world_from(self.uav_xyz, self.hover_index, self.users, self.tasks, self.served, self.battery_j,
                          self.interval, self.energy_used_j, self.reward_sum)

    def absorb(self, w: World) -> None:
        """Take the values of ``w`` (made by ``world()`` and stepped) into this state."""
        for name in ("uav_xyz", "users", "tasks", "served"):
            mine, theirs = getattr(self, name), getattr(w, name)
            if mine is not theirs:
                mine[...] = theirs.reshape(mine.shape)
        self.hover_index = int(w.hover[0])
        self.battery_j = float(w.battery_j[0])
        self.interval = int(w.interval[0])
        self.energy_used_j = float(w.energy_used_j[0])
        self.reward_sum = float(w.reward_sum[0])
