"""``mcts``: the planner the service flies. Sound where Algorithm 1 is not.

- Each node's value is the return from its own step onward (not the mean of the steps
  after the newly expanded node, which the paper backs up into every ancestor).
- Open loop: chance is re-sampled on every iteration from the real root state, so values
  average over futures instead of trusting one draw (``open_loop.py``).
- Playouts epsilon-greedy on the immediate reward q by default (uniform as an option).
- Tree reuse: when the UAV takes the planned action, the chosen child's subtree becomes the
  root. Its statistics were averaged over all the futures the search sampled; the real
  observation is one of them. They are kept as a prior (scaled by ``reuse_decay``) and the
  new search runs from the observed state, where actions no longer allowed are never
  selected. If the UAV did something else (another point, a skipped interval) the tree
  starts afresh.
- Anytime: an iteration budget, a wall-clock budget, or both; the decision is the most
  visited allowed root child, and the principal line below it is the rest of the plan.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np

from ..model import Scenario, SortieState, pack
from ..model.interval import remaining_intervals
from ..model.world import Scene, World, in_time, scene_of
from ..policy import Decision
from .futures import FutureIndex, RootValues, index_of, point_tables_of, root_values_of
from .objective import RETURN_MEAN, RETURN_SORTIE, RETURN_SUM
from .open_loop import (ROLLOUT_EPSILON_GREEDY, ROLLOUT_RANDOM, SearchSettings, draw_futures, paired_fresh,
                        paired_rollouts, search)
from .tree import ROOT_INDEX, UNVISITED, Tree

ROLLOUTS = {"random": ROLLOUT_RANDOM, "epsilon-greedy": ROLLOUT_EPSILON_GREEDY}
RETURNS = {"mean": RETURN_MEAN, "sum": RETURN_SUM, "sortie": RETURN_SORTIE}


@dataclass(frozen=True)
class MctsConfig:
    """Settings of the sound planner."""

    iterations: int | None = 1000
    """Iterations per decision (the paper's "training episodes"); None: only the clock."""
    budget_ms: float | None = None
    """Wall-clock budget per decision; None: only the iteration count."""
    c: float = 1.0
    """UCT exploration constant on min-max normalised values (see docs/PLANNER.md)."""
    rollout: str = "epsilon-greedy"
    """Playout policy: ``epsilon-greedy`` on the immediate q, or ``random``."""
    rollout_epsilon: float = 0.1
    """Probability of a uniform step in an epsilon-greedy playout."""
    return_kind: str = "sortie"
    """What a node backs up (``objective.py``): ``sortie``, the objective of ``mcts`` (the
    whole sortie's average q, past intervals included: the reported average reward);
    ``mean`` of q from the node's step on, or their ``sum``, for comparison."""
    reuse_tree: bool = True
    """Keep the chosen child's subtree for the next decision."""
    reuse_decay: float = 0.3
    """Factor on reused statistics (1 keeps them, 0 forgets them)."""
    chunk: int = 16
    """Iterations between clock checks under a wall-clock budget."""
    max_depth: int = 10
    """Levels the tree may grow below the root (the paper's m); playouts go on past them."""
    futures: int = 32
    """Sampled futures per decision shared by all iterations (common random numbers);
    0: a fresh future every iteration."""
    confidence_z: float = 2.0
    """Leave the greedy choice (largest immediate q) only when the search's choice, each
    followed by greedy, beats it on ``confirm_futures`` fresh futures by this many standard
    errors of the paired difference; 0 always takes the search's choice."""
    confirm_futures: int = 64
    """Fresh futures for that confirmation. Fresh, because the search's own samples picked
    the candidate and would favour it (the winner's curse)."""

    def __post_init__(self) -> None:
        if self.iterations is None and self.budget_ms is None:
            raise ValueError("MctsConfig needs iterations, budget_ms or both")
        if self.iterations is not None and self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        if self.budget_ms is not None and not self.budget_ms > 0:
            raise ValueError(f"budget_ms must be positive, got {self.budget_ms}")
        if self.rollout not in ROLLOUTS:
            raise ValueError(f"rollout must be one of {sorted(ROLLOUTS)}, got {self.rollout!r}")
        if self.return_kind not in RETURNS:
            raise ValueError(f"return_kind must be one of {sorted(RETURNS)}, got {self.return_kind!r}")
        if not 0.0 <= self.rollout_epsilon <= 1.0 or not 0.0 <= self.reuse_decay <= 1.0:
            raise ValueError("rollout_epsilon and reuse_decay must lie in [0, 1]")
        if self.max_depth < 1:
            raise ValueError(f"max_depth must be at least 1, got {self.max_depth}")
        if self.futures < 0:
            raise ValueError(f"futures must not be negative, got {self.futures}")
        if self.confirm_futures < 2:
            raise ValueError(f"confirm_futures must be at least 2, got {self.confirm_futures}")
        if not (self.confidence_z >= 0 and math.isfinite(self.confidence_z)):
            raise ValueError(f"confidence_z must be finite and non-negative, got {self.confidence_z}")
        if not (self.c >= 0 and math.isfinite(self.c)) or self.chunk < 1:
            raise ValueError("c must be finite and non-negative, chunk at least 1")


class MctsPlanner:
    """Open-loop MCTS with tree reuse over one scenario's hovering points."""

    def __init__(self, scenario: Scenario, hover_points: np.ndarray, config: MctsConfig, rng: np.random.Generator) -> None:
        self.scenario = scenario
        self.params = pack(scenario)
        self.hover_points = np.ascontiguousarray(hover_points, dtype=np.float64)
        self.config = config
        self.rng = rng
        self.tables = point_tables_of(self.params, self.hover_points)
        self.in_time = bool(in_time(self.params))
        """Tasks arrive in time: the futures cannot be shared (``open_loop``), each
        iteration draws its own and the confirmation plays ``paired_fresh``."""
        self.tree = self._new_tree()
        self._expect: tuple[int, int] | None = None  # (interval, hover index) after our move
        self.shape_futures: Callable[[np.ndarray, np.ndarray], None] | None = None
        """Called on every set of futures a decision draws, moves (S, H, I, 3) and news
        (S, H, I), before they are indexed, to change them in place: a fleet's ``dec-mcts``
        writes there what the other UAVs' sampled plans take from the users. None: as drawn."""

    def _new_tree(self) -> Tree:
        return Tree.empty(len(self.hover_points), (self.config.iterations or 1024) + 1)

    def reset(self) -> None:
        """Forget the tree (a new sortie, or a state the tree knows nothing about)."""
        self.tree = self._new_tree()
        self._expect = None

    def plan(self, state: SortieState) -> Decision:
        """The next hovering point for ``state`` and the line expected after it."""
        start = time.perf_counter()
        scene = scene_of(self.params, self.hover_points, state.task_table)
        root = state.world()
        values = root_values_of(scene, root, self.tables)
        allowed = np.isfinite(values.q)
        if not allowed.any():
            raise ValueError("no hovering point is allowed in this state: the sortie is over")
        self._reuse_or_reset(state)
        greedy = int(np.argmax(values.q))
        settings = self._settings(state)
        done = self._search(scene, root, values, settings, start)
        child = self._choose(scene, root, values, settings, greedy, allowed)
        if child == UNVISITED:  # budget too small for one iteration: the greedy choice
            action, line = greedy, ()
        else:
            action = int(self.tree.action[child])
            line = tuple(self.tree.principal_line(child))
        if self.config.reuse_tree and child != UNVISITED:
            self._chosen = child
            self._expect = (state.interval + 1, action)
        return Decision(
            action=action,
            line=(action, *line),
            iterations=done,
            wall_s=time.perf_counter() - start,
            extra={"root_visits": float(self.tree.visits[ROOT_INDEX]), "nodes": self.tree.num_nodes},
        )

    def _settings(self, state: SortieState) -> SearchSettings:
        cfg = self.config
        return SearchSettings(float(cfg.c), ROLLOUTS[cfg.rollout], float(cfg.rollout_epsilon), RETURNS[cfg.return_kind],
                              float(state.reward_sum), int(state.interval), int(cfg.max_depth))

    def _reuse_or_reset(self, state: SortieState) -> None:
        if self._expect is not None and self._expect == (state.interval, state.hover_index):
            self.tree = self.tree.subtree(self._chosen, self.config.reuse_decay)
        else:
            self.tree = self._new_tree()
        self._expect = None

    def _choose(self, scene: Scene, root: World, values: RootValues, settings: SearchSettings, greedy: int,
                allowed: np.ndarray) -> int:
        """The most visited allowed root child, unless it fails to beat the greedy choice
        on fresh paired futures (``confidence_z``): then the greedy child."""
        best = self.tree.best_child(ROOT_INDEX, allowed)
        greedy_child = self.tree.children[ROOT_INDEX, greedy]
        if best == UNVISITED or greedy_child == UNVISITED or best == greedy_child:
            return best
        if self.config.confidence_z <= 0:
            return best
        first = int(self.tree.action[best])
        if self.in_time:
            returns = self._paired_fresh(scene, root, values, settings, first, greedy)
        else:
            index = self._index(scene, root, values, self.config.confirm_futures)
            returns = np.empty((index.moves.shape[0], 2))
            paired_rollouts(scene, root, first, greedy, settings, index, returns)
        return best if paired_t(returns[:, 0] - returns[:, 1]) >= self.config.confidence_z else int(greedy_child)

    def _search(self, scene: Scene, root: World, values: RootValues, settings: SearchSettings, start: float) -> int:
        cfg = self.config
        deadline = None if cfg.budget_ms is None else start + cfg.budget_ms / 1e3
        target = cfg.iterations if cfg.iterations is not None else math.inf
        index = self._index(scene, root, values, 0 if self.in_time else cfg.futures)
        done = 0
        while done < target:
            batch = int(min(target - done, cfg.chunk if deadline is not None else target - done))
            self.tree.reserve(batch)
            self.tree.num_nodes = search(scene, self.tree.arrays(), self.tree.num_nodes, root, settings, index,
                                         batch, self.rng)
            done += batch
            if deadline is not None:
                now = time.perf_counter()
                # keep time for the confirmation: about 2 * confirm_futures playouts
                per_iteration = (now - start) / done
                if now + per_iteration * 2 * cfg.confirm_futures >= deadline:
                    break
        return done

    def _index(self, scene: Scene, root: World, values: RootValues, count: int) -> FutureIndex:
        """``count`` futures sampled from the root (drawn now from the planner's generator)
        and their index (``futures.index_of``): (S, H, I, 3) moves and (S, H, I) task draws."""
        num_users = len(root.users)
        horizon = remaining_intervals(self.params, num_users, int(root.interval[0]))
        count = count if horizon > 0 else 0
        moves = np.empty((count, horizon, num_users, 3))
        news = np.empty((count, horizon, num_users), dtype=np.int64)
        draw_futures(self.params, moves, news, self.rng)
        if self.shape_futures is not None and count:
            self.shape_futures(moves, news)
        return index_of(scene, root, moves, news, self.tables, values)

    def _paired_fresh(self, scene: Scene, root: World, values: RootValues, settings: SearchSettings, first: int,
                      second: int) -> np.ndarray:
        """The confirmation's returns (S, 2) when tasks arrive in time (``paired_fresh``)."""
        index = self._index(scene, root, values, 0)
        count, horizon = self.config.confirm_futures, remaining_intervals(self.params, len(root.users),
                                                                          int(root.interval[0]))
        moves = np.empty((count, horizon, len(root.users), 3))
        draw_futures(self.params, moves, np.empty((count, horizon, len(root.users)), dtype=np.int64), self.rng)
        uniforms = self.rng.random((count, horizon, len(root.users)))
        returns = np.empty((count, 2))
        paired_fresh(scene, root, first, second, settings, index, moves, uniforms, returns)
        return returns

    def describe(self) -> dict:
        return asdict(self.config)



def paired_t(diff: np.ndarray) -> float:
    """t-statistic of the mean of paired differences ``diff`` (S,); +-inf without spread."""
    spread = diff.std(ddof=1) if len(diff) > 1 else 0.0
    if spread == 0.0:
        return math.inf if diff.mean() > 0 else -math.inf
    return float(diff.mean() / (spread / math.sqrt(len(diff))))
