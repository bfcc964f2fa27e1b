"""A plain reference of the ``mcts`` planner: one object per node, written for clarity.

It runs the same algorithm as ``planner.py`` + ``open_loop.py`` and draws the same random
numbers in the same order, so with the same generator it takes the same decisions: the
tests check that, and the benchmark times both on the same states. Run it with
``UAV_PLANNER_NO_NUMBA=1`` for a pure-Python model as well.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..model import Scenario, SortieState, pack
from ..model.interval import remaining_intervals
from ..model.world import World, clone, draw_chance, evaluate, scene_of, step
from ..policy import Decision
from .objective import node_return
from .planner import RETURNS, MctsConfig, paired_t


@dataclass(eq=False)
class Node:
    """A sequence of hovering points from the root; statistics of its returns."""

    action: int
    parent: "Node | None" = None
    children: dict[int, "Node"] = field(default_factory=dict)
    visits: float = 0.0
    value_sum: float = 0.0

    @property
    def mean(self) -> float:
        return self.value_sum / self.visits if self.visits > 0 else 0.0


class ReferenceMcts:
    """Open-loop MCTS with shared futures, confirmation against greedy, and tree reuse."""

    def __init__(self, scenario: Scenario, hover_points: np.ndarray, config: MctsConfig, rng: np.random.Generator) -> None:
        if config.iterations is None:
            raise ValueError("the reference runs a number of iterations")
        self.scenario = scenario
        self.p = pack(scenario)
        self.hover_points = np.ascontiguousarray(hover_points, dtype=np.float64)
        self.config = config
        self.rng = rng
        self.root = Node(action=-1)
        self.chosen: Node | None = None
        self.expect: tuple[int, int] | None = None
        self.scene = scene_of(self.p, self.hover_points, np.zeros((0, 0), dtype=np.int64))

    # --- the decision ------------------------------------------------------------------
    def plan(self, state: SortieState) -> Decision:
        start = time.perf_counter()
        self.scene = scene_of(self.p, self.hover_points, state.task_table)
        q = self.action_values(world_of(state))
        allowed = np.isfinite(q)
        if not allowed.any():
            raise ValueError("no hovering point is allowed in this state: the sortie is over")
        if self.expect == (state.interval, state.hover_index) and self.chosen is not None:
            self.root = self.reuse(self.chosen)
        else:
            self.root = Node(action=-1)
        self.expect = None
        greedy = int(np.argmax(q))
        futures = self.draw_futures(state, self.config.futures)
        for _ in range(self.config.iterations):
            self.iterate(state, futures)
        best = self.most_visited(self.root, allowed)
        if best is not None and greedy in self.root.children and best.action != greedy and self.config.confidence_z > 0:
            if not self.confirmed(state, best.action, greedy):
                best = self.root.children[greedy]
        if best is None:
            action, line = greedy, ()
        else:
            action, line = best.action, tuple(self.principal_line(best))
            if self.config.reuse_tree:
                self.chosen = best
                self.expect = (state.interval + 1, action)
        return Decision(action=action, line=(action, *line), iterations=self.config.iterations,
                        wall_s=time.perf_counter() - start)

    def confirmed(self, state: SortieState, candidate: int, greedy: int) -> bool:
        """Does ``candidate`` then greedy beat greedy on fresh shared futures?"""
        futures = self.draw_futures(state, self.config.confirm_futures)
        diffs = []
        for moves, tasks in futures:
            a = self.greedy_continuation(state, candidate, moves, tasks)
            b = self.greedy_continuation(state, greedy, moves, tasks)
            diffs.append(a - b)
        return paired_t(np.array(diffs)) >= self.config.confidence_z

    # --- one iteration -------------------------------------------------------------------
    def iterate(self, state: SortieState, futures: list[tuple[np.ndarray, np.ndarray]]) -> None:
        world = world_of(state)
        node, path, rewards = self.root, [self.root], []
        future = None
        in_tree = True
        while self.within_length(world):
            q = self.action_values(world)
            if not np.isfinite(q).any():
                break
            if in_tree and len(path) > self.config.max_depth:
                in_tree = False
            if in_tree:
                action = self.untried_best(node, q)
                if action is not None:
                    child = node.children.get(action) or Node(action=action, parent=node)
                    node.children[action] = child
                    in_tree = False
                else:
                    child = self.uct_child(node, q)
                    action = child.action
                if len(path) == 1 and futures:
                    future = futures[int(child.visits + 0.5) % len(futures)]
                node = child
                path.append(node)
            else:
                action = self.rollout_action(q)
            rewards.append(self.step(world, action, future, len(rewards)))
        self.backup(state, path, rewards)

    def step(self, world: World, action: int, future, index: int) -> float:
        if future is not None:
            moves, news = future[0][index], future[1][index]
        else:
            moves, news = np.empty_like(world.users), np.empty_like(world.tasks)
            draw_chance(self.p, moves, news, self.rng)
        return step(self.scene, world, action, moves, news).reward

    def backup(self, state: SortieState, path: list[Node], rewards: list[float]) -> None:
        kind = RETURNS[self.config.return_kind]
        whole = sum_from_end(rewards)
        for j, node in enumerate(path):
            first = j - 1 if j > 0 else 0  # node j is entered by step j - 1
            own = rewards[first:]
            ret = node_return(kind, sum_from_end(own), len(own), whole, len(rewards), state.reward_sum, state.interval)
            node.visits += 1.0
            node.value_sum += ret

    # --- policies inside the search ------------------------------------------------------
    def untried_best(self, node: Node, q: np.ndarray) -> int | None:
        best, best_q = None, -math.inf
        for a in range(len(q)):
            child = node.children.get(a)
            if (child is None or child.visits <= 0) and q[a] > best_q:
                best, best_q = a, q[a]
        return best

    def uct_child(self, node: Node, q: np.ndarray) -> Node:
        kids = [node.children[a] for a in range(len(q)) if q[a] > -math.inf]
        lo, hi = min(k.mean for k in kids), max(k.mean for k in kids)
        log_total = math.log(max(sum_in_order([k.visits for k in kids]), 1.0))
        best, best_score = kids[0], -math.inf
        for k in kids:
            exploit = (k.mean - lo) / (hi - lo) if hi > lo else 0.5
            score = exploit + self.config.c * math.sqrt(2.0 * log_total / k.visits)  # (10)
            if score > best_score:
                best, best_score = k, score
        return best

    def rollout_action(self, q: np.ndarray) -> int:
        allowed = np.flatnonzero(np.isfinite(q))
        if self.config.rollout == "epsilon-greedy" and self.rng.random() >= self.config.rollout_epsilon:
            return int(np.argmax(q))
        return int(allowed[self.rng.integers(0, len(allowed))])

    def greedy_continuation(self, state: SortieState, first: int, moves: np.ndarray, tasks: np.ndarray) -> float:
        world, rewards = world_of(state), []
        while self.within_length(world):
            q = self.action_values(world)
            if not np.isfinite(q).any():
                break
            action = first if not rewards else int(np.argmax(q))
            rewards.append(self.step(world, action, (moves, tasks), len(rewards)))
        total, steps = sum_in_order(rewards), len(rewards)
        return node_return(RETURNS[self.config.return_kind], total, steps, total, steps, state.reward_sum,
                           state.interval)

    # --- helpers -------------------------------------------------------------------------
    def draw_futures(self, state: SortieState, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
        horizon = remaining_intervals(self.p, len(state.users), state.interval)
        if horizon <= 0:
            return []
        futures = []
        for _ in range(count):
            moves = np.empty((horizon, len(state.users), 3))
            tasks = np.empty((horizon, len(state.users)), dtype=np.int64)
            for h in range(horizon):
                draw_chance(self.p, moves[h], tasks[h], self.rng)
            futures.append((moves, tasks))
        return futures

    def within_length(self, world: World) -> bool:
        limit = self.scenario.max_intervals
        return limit <= 0 or world.interval[0] < limit

    def action_values(self, world: World) -> np.ndarray:
        q = np.empty(len(self.hover_points))
        evaluate(self.scene, world, q)
        return q

    @staticmethod
    def most_visited(node: Node, allowed: np.ndarray) -> Node | None:
        best, key = None, (-1.0, -math.inf)
        for a in sorted(node.children):
            child = node.children[a]
            if allowed[a] and (child.visits, child.mean) > key:
                best, key = child, (child.visits, child.mean)
        return best

    def principal_line(self, node: Node, max_depth: int = 64) -> list[int]:
        line = []
        while len(line) < max_depth:
            child = self.most_visited(node, np.ones(len(self.hover_points), dtype=bool))
            if child is None or child.visits <= 0:
                break
            line.append(child.action)
            node = child
        return line

    def reuse(self, node: Node) -> Node:
        node.parent = None
        decay = self.config.reuse_decay
        stack = [node]
        while stack:
            n = stack.pop()
            n.visits *= decay
            n.value_sum *= decay
            stack.extend(n.children.values())
        return node


def sum_in_order(values: list[float]) -> float:
    """Left-to-right sum, as the compiled kernel adds (so both round alike)."""
    total = 0.0
    for v in values:
        total += v
    return total


def sum_from_end(values: list[float]) -> float:
    """Right-to-left sum, as the kernel's suffix sums add."""
    return sum_in_order(values[::-1])


def world_of(state: SortieState) -> World:
    """A copy of the sortie state that an iteration plays forward."""
    return clone(state.world())
