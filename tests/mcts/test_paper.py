"""Algorithm 1 as written, and TS-MCTS's schedule."""

from __future__ import annotations

import numpy as np

from planner_service.mcts import PaperMctsPlanner
from planner_service.model import paper
from planner_service.policy import PolicySpec
from planner_service.sortie import run_sortie


def test_timesaving_schedule_section_3c():
    planner = PaperMctsPlanner(paper(), np.zeros((20, 3)), 500, np.random.default_rng(0), schedule="timesaving")
    # n = 500, m = 10: 500 from the first layer, 450 from the second, ... 50 at the tenth
    assert [planner.iterations_at(t) for t in range(10)] == [500, 450, 400, 350, 300, 250, 200, 150, 100, 50]
    assert planner.iterations_at(12) == 50  # past m (no interval limit): n / m
    literal = PaperMctsPlanner(paper(), np.zeros((20, 3)), 500, np.random.default_rng(0))
    assert {literal.iterations_at(t) for t in range(10)} == {500}
    # total iterations (m n / 2 + n / 2) against m n: 55 % of the work
    assert sum(planner.iterations_at(t) for t in range(10)) == 10 * 500 / 2 + 500 / 2


def test_the_literal_algorithm_gets_worse_with_more_iterations():
    """The paper's backup drops a node's own step from its value (see paper.py); measured
    on 15 seeds: fewer tasks per interval at 1000 iterations than at 10."""
    def throughput(n):
        runs = [run_sortie(paper(), "mcts-paper", s, PolicySpec(n)) for s in range(15)]
        assert all(r["fairness_violations"] == 0 and not r["energy_violation"] for r in runs)
        return np.mean([r["throughput_tasks_per_interval"] for r in runs])

    assert throughput(1000) < throughput(10) - 0.5


def test_same_seed_same_paper_decisions():
    a = run_sortie(paper(), "ts-mcts", 3, PolicySpec(200))
    b = run_sortie(paper(), "ts-mcts", 3, PolicySpec(200))
    assert a["hover_points"] == b["hover_points"]
