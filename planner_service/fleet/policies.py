"""The fleet's planners, each a ``FleetPolicy`` (``policy.py``) made of one single-UAV
``Policy`` per UAV (``registry.make_policy``: ``mcts`` by default), so every UAV plans
with today's planner; what differs is the view each is given."""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..model.fleet import FleetEnv
from ..policy import Decision, FleetPolicy, PolicySpec
from .dec_mcts import DecMctsConfig, DecMctsFleet
from .joint import JointFleet
from .per_uav import BASES, PerUav, intent_of

class IndependentFleet(PerUav):
    """``independent``: each UAV plans on its blind view (``FleetEnv.view``): it knows its
    own record and the users, not where the others are or whom they serve. The baseline."""

    name = "independent"

    def begin(self, env: FleetEnv) -> None:
        for j, policy in enumerate(self.policies):
            policy.begin(env.view(j))

    def decide(self, env: FleetEnv) -> Decision:
        j = env.due
        view = env.view(j)
        return self.legal(env, j, self.policies[j].decide(view) if view.action_mask().any() else None)


class ClaimsFleet(PerUav):
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
            return self.legal(env, j, None)
        d = self.policies[j].decide(view)
        mapped = Decision(int(keep[d.action]), tuple(int(keep[a]) for a in d.line), d.iterations, d.wall_s, d.extra)
        return self.legal(env, j, mapped)


def _dec_mcts(base: str, spec: PolicySpec, rngs: list[np.random.Generator], **settings: Any) -> FleetPolicy:
    return DecMctsFleet(base, spec, rngs, DecMctsConfig(**settings))


def _plain(cls: type) -> "FleetFactory":
    def make(base: str, spec: PolicySpec, rngs: list[np.random.Generator], **settings: Any) -> FleetPolicy:
        if settings:
            raise ValueError(f"fleet planner {cls.name!r} takes no settings, got {sorted(settings)}")
        return cls(base, spec, rngs)
    return make


FleetFactory = Callable[..., FleetPolicy]
"""(base, spec, rngs, **settings) -> FleetPolicy; settings are the planner's own
(``dec-mcts``: ``DecMctsConfig``'s fields, e.g. ``drop`` and ``age`` of its messages)."""
FLEET_PLANNERS: dict[str, FleetFactory] = {"independent": _plain(IndependentFleet), "claims": _plain(ClaimsFleet),
                                           "dec-mcts": _dec_mcts, "joint": _plain(JointFleet)}
LATER: tuple[str, ...] = ()
"""Fleet planners named by issue 26 and not built yet: none now."""


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


MESSAGE_PLANNERS = frozenset({"dec-mcts"})
"""The fleet planners whose UAVs send one another messages (their settings ``drop``, ``age``)."""


def takes_link(name: str) -> bool:
    """Whether fleet planner ``name`` sends messages whose loss and lateness can be set (a
    ``MessageLink``): the experiments read this, so a message-passing planner is swept
    without other edits. A factory may also take the link itself (keyword ``link``)."""
    if name not in FLEET_PLANNERS:
        raise ValueError(f"unknown fleet planner {name!r}; choose from {fleet_algorithms()}")
    return name in MESSAGE_PLANNERS or "link" in inspect.signature(FLEET_PLANNERS[name]).parameters


def make_fleet_policy(name: str, base: str, spec: PolicySpec, rngs: list[np.random.Generator],
                      link: MessageLink | None = None, **settings: Any) -> FleetPolicy:
    """The fleet planner ``name`` with ``base`` as each UAV's planner, one generator per UAV,
    its own ``settings`` (``FleetFactory``), and ``link`` for a planner that sends messages
    (``takes_link``; refused by the others): its loss and lateness are the planner's ``drop``
    and ``age``."""
    if name in LATER:
        raise ValueError(f"fleet planner {name!r} is not built yet (issue 26, second half); choose from "
                         f"{fleet_algorithms()}")
    if name not in FLEET_PLANNERS:
        raise ValueError(f"unknown fleet planner {name!r}; choose from {fleet_algorithms()}")
    factory = FLEET_PLANNERS[name]
    if link is not None:
        if not takes_link(name):
            raise ValueError(f"fleet planner {name!r} sends no messages: a message link (loss, lateness) does not apply")
        if "link" in inspect.signature(factory).parameters:
            settings["link"] = link
        else:
            settings.update(drop=link.loss, age=link.late_intervals)
    try:
        return factory(base, spec, rngs, **settings)
    except TypeError as err:  # a setting the planner does not have
        raise ValueError(f"fleet planner {name!r}: {err}") from None


__all__ = ["BASES", "FLEET_PLANNERS", "LATER", "MESSAGE_PLANNERS", "ClaimsFleet", "FleetFactory", "IndependentFleet",
           "MessageLink", "fleet_algorithms", "intent_of", "make_fleet_policy", "takes_link"]
