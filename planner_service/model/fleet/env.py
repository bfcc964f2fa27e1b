"""A fleet sortie, event-driven: the UAV whose interval ends first decides next.

``reset(*, seed, options) -> (obs, info)``; ``due`` is the UAV whose turn it is;
``step(action, intent) -> (obs, reward, terminated, truncated, info)`` flies it to hovering
point ``action`` and serves there. Each decision is one step of the single-UAV model for
that UAV (``world.serve`` then ``world.advance`` with the chance drawn before it, in the
order ``SortieEnv.step`` draws it), so a fleet of one is today's environment, draw for draw.
The joint rules (``rules.check_joint``) are checked after every change: an illegal joint
state raises ``FleetError``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..env import SortieEnv, _option_array
from ..interval import AT_BASE, NO_USER, evaluate_actions, interval_duration_s, served_user
from ..layouts import base_position, hover_points, user_rows
from ..mobility import draw_tasks, draw_timed_arrivals
from ..params import pack
from ..scenario import Scenario
from ..world import NO_MOVES, NO_NEWS, advance, draw_chance, in_time, scene_of, serve
from .rules import FleetError, busy_users, check_joint, claimed_points, visible_tasks
from .setup import Fleet, uav_scenarios
from .state import FleetState

RETIRED_TERMINATED = "terminated"
"""Why a UAV stopped: no action of its own is allowed (battery (9b), nobody eligible (3)),
or it waited for the others twice while nobody flew (they block each other: a deadlock)."""
RETIRED_TRUNCATED = "truncated"
"""Why a UAV stopped: it flew ``max_intervals`` intervals (an outside limit)."""


@dataclass(frozen=True)
class FleetSnapshot:
    """A restorable copy of the fleet environment: state plus the generator's position."""

    state: FleetState
    rng_state: dict[str, Any]
    ended: dict[int, str]
    order_next: int
    waiting_since: dict[int, int]
    arrivals_until_s: float = 0.0


