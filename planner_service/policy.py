"""What every planner offers the sortie runner: the contract the planners import (their
registry by name is ``registry.py``, which imports them)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from .model import SortieEnv
from .model.fleet import FleetEnv


@dataclass(frozen=True)
class Decision:
    """A chosen hovering point, and the line the planner expects to fly after it."""

    action: int
    line: tuple[int, ...] = ()
    iterations: int = 0
    wall_s: float = 0.0
    extra: dict = field(default_factory=dict)


class Policy(Protocol):
    """A planner. ``begin`` runs once per sortie after ``env.reset`` (learners train
    there); ``decide`` picks the next hovering point among ``env.action_mask()`` and must
    not change ``env``."""

    name: str

    def begin(self, env: SortieEnv) -> None: ...

    def decide(self, env: SortieEnv) -> Decision: ...


@dataclass(frozen=True)
class PolicySpec:
    """How the command line asks for a planner."""

    iterations: int | None = 1000
    """Iterations per decision for MCTS, training episodes for the learners; None with a
    ``budget_ms``: only the clock limits MCTS."""
    budget_ms: float | None = None
    """Wall-clock budget per MCTS decision, in milliseconds."""


Factory = Callable[[PolicySpec, np.random.Generator], Policy]


class FleetPolicy(Protocol):
    """A fleet's planner: one decision at a time, for the UAV whose turn it is
    (``env.due``). ``begin`` runs once per sortie after ``env.reset``; ``decide`` picks
    a point among ``env.action_mask(env.due)``, its ``line`` the points it expects to fly
    after (the second is published to the others as its intent), and must not change
    ``env``. Each UAV's own planner is a ``Policy`` on a view of its own
    (``FleetEnv.view``), so every single-UAV planner plans a UAV of a fleet unchanged."""

    name: str

    def begin(self, env: FleetEnv) -> None: ...

    def decide(self, env: FleetEnv) -> Decision: ...
