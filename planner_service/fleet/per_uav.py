"""One single-UAV planner per UAV, and the fallback every fleet planner shares."""

from __future__ import annotations

import numpy as np

from ..model.fleet import FleetEnv
from ..model.interval import AT_BASE
from ..policy import Decision, Policy, PolicySpec
from ..registry import make_policy

BASES = ("mcts", "mcts-paper", "ts-mcts", "greedy", "random")
"""Single-UAV planners a fleet's UAV may use: those whose ``begin`` leaves the environment
alone (``ql`` and ``dqn`` train on theirs, which for a UAV of a fleet is a view)."""


def intent_of(decision: Decision) -> int:
    """The point a decision says its UAV flies to after this one (the second of its line),
    or ``AT_BASE`` when its line stops at the first."""
    return int(decision.line[1]) if len(decision.line) > 1 else AT_BASE


class PerUav:
    """One single-UAV planner per UAV, and the one rule both fleet planners share: a
    choice the fleet does not allow (a point another UAV holds, a point whose only users
    another UAV serves) is replaced by the allowed point of largest q (11) under the
    fleet's rules, and counted (``blocked``)."""

    name = "per-uav"

    def __init__(self, base: str, spec: PolicySpec, rngs: list[np.random.Generator]) -> None:
        if base not in BASES:
            raise ValueError(f"unknown planner for a fleet's UAV {base!r}; choose from {list(BASES)}")
        self.base = base
        self.policies: list[Policy] = [make_policy(base, spec, rng) for rng in rngs]
        self.blocked = 0

    def legal(self, env: FleetEnv, j: int, decision: Decision | None) -> Decision:
        """``decision`` if the fleet allows it, else the fallback (None: the UAV's view
        allowed nothing, though the fleet allows something: a point whose nearest user
        another UAV serves may be within budget with the next nearest)."""
        if decision is not None and env.action_mask(j)[decision.action]:
            return decision
        self.blocked += 1
        action = int(np.argmax(env.action_values(j)))
        if decision is None:
            return Decision(action, (action,), extra={"blocked": None})
        return Decision(action, (action,), decision.iterations, decision.wall_s,
                        {**decision.extra, "blocked": decision.action})
