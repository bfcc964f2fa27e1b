"""Every planner by name: the table of algorithms the command line, the experiments and the
sortie runner choose from. Apart from the contract (``policy.py``) so that the planners
import the contract and this module imports the planners, with no cycle between them."""

from __future__ import annotations

import numpy as np

from .baselines import BASELINES
from .mcts import PLANNERS
from .policy import Factory, Policy, PolicySpec

FACTORIES: dict[str, Factory] = {**BASELINES, **PLANNERS}


def algorithms() -> list[str]:
    """Every algorithm name ``make_policy`` accepts."""
    return sorted(FACTORIES)


def make_policy(name: str, spec: PolicySpec, rng: np.random.Generator) -> Policy:
    """The planner called ``name`` (see ``algorithms()``)."""
    if name not in FACTORIES:
        raise ValueError(f"unknown algorithm {name!r}; choose from {sorted(FACTORIES)}")
    return FACTORIES[name](spec, rng)