class FleetEnv:
    """N UAVs over one scenario's users (``Fleet`` says what differs between them)."""

    def __init__(self, scenario: Scenario, fleet: Fleet) -> None:
        self.scenario = scenario
        self.fleet = fleet
        self.scenarios = uav_scenarios(scenario, fleet)
        self.params = [pack(s) for s in self.scenarios]
        """Each UAV's kernel parameters; the users' chance reads UAV 0's (the shared fields)."""
        self.hover_points = [hover_points(s) for s in self.scenarios]
        """Each UAV's K points, on its own layer: point k is the same place for every UAV."""
        self.rng = np.random.default_rng()
        self.state: FleetState | None = None
        self.ended: dict[int, str] = {}
        self._order_next = 0
        self._waiting_since: dict[int, int] = {}
        self._arrivals_until_s = 0.0
        """With arrivals in time and several UAVs: the fleet time up to which the users' new
        tasks are drawn (``_arrivals_until``)."""
        self._views = [SortieEnv(s) for s in self.scenarios]
        self._claims_views = [SortieEnv(s) for s in self.scenarios]

    @property
    def num_uavs(self) -> int:
        return self.fleet.uavs

    @property
    def num_actions(self) -> int:
        return len(self.hover_points[0])

    @property
    def done(self) -> bool:
        return len(self.ended) == self.num_uavs

    @property
    def due(self) -> int:
        """The UAV whose decision comes next: the active one whose interval ends first
        (ties: the one scheduled first). Always one that has an allowed action."""
        st = self._require_state()
        if self.done:
            raise FleetError("due", "the fleet's sortie is over: call reset()")
        live = np.flatnonzero(st.active)
        return int(live[np.lexsort((st.order[live], st.clock_s[live]))[0]])

    # --- Gymnasium-style API --------------------------------------------------------------
    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict[str, Any], dict[str, Any]]:
        """Every UAV at its base, the users in their rows. ``options``: ``users_xyz`` (I, 3)
        and ``task_table`` (T, I), as ``SortieEnv.reset`` reads them (row t meets the t-th
        decision of the fleet)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        options = dict(options or {})
        s, n = self.scenario, self.num_uavs
        users = _option_array(options.pop("users_xyz", None), (s.num_users, 3), "users_xyz", float)
        if users is None:
            users = user_rows(s.num_users, s.area_side_m)
        table = _option_array(options.pop("task_table", None), (None, s.num_users), "task_table", int)
        if table is None:
            table = np.zeros((0, s.num_users), dtype=np.int64)
        if options:
            raise FleetError(next(iter(options)), f"unknown fleet reset option {next(iter(options))!r}")
        if len(table) and (table.min() < 0 or table.max() > s.task_max):
            raise FleetError("task_table", f"task_table values must lie in [0, {s.task_max}]")
        tasks = np.zeros(s.num_users, dtype=np.int64)
        if len(table):
            tasks[:] = table[0]
        else:
            draw_tasks(self.params[0], tasks, self.rng)
        self.state = FleetState(
            uav_xyz=np.array([base_position(x) for x in self.scenarios], dtype=np.float64).reshape(n, 3),
            hover=np.full(n, AT_BASE, dtype=np.int64),
            battery_j=np.array([x.battery_j for x in self.scenarios], dtype=np.float64),
            energy_used_j=np.zeros(n),
            reward_sum=np.zeros(n),
            intervals=np.zeros(n, dtype=np.int64),
            clock_s=np.zeros(n),
            order=np.arange(n, dtype=np.int64),
            bound=np.full(n, NO_USER, dtype=np.int64),
            intent=np.full(n, AT_BASE, dtype=np.int64),
            active=np.ones(n, dtype=np.bool_),
            users=users,
            tasks=tasks,
            served=np.zeros(s.num_users, dtype=np.int64),
            events=np.zeros(1, dtype=np.int64),
            task_table=table,
        )
        self.ended, self._order_next, self._waiting_since = {}, n, {}
        self._arrivals_until_s = 0.0
        self._settle_turn()
        return self.observation(), {"due": None if self.done else self.due, "ended": dict(self.ended)}

    def step(self, action: int, intent: int = AT_BASE) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """The due UAV flies to hovering point ``action`` and serves its nearest eligible user
        there that no other UAV is serving; ``intent`` is the point it says it will fly to
        after this one (published for the others' planners, never enforced). Then the world
        moves on (the users' moves, their new tasks) and the next UAV's turn is found.

        ``terminated`` / ``truncated``: the whole fleet's sortie is over, every UAV stopped,
        and some UAV stopped at ``max_intervals`` (``truncated``) or none did."""
        st = self._require_state()
        if self.done:
            raise FleetError("action", "the fleet's sortie is over: call reset()")
        j = self.due
        if not (isinstance(action, (int, np.integer)) and 0 <= action < self.num_actions):
            raise FleetError("action", f"action must be a hovering-point index in [0, {self.num_actions})")
        if not (isinstance(intent, (int, np.integer)) and AT_BASE <= intent < self.num_actions):
            raise FleetError("intent", f"intent must be a hovering-point index in [0, {self.num_actions}) or "
                                       f"AT_BASE ({AT_BASE})")
        if action in st.held_points(j):
            raise FleetError("action", f"hovering point {action} is held by another UAV")
        if not self.action_mask(j)[action]:
            raise FleetError("action", f"hovering point {action} is not allowed for UAV {j} now")
        p, hp = self.params[j], self.hover_points[j]
        user_xyz = st.users.tolist()
        moves, news = np.empty_like(st.users), np.empty_like(st.tasks)
        draw_chance(self.params[0], moves, news, self.rng)  # as SortieEnv.step draws it: before the step
        user = served_user(p, hp[action], st.users, visible_tasks(st, j), st.served)
        if user != NO_USER and user in busy_users(st, j):  # visible_tasks excludes them: a broken rule
            raise FleetError("user", f"user {user} is being served by another UAV")
        from_xyz = st.uav_xyz[j].copy()
        start_s = float(st.clock_s[j])
        out = serve(scene_of(p, hp, st.task_table), st.world(j), int(action), int(user))
        st.bound[j] = out.user
        st.intent[j] = intent
        served_at = np.array(user_xyz[out.user]) if out.user != NO_USER else hp[action]
        duration = interval_duration_s(p, from_xyz, hp[action], served_at, out.bits)
        st.clock_s[j] += duration
        st.order[j] = self._next_order()
        st.events[0] += 1
        chance = scene_of(self.params[0], hp, st.task_table)
        if in_time(self.params[0]) and self.num_uavs == 1:  # the arrivals follow the interval's length
            advance(chance, st.chance_world(j), moves, NO_NEWS)
            draw_timed_arrivals(self.params[0], news, duration, self.rng)
            advance(chance, st.chance_world(j), NO_MOVES, news)
        elif in_time(self.params[0]):  # several UAVs: up to the fleet's time (``_settle_turn``)
            advance(chance, st.chance_world(j), moves, NO_NEWS)
        else:
            advance(chance, st.chance_world(j), moves, news)
        check_joint(st)
        self._waiting_since.pop(j, None)
        info = {
            "uav": j,
            "interval": int(st.intervals[j]) - 1,
            "hover_point": int(action),
            "uav_xyz": hp[action].tolist(),
            "user": int(out.user),
            "user_xyz": user_xyz[out.user],
            "tasks": int(out.tasks),
            "bits": float(out.bits),
            "e_hover_j": float(out.e_hover_j),
            "e_comp_j": float(out.e_comp_j),
            "e_flight_j": float(out.e_flight_j),
            "reward": float(out.reward),
            "battery_j": float(st.battery_j[j]),
            "start_s": start_s,
            "end_s": float(st.clock_s[j]),
        }
        self._settle_turn()
        info["ended"] = dict(self.ended)
        truncated = self.done and RETIRED_TRUNCATED in self.ended.values()
        return self.observation(), float(out.reward), self.done and not truncated, truncated, info

    # --- what a UAV may do ------------------------------------------------------------------
    def action_values(self, j: int) -> np.ndarray:
        """UAV ``j``'s reward q (11) for each hovering point now under the fleet's rules
        (the users the others serve are busy, the points they hold are taken); -inf where
        not allowed. (K,)"""
        st = self._require_state()
        q = np.empty(self.num_actions)
        evaluate_actions(self.params[j], self.hover_points[j], int(st.hover[j]), st.uav_xyz[j], st.users,
                         visible_tasks(st, j), st.served, float(st.battery_j[j]), q)
        q[st.held_points(j)] = -np.inf
        return q

    def action_mask(self, j: int) -> np.ndarray:
        """Which hovering points UAV ``j`` may fly to now; (K,) bool."""
        return np.isfinite(self.action_values(j))

    def view(self, j: int) -> SortieEnv:
        """UAV ``j`` as a single-UAV environment that knows nothing of the others (its own
        record, the users as they report themselves): the view a planner blind to the
        others plans on. Its state is a copy; stepping it does not change the fleet."""
        st = self._require_state()
        env = self._views[j]
        env.rng = np.random.default_rng(0)  # a view's chance is not the world's: never the fleet's generator
        env.state = st.sortie_state(j)
        env._done = False
        return env

    def claims_view(self, j: int) -> tuple[SortieEnv, np.ndarray]:
        """UAV ``j``'s view without what the others have committed to: the points they hold
        or say they fly to next (``rules.claimed_points``) are not in it, and the users they
        are serving have nothing to offload in it (``rules.visible_tasks``: for its next
        interval; under ``redraw`` the next draw brings them back, as the world does once
        their service ends). Returns the view and ``keep`` (K',): the fleet's index of each
        of the view's points, so the view's action a is the fleet's ``keep[a]``. Its current
        point, if the others claimed it, is not in the view: it is then at no point of it
        (``AT_BASE``), which changes nothing but that it may not stay (it may not anyway)."""
        st = self._require_state()
        return self.partial_view(j, claimed_points(st, j), busy_users(st, j))

    def partial_view(self, j: int, points: list[int], users: list[int]) -> tuple[SortieEnv, np.ndarray]:
        """UAV ``j``'s view without hovering points ``points`` and with nothing to offload
        for ``users`` (what it believes the others hold and serve: ``claims_view`` takes
        the fleet's own record, ``dec-mcts`` what the others' messages said). Returns the
        view and ``keep`` (K',), as ``claims_view`` does."""
        st = self._require_state()
        env = self._claims_views[j]
        keep = np.setdiff1d(np.arange(self.num_actions), np.asarray(points, dtype=np.int64))
        env.hover_points = self.hover_points[j][keep]
        env.rng = np.random.default_rng(0)  # a view's chance is not the world's
        state = st.sortie_state(j)
        state.tasks[np.asarray(users, dtype=np.int64)] = 0
        where = np.flatnonzero(keep == state.hover_index)
        state.hover_index = int(where[0]) if len(where) else AT_BASE
        env.state = state
        env._done = False
        return env, keep

    def observation(self) -> dict[str, Any]:
        st = self._require_state()
        return {"uav_xyz": st.uav_xyz.copy(), "hover": st.hover.copy(), "battery_j": st.battery_j.copy(),
                "intervals": st.intervals.copy(), "clock_s": st.clock_s.copy(), "bound": st.bound.copy(),
                "intent": st.intent.copy(), "active": st.active.copy(), "users_xyz": st.users.copy(),
                "tasks": st.tasks.copy(), "served": st.served.copy()}

    def snapshot(self) -> FleetSnapshot:
        return FleetSnapshot(self._require_state().copy(), self.rng.bit_generator.state, dict(self.ended),
                             self._order_next, dict(self._waiting_since), self._arrivals_until_s)

    def restore(self, snap: FleetSnapshot) -> None:
        self.state = snap.state.copy()
        self.rng.bit_generator.state = snap.rng_state
        self.ended, self._order_next = dict(snap.ended), snap.order_next
        self._waiting_since = dict(snap.waiting_since)
        self._arrivals_until_s = snap.arrivals_until_s

    # --- whose turn ---------------------------------------------------------------------------
    def _settle_turn(self) -> None:
        """Make ``due`` a UAV that can act: the UAV whose interval ends first stops for good if
        it reached ``max_intervals`` or no point is allowed to it even blind to the others; it
        waits (until the next other UAV's interval ends) if only the others block it; a UAV
        blocked again while nobody flew stops (two UAVs that block each other would wait
        forever)."""
        st = self._require_state()
        limit = self.scenario.max_intervals
        while not self.done:
            j = self.due
            self._arrivals_until(j)
            if limit and st.intervals[j] >= limit:
                self._retire(j, RETIRED_TRUNCATED)
            elif self.action_mask(j).any():
                return
            elif not self.view(j).action_mask().any() or self._waiting_since.get(j) == int(st.events[0]):
                self._retire(j, RETIRED_TERMINATED)
            else:  # only the others block it: wait for the next of them to end its interval
                st.bound[j] = NO_USER  # its own interval is over
                others = st.others(j)
                st.clock_s[j] = max(st.clock_s[j], st.clock_s[others].min())
                st.order[j] = self._next_order()
                self._waiting_since[j] = int(st.events[0])
        check_joint(st)

    def _arrivals_until(self, j: int) -> None:
        """With arrivals in time and several UAVs, the users' new tasks up to the fleet's time,
        the clock of UAV ``j`` whose turn it is (every other active UAV's is later): each span
        of the fleet's time is drawn once, whichever UAV's interval covered it, so N UAVs meet
        the arrivals of one clock, not N (one UAV: ``step`` draws them per interval, as
        ``SortieEnv`` does)."""
        st = self._require_state()
        now = float(st.clock_s[j])
        if self.num_uavs == 1 or not in_time(self.params[0]) or now <= self._arrivals_until_s:
            return
        news = np.empty_like(st.tasks)
        draw_timed_arrivals(self.params[0], news, now - self._arrivals_until_s, self.rng)
        advance(scene_of(self.params[0], self.hover_points[0], st.task_table), st.chance_world(j), NO_MOVES, news)
        self._arrivals_until_s = now

    def _retire(self, j: int, why: str) -> None:
        st = self._require_state()
        st.active[j] = False  # it flies home: it holds no point and serves nobody any more
        st.bound[j] = NO_USER
        st.intent[j] = AT_BASE
        self.ended[j] = why

    def _next_order(self) -> int:
        self._order_next += 1
        return self._order_next

    def _require_state(self) -> FleetState:
        if self.state is None:
            raise FleetError("state", "call reset() before using the fleet environment")
        return self.state


__all__ = ["FleetEnv", "FleetSnapshot", "RETIRED_TERMINATED", "RETIRED_TRUNCATED"]
