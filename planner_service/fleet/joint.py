"""``joint``: one search over the whole fleet's plan, the reference for the decentralised
planners where it is tractable (docs/PLANNER.md, "joint").

The fleet decides one UAV at a time (``FleetEnv.due``: the UAV whose interval ends first),
so a joint action of the N UAVs is N successive decisions; one tree holds them all, each
node a decision of the UAV due there, keyed (uav, point) since which UAV is due can depend
on the chance (an interval's length follows the users' positions). Its model is the fleet's
own environment (a copy, restored to the real state every iteration, its chance drawn from
the planner's generator): open loop, UCT (10) on min-max normalised values, playouts
epsilon-greedy on q to the end of the sortie, every node backing up the fleet's average q
over the sortie (the ``sortie`` objective of ``mcts``, over every UAV's intervals). It is
slow (the environment steps in Python) and its joint action space grows as K^N, so it
refuses fleets beyond ``MAX_JOINT_ACTIONS``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..model.fleet import FleetEnv
from ..policy import Decision, PolicySpec
from .per_uav import PerUav

MAX_JOINT_ACTIONS = 10_000
"""Largest K^N ``joint`` accepts (K points, N UAVs): 100 points for 2 UAVs, 21 for 3. Past it
one joint action's children cannot each be tried in a decision's iterations. *decision*"""
EPSILON = 0.1
"""Probability of a uniform step in a playout (``mcts``'s default)."""
C = 1.0
"""UCT constant on min-max normalised values (``mcts``'s default)."""



def joint_fits(points: int, uavs: int) -> bool:
    """``joint`` searches a fleet of ``uavs`` over ``points`` hovering points: K^N joint
    actions at most ``MAX_JOINT_ACTIONS`` (it refuses more)."""
    return points ** uavs <= MAX_JOINT_ACTIONS

class _Node:
    __slots__ = ("children", "visits", "value")

    def __init__(self) -> None:
        self.children: dict[tuple[int, int], _Node] = {}
        self.visits = 0.0
        self.value = 0.0


class JointFleet(PerUav):
    """``joint`` (the module's docstring). ``base`` must be ``mcts`` (its settings: the
    iterations of ``spec``); its per-UAV planners are not used, only the fallback."""

    name = "joint"

    def __init__(self, base: str, spec: PolicySpec, rngs: list[np.random.Generator]) -> None:
        if base != "mcts":
            raise ValueError(f"joint is its own search (mcts's settings); got base {base!r}")
        if spec.iterations is None:
            raise ValueError("joint runs a number of iterations; give --iterations")
        super().__init__("greedy", spec, rngs)
        self.base = base
        self.iterations = spec.iterations
        self.rng = rngs[0]
        self._model: FleetEnv | None = None

    def begin(self, env: FleetEnv) -> None:
        size = env.num_actions ** env.num_uavs
        if not joint_fits(env.num_actions, env.num_uavs):
            raise ValueError(f"joint searches K^N = {env.num_actions}^{env.num_uavs} = {size} joint actions, more "
                             f"than {MAX_JOINT_ACTIONS}: use fewer UAVs or hovering points (or dec-mcts)")
        self._model = FleetEnv(env.scenario, env.fleet)

    def decide(self, env: FleetEnv) -> Decision:
        if self._model is None:
            raise ValueError("joint: call begin(env) first")
        start = time.perf_counter()
        j = env.due
        real = env.snapshot()
        model = self._model
        root = _Node()
        scratch = np.random.default_rng(0)
        for _ in range(self.iterations):
            model.rng = scratch  # restore writes the world's generator state into it: never into ours
            model.restore(real)
            model.rng = self.rng  # the model's chance is the planner's, never the world's
            self._iterate(model, root)
        mine = {key: child for key, child in root.children.items() if key[0] == j}
        if not mine:
            return self.legal(env, j, None)
        (_, action), best = max(mine.items(), key=lambda kv: (kv[1].visits, kv[1].value / max(kv[1].visits, 1)))
        line = [action, *_own_line(best, j)]
        return self.legal(env, j, Decision(action, tuple(line), self.iterations, time.perf_counter() - start,
                                           {"root_visits": root.visits}))

    def _iterate(self, model: FleetEnv, root: _Node) -> None:
        st = model.state
        past_sum, past_count = float(st.reward_sum.sum()), int(st.intervals.sum())
        path, node, in_tree = [root], root, True
        total, steps = 0.0, 0
        while not model.done:
            j = model.due
            q = model.action_values(j)
            allowed = np.flatnonzero(np.isfinite(q))
            if in_tree:
                untried = [a for a in allowed if (j, int(a)) not in node.children]
                if untried:  # the untried allowed point of largest q first, as mcts does
                    a = int(max(untried, key=lambda b: q[b]))
                    node.children[(j, a)] = _Node()
                    in_tree = False
                else:
                    a = _uct(node, j, allowed)
                node = node.children[(j, a)]
                path.append(node)
            else:
                a = int(allowed[self.rng.integers(len(allowed))]) if self.rng.random() < EPSILON else int(np.argmax(q))
            _, reward, _, _, _ = model.step(a)
            total += reward
            steps += 1
        value = (past_sum + total) / max(past_count + steps, 1)  # the fleet's average q over the sortie
        for n in path:
            n.visits += 1.0
            n.value += value


def _uct(node: _Node, j: int, allowed: np.ndarray) -> int:
    """UCT (10) over UAV j's allowed children, their means min-max normalised."""
    kids = [(int(a), node.children[(j, int(a))]) for a in allowed]
    means = np.array([c.value / c.visits for _, c in kids])
    lo, spread = means.min(), means.max() - means.min()
    total = sum(c.visits for _, c in kids)
    scores = [((m - lo) / spread if spread > 0 else 0.0) + C * math.sqrt(math.log(max(total, 1.0)) / c.visits)
              for m, (_, c) in zip(means, kids)]
    return kids[int(np.argmax(scores))][0]


def _own_line(node: _Node, j: int, depth: int = 16) -> list[int]:
    """UAV j's own next points along the most visited path below ``node``."""
    line: list[int] = []
    for _ in range(depth):
        if not node.children:
            break
        (uav, a), node = max(node.children.items(), key=lambda kv: kv[1].visits)
        if uav == j:
            line.append(a)
    return line


__all__ = ["JointFleet", "MAX_JOINT_ACTIONS", "joint_fits"]
