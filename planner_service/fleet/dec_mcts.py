"""``dec-mcts``: each UAV grows its own tree over its own points (today's ``mcts``) and plays
its futures against the others' plans, sampled from the distributions they published
(Best et al., "Dec-MCTS", IJRR 2019, Algorithm 1; docs/PLANNER.md, "dec-mcts").

Per decision of UAV j:
1. its inbox (``LinkModel``): each other UAV's newest message that reached it;
2. its view leaves out the points those messages say are held and the users being served
   (``FleetEnv.partial_view``);
3. each of its S futures samples one sequence from each other's distribution; the users
   that sequence would serve (its points' nearest eligible users, taken in turn) have
   nothing to offload for j in that future at the interval it takes them (m-th point: j's
   interval m), so j's playouts see the users the others will probably take;
4. after the search, its own distribution (the simplification of the paper's variational
   step, docs/PLANNER.md): the k most visited children below the chosen point, each with
   its principal line to length d, weighted by a softmax over their mean returns with a
   temperature that cools as the evidence grows: tau = tau_0 / sqrt(1 + n / k), n the
   chosen point's visits. It is sent as ``messages.PlanMessage`` bytes.

Without messages (lost, or none yet) a UAV plans as ``independent`` does: the fleet's
fallback (``per_uav.PerUav.legal``) then replaces a choice the fleet refuses, and the
environment refuses every double service and hold whatever the messages said.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..model.fleet import FleetEnv
from ..model.fleet.rules import visible_tasks
from ..model.interval import AT_BASE, NO_USER, served_user
from ..policy import Decision, PolicySpec
from .messages import PlanMessage, decode
from .per_uav import PerUav


@dataclass(frozen=True)
class DecMctsConfig:
    """Settings of ``dec-mcts`` beyond each UAV's ``mcts``."""

    top_k: int = 4
    """Sequences in a UAV's published distribution (the paper's sample set size)."""
    depth: int = 3
    """Points per published sequence (its next d points after the one it flies now)."""
    temperature: float = 0.1
    """tau_0 of the softmax over mean returns (the sortie's average q, about 0.2-0.5)."""
    drop: float = 0.0
    """Probability that a message does not reach a given UAV (drawn per message and receiver)."""
    age: int = 0
    """Messages arrive this many of the sender's intervals late (0: before anyone's next decision)."""

    def __post_init__(self) -> None:
        if not 1 <= self.top_k <= 255 or not 1 <= self.depth <= 255:
            raise ValueError(f"top_k and depth must lie in [1, 255], got {self.top_k}, {self.depth}")
        if not (self.temperature > 0 and math.isfinite(self.temperature)):
            raise ValueError(f"temperature must be positive and finite, got {self.temperature}")
        if not 0.0 <= self.drop <= 1.0:
            raise ValueError(f"drop must lie in [0, 1], got {self.drop}")
        if self.age < 0:
            raise ValueError(f"age must not be negative, got {self.age}")


class LinkModel:
    """The fleet's broadcast link, simulated: every message is kept as its bytes; whether it
    reaches each receiver is drawn when it is sent (``drop``), and a receiver sees only
    messages at least ``age`` of the sender's messages old."""

    def __init__(self, uavs: int, drop: float, age: int, rng: np.random.Generator) -> None:
        self.drop, self.age, self.rng = drop, age, rng
        self.sent: list[list[tuple[bytes, np.ndarray]]] = [[] for _ in range(uavs)]
        """Per sender, its messages in order, each with (N,) bool: reached that receiver."""

    def send(self, sender: int, data: bytes) -> None:
        reached = self.rng.random(len(self.sent)) >= self.drop if self.drop > 0 else np.ones(len(self.sent), bool)
        self.sent[sender].append((data, reached))

    def inbox(self, receiver: int) -> dict[int, PlanMessage]:
        """Per other sender, the newest of its messages that reached ``receiver`` and is old enough."""
        out = {}
        for sender, history in enumerate(self.sent):
            if sender == receiver:
                continue
            for data, reached in reversed(history[:max(len(history) - self.age, 0)]):
                if reached[receiver]:
                    out[sender] = decode(data)
                    break
        return out

    @property
    def sizes(self) -> list[int]:
        return [len(data) for history in self.sent for data, _ in history]


