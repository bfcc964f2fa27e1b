"""The MCTS planners as policies of the sortie runner, by name."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from ..model import SortieEnv
from ..policy import Decision, PolicySpec
from .paper import PaperMctsPlanner
from .planner import MctsConfig, MctsPlanner


class PlannerPolicy:
    """Builds a planner for the sortie's scenario in ``begin`` and asks it each interval."""

    def __init__(self, name: str, build: Callable[[SortieEnv], object]) -> None:
        self.name = name
        self._build = build
        self.planner = None

    def begin(self, env: SortieEnv) -> None:
        self.planner = self._build(env)

    def decide(self, env: SortieEnv) -> Decision:
        return self.planner.plan(env.state)  # type: ignore[union-attr]


def sound_mcts(spec: PolicySpec, rng: np.random.Generator, **settings) -> PlannerPolicy:
    """``mcts``: the open-loop planner with tree reuse (``planner.py``)."""
    config = replace(MctsConfig(), iterations=spec.iterations, budget_ms=spec.budget_ms, **settings)
    return PlannerPolicy("mcts", lambda env: MctsPlanner(env.scenario, env.hover_points, config, rng))


def _iterations(spec: PolicySpec, name: str) -> int:
    if spec.iterations is None:
        raise ValueError(f"{name} runs a number of iterations (the paper's episodes); give --iterations")
    return spec.iterations


def paper_mcts(spec: PolicySpec, rng: np.random.Generator) -> PlannerPolicy:
    """``mcts-paper``: Algorithm 1 as written (``paper.py``)."""
    n = _iterations(spec, "mcts-paper")
    return PlannerPolicy("mcts-paper", lambda env: PaperMctsPlanner(env.scenario, env.hover_points, n, rng))


def timesaving_mcts(spec: PolicySpec, rng: np.random.Generator) -> PlannerPolicy:
    """``ts-mcts``: Algorithm 1 with Section III-C's shrinking iteration schedule."""
    n = _iterations(spec, "ts-mcts")
    return PlannerPolicy(
        "ts-mcts", lambda env: PaperMctsPlanner(env.scenario, env.hover_points, n, rng, schedule="timesaving")
    )
