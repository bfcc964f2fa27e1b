"""The fleet's joint rules: one user served by one UAV at a time, one UAV on a point at a time."""

from __future__ import annotations

import numpy as np

from ..errors import ScenarioError
from ..interval import AT_BASE, NO_USER
from .claims import others_points
from .state import FleetState


class FleetError(ScenarioError):
    """A fleet input or joint state breaks a rule of the fleet: two UAVs on one hovering
    point, one user bound to two UAVs, an action for a UAV whose turn it is not."""


def check_joint(state: FleetState) -> None:
    """Raise ``FleetError`` if two active UAVs hold the same hovering point or are bound to
    the same user. The environment calls it after every change, so an illegal joint state
    cannot go unnoticed, whoever made it."""
    live = np.flatnonzero(state.active)
    points: dict[int, int] = {}
    users: dict[int, int] = {}
    for j in live:
        k, u = int(state.hover[j]), int(state.bound[j])
        if k != AT_BASE:
            if k in points:
                raise FleetError("hover", f"UAVs {points[k]} and {j} both hold hovering point {k}")
            points[k] = int(j)
        if u != NO_USER:
            if u in users:
                raise FleetError("user", f"user {u} is served by UAVs {users[u]} and {j} at once")
            users[u] = int(j)


def busy_users(state: FleetState, j: int) -> list[int]:
    """The users the other active UAVs' current intervals serve."""
    return [int(state.bound[i]) for i in state.others(j) if state.bound[i] != NO_USER]


def claimed_points(state: FleetState, j: int) -> list[int]:
    """The hovering points the other active UAVs have committed to: the one each holds now
    and the one each says it flies to next (its intent), sorted, each once: the fleet's claim
    rule (``claims.others_points``), the one the live fleet flies."""
    points = {int(i): [int(k) for k in (state.hover[i], state.intent[i]) if k != AT_BASE]
              for i in np.flatnonzero(state.active)}
    return sorted(others_points(int(j), points, points))


def visible_tasks(state: FleetState, j: int) -> np.ndarray:
    """The task counts as UAV ``j`` may serve them now: a user another UAV is serving is
    busy uploading there, so for ``j`` it has nothing to offload (0: not eligible (3)).
    A copy; the state's own counts are unchanged."""
    tasks = state.tasks.copy()
    tasks[busy_users(state, j)] = 0
    return tasks
