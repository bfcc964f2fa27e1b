"""A Gymnasium-style environment of one sortie (Section II).

``reset(*, seed, options) -> (obs, info)``; ``step(action) -> (obs, reward, terminated,
truncated, info)`` with action = hovering-point index. ``terminated``: no action is
allowed any more (battery at the threshold (9b), or nobody eligible (3)); ``truncated``:
the sortie-length limit ``max_intervals``. Every random draw comes from the
environment's ``np.random.Generator``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .arrivals import TimedArrivals
from .errors import ScenarioError
from .interval import AT_BASE, NO_USER, evaluate_actions, interval_duration_s
from .mobility import draw_tasks, draw_timed_arrivals
from .layouts import base_position, hover_points, user_rows
from .params import pack
from .scenario import Scenario
from .state import SortieState
from .world import NO_MOVES, NO_NEWS, advance, draw_chance, in_time, scene_of, step


@dataclass(frozen=True)
class Snapshot:
    """A restorable copy of the environment: state plus the generator's position."""

    state: SortieState
    rng_state: dict[str, Any]
    done: bool
    arrivals: TimedArrivals | None = None


class SortieEnv:
    """One sortie of the UAV over the scenario's users and hovering points."""

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.params = pack(scenario)
        self.hover_points = hover_points(scenario)
        self.base_xyz = base_position(scenario)
        self.rng = np.random.default_rng()
        self.state: SortieState | None = None
        self.arrivals: TimedArrivals | None = None
        """The users' own arrival law (``reset`` option ``arrivals_every_s``); None: the
        scenario's (once per interval, or in time: ``task_arrival_period_s``)."""
        self._done = True
        self._q = np.empty(len(self.hover_points))

    @property
    def num_actions(self) -> int:
        return len(self.hover_points)

    # --- Gymnasium API ---------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Start a sortie at the base with the users in their rows.

        ``seed`` reseeds the generator. ``options``: ``task_table`` (T, I) ints, a known
        task schedule used instead of draws for its T intervals; ``users_xyz`` (I, 3),
        starting positions instead of the rows; ``arrivals_every_s`` (``backlog`` only): the
        users' new tasks come in time, a draw of the model's arrivals every so many seconds
        of flight and hold, each user at its phase (``arrivals.TimedArrivals``, from a
        generator spawned from this one, as ``sim_bridge users`` draw them), whatever the
        scenario's ``task_arrival_period_s`` says the planners' model is.
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        options = dict(options or {})
        s = self.scenario
        users = _option_array(options.pop("users_xyz", None), (s.num_users, 3), "users_xyz", float)
        if users is None:
            users = user_rows(s.num_users, s.area_side_m)
        table = _option_array(options.pop("task_table", None), (None, s.num_users), "task_table", int)
        if table is None:
            table = np.zeros((0, s.num_users), dtype=np.int64)
        period = options.pop("arrivals_every_s", None)
        if options:
            raise ScenarioError(next(iter(options)), f"unknown reset option {next(iter(options))!r}")
        if period is not None and len(table):
            raise ScenarioError("arrivals_every_s", "arrivals_every_s and task_table both say when tasks arrive: give one")
        self.arrivals = None if period is None else _timed_arrivals(period, s, self.rng)
        if len(table) and (table.min() < 0 or table.max() > s.task_max):
            raise ScenarioError("task_table", f"task_table values must lie in [0, {s.task_max}]")
        tasks = np.zeros(s.num_users, dtype=np.int64)
        if len(table):
            tasks[:] = table[0]
        else:
            draw_tasks(self.params, tasks, self.rng)
        self.state = SortieState(
            uav_xyz=self.base_xyz.copy(),
            hover_index=AT_BASE,
            users=users,
            tasks=tasks,
            served=np.zeros(s.num_users, dtype=np.int64),
            battery_j=float(s.battery_j),
            interval=0,
            energy_used_j=0.0,
            task_table=table,
        )
        self._done = self.action_mask().sum() == 0
        return self.observation(), {"battery_j": s.battery_j, "action_mask": self.action_mask()}

    def step(self, action: int) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Fly to hovering point ``action``, serve its user, then let the world move on."""
        st = self._require_state()
        if self._done:
            raise ScenarioError("action", "the sortie is over: call reset()")
        if not (isinstance(action, (int, np.integer)) and 0 <= action < self.num_actions):
            raise ScenarioError("action", f"action must be a hovering-point index in [0, {self.num_actions})")
        mask = self.action_mask()
        if not mask[action]:
            raise ScenarioError("action", f"hovering point {action} is not allowed now")
        hp = self.hover_points[action]
        user_xyz = st.users.tolist()
        moves, news = np.empty_like(st.users), np.empty_like(st.tasks)
        draw_chance(self.params, moves, news, self.rng)
        world = st.world()
        from_xyz = st.uav_xyz.copy()
        scene = scene_of(self.params, self.hover_points, st.task_table)
        per_interval = self.arrivals is None and not in_time(self.params)
        out = step(scene, world, int(action), moves, news if per_interval else NO_NEWS)
        if not per_interval:  # the interval's arrivals follow how long it lasted
            served_at = np.array(user_xyz[out.user]) if out.user != NO_USER else hp  # where it was served
            duration = interval_duration_s(self.params, from_xyz, hp, served_at, out.bits)
            if self.arrivals is not None:
                self.arrivals.run(self.params, world.tasks, duration)
            else:
                draw_timed_arrivals(self.params, news, duration, self.rng)
                advance(scene, world, NO_MOVES, news)
        st.absorb(world)
        info = {
            "interval": st.interval - 1,
            "hover_point": int(action),
            "uav_xyz": hp.tolist(),
            "user": int(out.user),
            "user_xyz": user_xyz[out.user],
            "tasks": int(out.tasks),
            "bits": float(out.bits),
            "e_hover_j": float(out.e_hover_j),
            "e_comp_j": float(out.e_comp_j),
            "e_flight_j": float(out.e_flight_j),
            "reward": float(out.reward),
        }
        info["battery_j"] = float(st.battery_j)
        limit = self.scenario.max_intervals
        truncated = bool(limit and st.interval >= limit)
        next_mask = self.action_mask()
        terminated = not next_mask.any()
        info["action_mask"] = next_mask
        self._done = terminated or truncated
        return self.observation(), float(out.reward), terminated, truncated, info

    # --- helpers for planners -----------------------------------------------------------
    def action_values(self) -> np.ndarray:
        """Each hovering point's immediate reward q now; -inf where not allowed. (K,)"""
        st = self._require_state()
        q = np.empty(self.num_actions)
        evaluate_actions(
            self.params, self.hover_points, st.hover_index, st.uav_xyz,
            st.users, st.tasks, st.served, st.battery_j, q,
        )
        return q

    def action_mask(self) -> np.ndarray:
        """Which hovering points are allowed now; (K,) bool."""
        return np.isfinite(self.action_values())

    @property
    def done(self) -> bool:
        return self._done

    def observation(self) -> dict[str, Any]:
        """What the UAV knows at the start of the interval (all requests are in)."""
        st = self._require_state()
        return {
            "interval": st.interval,
            "hover_index": st.hover_index,
            "uav_xyz": st.uav_xyz.copy(),
            "users_xyz": st.users.copy(),
            "tasks": st.tasks.copy(),
            "served": st.served.copy(),
            "battery_j": st.battery_j,
        }

    def snapshot(self) -> Snapshot:
        """Copy of the state and the generator; ``restore`` continues identically."""
        arrivals = None if self.arrivals is None else self.arrivals.copy()
        return Snapshot(self._require_state().copy(), self.rng.bit_generator.state, self._done, arrivals)

    def restore(self, snap: Snapshot) -> None:
        self.state = snap.state.copy()
        self.rng.bit_generator.state = snap.rng_state
        self._done = snap.done
        self.arrivals = None if snap.arrivals is None else snap.arrivals.copy()

    def _require_state(self) -> SortieState:
        if self.state is None:
            raise ScenarioError("state", "call reset() before using the environment")
        return self.state