class DecMctsFleet(PerUav):
    """``dec-mcts`` (the module's docstring). Each UAV's base planner must be ``mcts``."""

    name = "dec-mcts"

    def __init__(self, base: str, spec: PolicySpec, rngs: list[np.random.Generator],
                 config: DecMctsConfig | None = None) -> None:
        if base != "mcts":
            raise ValueError(f"dec-mcts grows each UAV's tree with mcts (its futures carry the others' plans); "
                             f"got base {base!r}")
        super().__init__(base, spec, rngs)
        self.config = config or DecMctsConfig()
        # streams of their own, spawned from each UAV's seed and not drawn from it: a fleet
        # of one draws exactly what today's mcts draws
        self._samplers = [np.random.default_rng(_spawn(r)) for r in rngs]
        self._link_seed = _spawn(rngs[0])
        self._keep: list[np.ndarray | None] = [None] * len(rngs)
        self.link = LinkModel(len(rngs), self.config.drop, self.config.age, np.random.default_rng(self._link_seed))

    def begin(self, env: FleetEnv) -> None:
        self._keep = [None] * env.num_uavs
        self.link = LinkModel(env.num_uavs, self.config.drop, self.config.age, np.random.default_rng(self._link_seed))

    def decide(self, env: FleetEnv) -> Decision:
        j = env.due
        inbox = {i: m for i, m in self.link.inbox(j).items() if i not in env.ended}
        held = sorted({m.point for m in inbox.values() if m.point != AT_BASE})
        busy = sorted({m.user for m in inbox.values() if m.user != NO_USER})
        view, keep = env.partial_view(j, held, busy)
        last = self._keep[j]
        policy = self.policies[j]
        if last is None or not np.array_equal(last, keep):
            policy.begin(view)
            self._keep[j] = keep
        if not view.action_mask().any():
            decision = self.legal(env, j, None)
            self._publish(env, j, decision, None, keep)
            return decision
        planner = policy.planner  # type: ignore[attr-defined]
        planner.shape_futures = self._shaper(env, j, inbox, view.state.tasks)
        d = policy.decide(view)
        planner.shape_futures = None
        mapped = Decision(int(keep[d.action]), tuple(int(keep[a]) for a in d.line), d.iterations, d.wall_s, d.extra)
        decision = self.legal(env, j, mapped)
        self._publish(env, j, decision, planner if decision is mapped else None, keep, d.action)
        return decision

    # --- the others' plans in j's futures --------------------------------------------------
    def _shaper(self, env: FleetEnv, j: int, inbox: dict[int, PlanMessage],
                tasks: np.ndarray) -> Callable[[np.ndarray, np.ndarray], None]:
        """The futures' hook (``MctsPlanner.shape_futures``): per future, one sampled sequence
        per other UAV; the users it would take have no tasks for j at the interval it takes them."""
        taken = {i: self._sequence_users(env, i, m, tasks) for i, m in inbox.items() if len(m.probs)}
        rng = self._samplers[j]

        def shape(moves: np.ndarray, news: np.ndarray) -> None:
            horizon = news.shape[1]
            for i, users in taken.items():
                picks = rng.choice(len(inbox[i].probs), size=news.shape[0], p=inbox[i].probs)
                for s, pick in enumerate(picks):
                    for m, user in enumerate(users[pick]):
                        if user != NO_USER and m < horizon:  # the m+1-th point: j's interval m+1, news row m
                            news[s, m, user] = 0

        return shape

    @staticmethod
    def _sequence_users(env: FleetEnv, i: int, message: PlanMessage, tasks: np.ndarray) -> list[list[int]]:
        """For each of UAV i's published sequences, the users its points would serve, in turn
        (each the nearest eligible one not already taken by the sequence), from now's users."""
        st = env.state
        p, hp = env.params[i], env.hover_points[i]
        out = []
        for row in message.sequences:
            left, served = tasks.copy(), st.served.copy()
            users = []
            for k in row:
                user = NO_USER if k == AT_BASE else served_user(p, hp[int(k)], st.users, left, served)
                if user != NO_USER:
                    left[user] = 0
                    served[user] += 1
                users.append(int(user))
            out.append(users)
        return out

    # --- j's own distribution -------------------------------------------------------------------
    def _publish(self, env: FleetEnv, j: int, decision: Decision, planner: Any, keep: np.ndarray,
                 view_action: int | None = None) -> None:
        """Send j's distribution over its next sequences (empty when its search chose
        nothing the fleet took: a fallback or no search)."""
        cfg = self.config
        seqs, probs = np.zeros((0, cfg.depth), dtype=np.int64), np.zeros(0)
        if planner is not None and view_action is not None:
            seqs, probs = distribution(planner.tree, view_action, keep, cfg)
        user = _next_user(env, j, decision.action)
        message = PlanMessage(j, int(env.state.intervals[j]), decision.action, user, seqs, probs)
        self.link.send(j, message.encode())


def distribution(tree: Any, action: int, keep: np.ndarray, config: DecMctsConfig) -> tuple[np.ndarray, np.ndarray]:
    """(sequences (k, d), probs (k,)): the k most visited children below root action
    ``action`` of ``tree`` (an ``mcts`` ``Tree``: ``Tree.lines_below``) with their principal
    lines (fleet indices through ``keep``), weighted by a softmax over their mean returns,
    tau = tau_0 / sqrt(1 + n / k) (n: ``action``'s visits): the paper's variational update
    of q_n (its Algorithm 3) replaced by this, docs/PLANNER.md says why."""
    lines, means, visits = tree.lines_below(action, config.top_k, config.depth)
    if not lines:
        return np.zeros((0, config.depth), dtype=np.int64), np.zeros(0)
    seqs = np.full((len(lines), config.depth), AT_BASE, dtype=np.int64)
    for r, line in enumerate(lines):
        seqs[r, :len(line)] = keep[np.asarray(line)]
    tau = config.temperature / math.sqrt(1.0 + visits / len(lines))
    weights = np.exp((means - means.max()) / tau)
    return seqs, weights / weights.sum()


def _next_user(env: FleetEnv, j: int, action: int) -> int:
    """The user UAV j's interval at ``action`` will serve (the environment's rule, which j
    computes itself before it flies)."""
    st = env.state
    return int(served_user(env.params[j], env.hover_points[j][action], st.users, visible_tasks(st, j), st.served))


def _spawn(rng: np.random.Generator) -> np.random.SeedSequence:
    """A child of ``rng``'s seed sequence (its own draws untouched), or a fixed one."""
    seq = getattr(rng.bit_generator, "seed_seq", None)
    return seq.spawn(1)[0] if isinstance(seq, np.random.SeedSequence) else np.random.SeedSequence(0)


__all__ = ["DecMctsConfig", "DecMctsFleet", "LinkModel", "distribution"]
