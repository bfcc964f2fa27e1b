"""The fleet's state: each UAV's own record and the users they share."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..interval import AT_BASE
from ..state import SortieState
from ..world import World


@dataclass
class FleetState:
    """Mutable state of one fleet sortie; ``copy()`` is a snapshot.

    Per UAV (N rows): ``uav_xyz`` (N, 3), ``hover`` (N,) int64 (its point, held while it
    is active, or ``AT_BASE``), ``battery_j``, ``energy_used_j``, ``reward_sum`` (N,),
    ``intervals`` (N,) int64 (its own interval count), ``clock_s`` (N,) (when its current
    interval ends), ``order`` (N,) int64 (ties of ``clock_s`` go to the lower order: who
    was scheduled first), ``bound`` (N,) int64 (the user its current interval serves, or
    ``NO_USER``), ``intent`` (N,) int64 (the point it says it will fly to next, or
    ``AT_BASE``: published, never enforced), ``active`` (N,) bool. Shared: ``users``
    (I, 3), ``tasks`` and ``served`` (I,) int64, ``events`` (1,) int64 (decisions so
    far: the world's chance happens once per decision), ``task_table`` (T, I).
    """

    uav_xyz: np.ndarray
    hover: np.ndarray
    battery_j: np.ndarray
    energy_used_j: np.ndarray
    reward_sum: np.ndarray
    intervals: np.ndarray
    clock_s: np.ndarray
    order: np.ndarray
    bound: np.ndarray
    intent: np.ndarray
    active: np.ndarray
    users: np.ndarray
    tasks: np.ndarray
    served: np.ndarray
    events: np.ndarray
    task_table: np.ndarray

    @property
    def num_uavs(self) -> int:
        return len(self.hover)

    def copy(self) -> "FleetState":
        return FleetState(**{f.name: getattr(self, f.name) if f.name == "task_table" else getattr(self, f.name).copy()
                             for f in fields(self)})

    def world(self, j: int) -> World:
        """UAV ``j``'s ``World`` over the shared users: its arrays are views into this state,
        so a kernel's step changes this state in place."""
        s = slice(j, j + 1)
        return World(self.uav_xyz[j], self.hover[s], self.users, self.tasks, self.served, self.battery_j[s],
                     self.intervals[s], self.energy_used_j[s], self.reward_sum[s])

    def chance_world(self, j: int) -> World:
        """``world(j)`` with the fleet's decision count as its interval: the world's chance
        (``world.advance``, a known task table's row) follows the decisions, not one UAV's."""
        w = self.world(j)
        return w._replace(interval=self.events)

    def sortie_state(self, j: int) -> SortieState:
        """What UAV ``j`` knows of the world as a single UAV would (its own record, the users
        as they report themselves), a copy: the view a planner blind to the others gets. A
        known task table is shifted so that its rows still meet the decisions they meet in
        the fleet."""
        shift = int(self.events[0] - self.intervals[j])
        return SortieState(
            uav_xyz=self.uav_xyz[j].copy(),
            hover_index=int(self.hover[j]),
            users=self.users.copy(),
            tasks=self.tasks.copy(),
            served=self.served.copy(),
            battery_j=float(self.battery_j[j]),
            interval=int(self.intervals[j]),
            energy_used_j=float(self.energy_used_j[j]),
            task_table=self.task_table[shift:] if shift else self.task_table,
            reward_sum=float(self.reward_sum[j]),
        )

    def others(self, j: int) -> np.ndarray:
        """The active UAVs other than ``j``."""
        mask = self.active.copy()
        mask[j] = False
        return np.flatnonzero(mask)

    def held_points(self, j: int) -> list[int]:
        """The hovering points the other active UAVs hold now."""
        return [int(self.hover[i]) for i in self.others(j) if self.hover[i] != AT_BASE]