def _timed_arrivals(period: Any, s: Scenario, rng: np.random.Generator) -> TimedArrivals:
    if s.task_model != "backlog":
        raise ScenarioError("arrivals_every_s", "arrivals_every_s needs task_model = 'backlog' (tasks that wait)")
    try:
        return TimedArrivals.start(float(period), s.num_users, rng.spawn(1)[0])
    except (TypeError, ValueError) as exc:
        raise ScenarioError("arrivals_every_s", str(exc)) from None


def _option_array(value: Any, shape: tuple[int | None, int], name: str, kind: type) -> np.ndarray | None:
    if value is None:
        return None
    dtype = np.float64 if kind is float else np.int64
    try:
        arr = np.array(value, dtype=dtype)
    except (TypeError, ValueError):
        raise ScenarioError(name, f"{name} must be a numeric array") from None
    if arr.ndim != 2 or arr.shape[1] != shape[1] or (shape[0] is not None and arr.shape[0] != shape[0]):
        raise ScenarioError(name, f"{name} must have shape {shape}, got {arr.shape}")
    if kind is float and not np.isfinite(arr).all():
        raise ScenarioError(name, f"{name} must be finite")
    return arr.copy()


__all__ = ["SortieEnv", "Snapshot", "NO_USER", "AT_BASE"]
