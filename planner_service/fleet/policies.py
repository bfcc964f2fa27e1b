"""The fleet's planners, each a ``FleetPolicy`` (``policy.py``) made of one single-UAV
``Policy`` per UAV (``registry.make_policy``: ``mcts`` by default), so every UAV plans
with today's planner; what differs is the view each is given."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..model.fleet import FleetEnv
from ..model.interval import AT_BASE
from ..policy import Decision, FleetPolicy, Policy, PolicySpec
from ..registry import make_policy

BASES = ("mcts", "mcts-paper", "ts-mcts", "greedy", "random")
"""Single-UAV planners a fleet's UAV may use: those whose ``begin`` leaves the environment
alone (``ql`` and ``dqn`` train on theirs, which for a UAV of a fleet is a view)."""


def intent_of(decision: Decision) -> int:
    """The point a decision says its UAV flies to after this one (the second of its line),
    or ``AT_BASE`` when its line stops at the first."""
    return int(decision.line[1]) if len(decision.line) > 1 else AT_BASE


class _PerUav:
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

    def _legal(self, env: FleetEnv, j: int, decision: Decision | None) -> Decision:
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


class IndependentFleet(_PerUav):
    """``independent``: each UAV plans on its blind view (``FleetEnv.view``): it knows its
    own record and the users, not where the others are or whom they serve. The baseline."""

    name = "independent"

    def begin(self, env: FleetEnv) -> None:
        for j, policy in enumerate(self.policies):
            policy.begin(env.view(j))

    def decide(self, env: FleetEnv) -> Decision:
        j = env.due
        view = env.view(j)
        return self._legal(env, j, self.policies[j].decide(view) if view.action_mask().any() else None)


class ClaimsFleet(_PerUav):
    """``claims``: each UAV plans on a view without what the others have committed to
    (``FleetEnv.claims_view``: the points they hold or fly to next, the users they serve).
    A UAV's planner is rebuilt when the claimed points change (its points are renumbered:
    its tree cannot be kept) and reused, tree and all, while they stay the same."""

    name = "claims"

    def __init__(self, base: str, spec: PolicySpec, rngs: list[np.random.Generator]) -> None:
        super().__init__(base, spec, rngs)
        self._keep: list[np.ndarray | None] = [None] * len(rngs)

    def begin(self, env: FleetEnv) -> None:
        self._keep = [None] * env.num_uavs  # each UAV's planner is built at its first decision

    def decide(self, env: FleetEnv) -> Decision:
        j = env.due
        view, keep = env.claims_view(j)
        last = self._keep[j]
        if last is None or not np.array_equal(last, keep):
            self.policies[j].begin(view)
            self._keep[j] = keep
        if not view.action_mask().any():
            return self._legal(env, j, None)
        d = self.policies[j].decide(view)
        mapped = Decision(int(keep[d.action]), tuple(int(keep[a]) for a in d.line), d.iterations, d.wall_s, d.extra)
        return self._legal(env, j, mapped)


FleetFactory = Callable[[str, PolicySpec, list[np.random.Generator]], FleetPolicy]
FLEET_PLANNERS: dict[str, FleetFactory] = {"independent": IndependentFleet, "claims": ClaimsFleet}
LATER = ("dec-mcts", "joint")
"""Fleet planners of issue 26 not built yet (its second half)."""


def fleet_algorithms() -> list[str]:
    """Every fleet planner ``make_fleet_policy`` accepts."""
    return sorted(FLEET_PLANNERS)


@dataclass(frozen=True)
class MessageLink:
    """How the messages between a fleet's UAVs fare, for the planners that send some
    (``takes_link``): each message is lost with probability ``loss``, and the one a UAV
    reads is ``late_intervals`` of its sender's intervals old (0: the latest)."""

    loss: float = 0.0
    """Probability that a message is lost, in [0, 1)."""
    late_intervals: int = 0
    """How many of the sender's intervals old the message a UAV reads is (0: fresh)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.loss < 1.0:
            raise ValueError(f"message loss must be in [0, 1), got {self.loss}")
        if self.late_intervals < 0:
            raise ValueError(f"late_intervals must be at least 0, got {self.late_intervals}")


def takes_link(name: str) -> bool:
    """Whether fleet planner ``name`` sends messages whose loss and lateness can be set: its
    factory takes a keyword ``link`` (a ``MessageLink``). The experiments read this, so a
    message-passing planner added to ``FLEET_PLANNERS`` is swept without other edits."""
    if name not in FLEET_PLANNERS:
        raise ValueError(f"unknown fleet planner {name!r}; choose from {fleet_algorithms()}")
    return "link" in inspect.signature(FLEET_PLANNERS[name]).parameters


def make_fleet_policy(name: str, base: str, spec: PolicySpec, rngs: list[np.random.Generator],
                      link: MessageLink | None = None) -> FleetPolicy:
    """The fleet planner ``name`` with ``base`` as each UAV's planner, one generator per UAV;
    ``link`` for a planner that sends messages (``takes_link``), refused by the others."""
    if name in LATER and name not in FLEET_PLANNERS:
        raise ValueError(f"fleet planner {name!r} is not built yet (issue 26, second half); choose from "
                         f"{fleet_algorithms()}")
    if name not in FLEET_PLANNERS:
        raise ValueError(f"unknown fleet planner {name!r}; choose from {fleet_algorithms()}")
    if link is None:
        return FLEET_PLANNERS[name](base, spec, rngs)
    if not takes_link(name):
        raise ValueError(f"fleet planner {name!r} sends no messages: a message link (loss, lateness) does not apply")
    return FLEET_PLANNERS[name](base, spec, rngs, link=link)  # type: ignore[call-arg]
