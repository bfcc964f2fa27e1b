"""Child process of the benchmark: the plain reference planner on pickled states.

Started with ``UAV_PLANNER_NO_NUMBA=1`` so that the model runs as plain Python too. Reads
a pickle (scenario, hover points, states, config, seeds) on stdin; writes JSON on stdout.
"""

from __future__ import annotations

import json
import pickle
import sys

import numpy as np

from ..mcts.reference import ReferenceMcts
from .decisions import time_decisions


def main() -> int:
    scenario, hover_points, states, config, seeds = pickle.load(sys.stdin.buffer)

    def decide(i, state):
        return ReferenceMcts(scenario, hover_points, config, np.random.default_rng(seeds[i])).plan(state)

    timing = time_decisions(states, decide)
    json.dump({"seconds": timing.seconds, "actions": timing.actions, "iterations": timing.iterations}, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
