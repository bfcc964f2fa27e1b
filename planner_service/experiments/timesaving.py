"""What the time-saving schedule saves, from the planner's own schedule (Section III-C):
apart from the registry and the plots, which both use it (each importing the other for it
was an import cycle)."""

from __future__ import annotations

import numpy as np

from ..model import Scenario, hover_points


def iterations_saved(scenario: Scenario, n: int, intervals: int) -> float:
    """1 - (TS-MCTS iterations) / (Algorithm 1 iterations) over a sortie of ``intervals``
    decisions, from the planner's own schedule (Section III-C)."""
    from ..mcts import PaperMctsPlanner  # on use: listing the experiments loads no planner

    planner = PaperMctsPlanner(scenario, hover_points(scenario), n, np.random.default_rng(0), schedule="timesaving")
    ts = sum(planner.iterations_at(t) for t in range(intervals))
    return 1.0 - ts / (n * intervals)
