"""From the journal and the vehicle's telemetry to a safe, complete plan. Pure (numbers in,
numbers out): the service runs ``Planner.decide`` in a worker thread.

- ``assemble``: the model's ``SortieState`` from what the service knows. Users are every
  user heard from (in order of first request), standing where they last reported; a user
  with a pending request has its task count, any other has 0 (nothing to offload, so not
  eligible); service counts come from the journal (the fairness rule spans restarts).
- ``after_hold``: the state a decision on arrival at a point starts from, its hold done
  (its user served, the interval and its q counted).
- ``predict_path``: the planner's line as hovering points with hold times, by stepping a
  copy of the state along it with the model's own ``step``, with nothing happening
  between the intervals (the service knows no future): the user served at each point, its
  upload time (bits / rate: the hold), the energy. A served user's request is consumed
  (the step offloads its tasks; its next request is unknown until it asks again), so the
  line stops where nobody known is eligible, and where the next step would break the
  energy reserve (9b) with the way home.
- ``Planner``: the algorithm the operator chose (``planner.algo``): ``mcts`` (default),
  ``ts-mcts``, ``mcts-paper`` (their principal line is the path), ``greedy`` or ``random``
  (one-step rules: the path is the same rule applied again along the predicted state).
- ``check_path``: an independent guard before upload: every point inside the area and
  altitude limits, the predicted energy above the reserve.

The number of users I of an ``MctsPlanner`` is fixed by its scenario: when a new user
appears the planner is rebuilt for the new I (its tree is lost; it is rebuilt from the
next decision on). Padding with absent users would keep the tree but make every playout
pay for users that do not exist.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from protocol import Area

from ..mcts import MctsConfig, MctsPlanner, PaperMctsPlanner, warm_up
from ..model import AT_BASE, NO_MOVES, NO_NEWS, NO_USER, Scenario, SortieState, base_position, hover_points, pack
from ..model.channel import channel_gain, upload_rate_bps
from ..model.energy import flight_energy_j
from ..model.interval import (evaluate_actions, remaining_intervals, return_energy_j, served_user, user_outcome,
                              within_budget)
from ..model.world import clone, evaluate, scene_of, step
from ..policy import Decision
from .config import FLIGHT_ALGOS, FlightAlgo
from .errors import PlanningError
from .rows import RequestRow, ServiceRow, UserRow


@dataclass(frozen=True)
class VehicleFix:
    """What the telemetry says about the vehicle, in local metres and joules."""

    x_m: float
    y_m: float
    z_m: float
    battery_j: float
    airborne: bool


@dataclass(frozen=True)
class Assembled:
    """The model's state and how its user indices map back to the journal."""

    state: SortieState
    user_ids: tuple[str, ...]
    request_ids: tuple[int, ...]
    """Pending request id of each user index, 0 where none."""


@dataclass(frozen=True)
class PlannedPoint:
    hover_index: int
    x_m: float
    y_m: float
    z_m: float
    hold_s: float
    user_id: str
    request_id: int
    tasks: int
    bits: float
    energy_j: float
    reward: float


@dataclass(frozen=True)
class PlannedPath:
    points: tuple[PlannedPoint, ...]
    predicted_energy_j: float
    """Energy of the points' flights, hovers and computation, plus the flight home."""
    battery_after_j: float
    """Predicted battery on landing."""
    stop_reason: str
    """Why the path ends where it does (the line ended, nobody eligible, energy reserve)."""


def assemble(scenario: Scenario, users: list[UserRow], pending: list[RequestRow], services: list[ServiceRow],
             fix: VehicleFix, last_hover_index: int) -> Assembled:
    """The sortie state for the planner (shapes: users (I, 3), tasks and served (I,))."""
    ids = tuple(u.user_id for u in users)
    index = {uid: i for i, uid in enumerate(ids)}
    n = len(ids)
    positions = np.array([[u.x_m, u.y_m, u.z_m] for u in users], dtype=np.float64).reshape(n, 3)
    tasks = np.zeros(n, dtype=np.int64)
    request_ids = [0] * n
    for row in pending:
        i = index[row.user_id]
        tasks[i] = row.backlog  # what is left of it: a service may have consumed part
        request_ids[i] = row.request_id
        positions[i] = (row.x_m, row.y_m, row.z_m)
    served = np.array([u.services for u in users], dtype=np.int64)
    if fix.airborne:
        uav = np.array([fix.x_m, fix.y_m, fix.z_m], dtype=np.float64)
        hover_index = last_hover_index
    else:  # on the ground: the model's sortie starts at its base position
        uav, hover_index = base_position(scenario), AT_BASE
    state = SortieState(
        uav_xyz=uav, hover_index=hover_index, users=positions, tasks=tasks, served=served,
        battery_j=float(fix.battery_j), interval=len(services),
        energy_used_j=float(scenario.battery_j - fix.battery_j),
        task_table=np.zeros((0, n), dtype=np.int64), reward_sum=float(sum(s.reward for s in services)),
    )
    return Assembled(state, ids, tuple(request_ids))


def after_hold(assembled: Assembled, point: PlannedPoint, serving: str | None, reward: float) -> Assembled:
    """The state as it will be when the hold at ``point`` ends: the vehicle there and, if
    it serves the user ``serving``, that user served (its tasks consumed, one more service)
    and one more interval, whose q (``reward``) joins the sortie's sum: the interval and its
    reward are counted together, or the sortie's average (``mcts``'s objective) would take
    the hold under way for an interval that earned nothing."""
    state = assembled.state.copy()
    state.uav_xyz = np.array([point.x_m, point.y_m, point.z_m], dtype=np.float64)
    state.hover_index = point.hover_index
    if serving is not None and serving in assembled.user_ids:
        i = assembled.user_ids.index(serving)
        state.tasks[i] = 0
        state.served[i] += 1
        state.interval += 1
        state.reward_sum += reward
    return replace(assembled, state=state)


def hold_time_s(p: np.ndarray, hover_xyz: np.ndarray, user_xyz: np.ndarray, bits: float) -> float:
    """How long the user's upload of ``bits`` takes from ``hover_xyz``: S / R."""
    return float(bits / upload_rate_bps(p, channel_gain(p, hover_xyz, user_xyz)))


def predict_path(scenario: Scenario, points: np.ndarray, assembled: Assembled, line: tuple[int, ...],
                 max_points: int | None = None) -> PlannedPath:
    """Step a copy of the state along ``line`` (hovering-point indices) with the model, at
    most ``max_points`` of them (what the autopilot's mission holds): a shorter path is
    safe, since every step kept the energy for the way home from its point."""
    p = pack(scenario)
    state = assembled.state
    scene = scene_of(p, points, state.task_table)
    w = clone(state.world())
    out: list[PlannedPoint] = []
    reason = "the planned line ends"
    for k in line:
        if max_points is not None and len(out) >= max_points:
            reason = "the autopilot's mission capacity"
            break
        if not 0 <= k < len(points):
            raise PlanningError("line", f"hovering point {k} does not exist (K = {len(points)})")
        if k == w.hover[0] and not scenario.allow_stay:
            reason = "the line stays at one point"
            break
        user = served_user(p, points[k], w.users, w.tasks, w.served)
        if user == NO_USER:
            reason = "nobody known is eligible further on"
            break
        bits, e_h, e_c, e_f, q = user_outcome(p, w.uav_xyz, points[k], w.users[user], w.tasks[user])
        energy = e_h + e_c + e_f
        if not within_budget(p, w.battery_j[0], energy, points[k]):
            reason = "the energy reserve"
            break
        hold = hold_time_s(p, points[k], w.users[user], bits)
        served = step(scene, w, int(k), NO_MOVES, NO_NEWS)  # its request is consumed; nothing else changes
        out.append(PlannedPoint(
            hover_index=int(k), x_m=float(points[k][0]), y_m=float(points[k][1]), z_m=float(points[k][2]),
            hold_s=hold, user_id=assembled.user_ids[user], request_id=assembled.request_ids[user],
            tasks=int(served.tasks), bits=float(served.bits), energy_j=float(energy), reward=float(served.reward)))
    home = return_energy_j(p, w.uav_xyz)
    spent = sum(pt.energy_j for pt in out) + home
    return PlannedPath(tuple(out), float(spent), float(state.battery_j - spent), reason)


def one_step_line(scenario: Scenario, points: np.ndarray, state: SortieState, choose: Callable[[np.ndarray], int],
                  max_points: int | None = None) -> tuple[int, ...]:
    """A one-step rule's path: ``choose`` (q (K,), -inf where not allowed -> an allowed
    index) applied at the state, then again along the state predicted as ``predict_path``
    predicts it, until nothing is allowed (at most ``max_points`` points)."""
    p = pack(scenario)
    scene = scene_of(p, points, state.task_table)
    w = clone(state.world())
    q = np.empty(len(points))
    longest = remaining_intervals(p, len(state.users), state.interval)
    if max_points is not None:
        longest = min(longest, max_points)
    line: list[int] = []
    while len(line) < max(longest, 1) and evaluate(scene, w, q) > 0:
        line.append(int(choose(q)))
        step(scene, w, line[-1], NO_MOVES, NO_NEWS)
    return tuple(line)


def check_path(path: PlannedPath, area: Area, scenario: Scenario, battery_j: float) -> None:
    """Refuse a path that leaves the area or altitude limits or eats into the reserve."""
    for i, pt in enumerate(path.points):
        if not area.contains_xy(pt.x_m, pt.y_m):
            raise PlanningError("area", f"point {i} ({pt.x_m:.1f}, {pt.y_m:.1f}) m lies outside [0, {area.side_m}]^2")
        if not area.min_flight_altitude_m <= pt.z_m <= area.max_altitude_m:
            raise PlanningError("altitude", f"point {i} at {pt.z_m:.1f} m is outside "
                                f"[{area.min_flight_altitude_m}, {area.max_altitude_m}] m")
        if not (math.isfinite(pt.hold_s) and pt.hold_s >= 0):
            raise PlanningError("hold", f"point {i} has hold {pt.hold_s} s")
    floor = scenario.energy_floor_j
    # points' energy, plus the way home when the scenario keeps it in reserve
    needed = path.predicted_energy_j if scenario.reserve_return_energy else sum(p.energy_j for p in path.points)
    if path.points and battery_j - needed < floor - 1e-6:
        raise PlanningError("energy", f"the path needs {needed:.0f} J of {battery_j:.0f} J and would go "
                            f"below the reserve of {floor:.0f} J")


def not_served_reason(scenario: Scenario, tasks: int, services: int, ending: str) -> str:
    """Why a pending request was not served when the sortie ended."""
    if tasks <= 0:
        return "no tasks to offload"
    if services >= scenario.max_services_per_user:
        return f"fairness: already served {services} times (limit {scenario.max_services_per_user})"
    if services > 0 and tasks <= scenario.fairness_threshold_tasks:
        return (f"fairness: a repeat needs more than {scenario.fairness_threshold_tasks:g} tasks, "
                f"asked {tasks}")
    return ending


def planning_battery_j(scenario: Scenario, battery_j: float, stale_vehicle_s: float, margin_j: float) -> float:
    """The battery the planner may count on: the last reading, less what the vehicle spends
    until the plan is flown (``stale_vehicle_s`` of vehicle time: the reading's age plus
    the search, at the most power-hungry of hovering and cruising), less the landing
    descent from the base altitude (the model's way home ends at base, in the air) and the
    configured margin."""
    p = pack(scenario)
    power_w = max(scenario.hover_power_w, flight_energy_j(p, scenario.speed_mps))  # 1 s of cruise
    descent_j = flight_energy_j(p, scenario.base_z_m)
    return battery_j - power_w * max(stale_vehicle_s, 0.0) - descent_j - margin_j


def first_steps(scenario: Scenario, points: np.ndarray, requests: list[RequestRow], served: list[int],
                uav_xyz: tuple[float, float, float], hover_index: int, battery_j: float) -> int:
    """How many hovering points a decision from ``uav_xyz`` could fly to first with
    ``battery_j``: the model's first step (``evaluate_actions``) on the pending
    ``requests`` (``served``: each one's user's services). 0: a decision would find nothing
    to fly, whatever its search."""
    users = np.array([[r.x_m, r.y_m, r.z_m] for r in requests], dtype=np.float64).reshape(len(requests), 3)
    tasks = np.array([r.backlog for r in requests], dtype=np.int64)
    q = np.empty(len(points))
    return int(evaluate_actions(pack(scenario), points, hover_index, np.array(uav_xyz, dtype=np.float64), users,
                                tasks, np.array(served, dtype=np.int64), float(battery_j), q))


PAPER_ITERATIONS = 1000
"""Iterations of ``mcts-paper`` and ``ts-mcts`` when ``planner.iterations`` is 0: the
paper's n (they run a number of iterations, not a clock budget)."""


class Planner:
    """The chosen algorithm for the current set of users; rebuilt when that set grows."""

    def __init__(self, scenario: Scenario, config: MctsConfig, seed: int, max_points: int | None = None,
                 algo: FlightAlgo = "mcts") -> None:
        if algo not in FLIGHT_ALGOS:
            raise PlanningError("algo", f"unknown algorithm {algo!r}; choose from {FLIGHT_ALGOS}")
        self.base = scenario
        self.config = config
        self.algo = algo
        self.max_points = max_points
        """The most hovering points one mission holds (the autopilot's capacity)."""
        self.points = hover_points(scenario)
        self.rng = np.random.default_rng(seed)
        self._planner: MctsPlanner | PaperMctsPlanner | None = None
        self._users = -1
        self._keep = np.arange(len(self.points))
        """The hovering points the planner was built on (a fleet's: without the points the
        other members claim), as indices of ``points``."""

    def new_sortie(self) -> None:
        """Forget the search tree: a new sortie starts from the base with fresh counts, which
        the tree of the last one knows nothing about (the generator runs on)."""
        if isinstance(self._planner, MctsPlanner):
            self._planner.reset()

    def scenario_for(self, num_users: int) -> Scenario:
        return self.base.replace(num_users=max(num_users, 1))

    def decide(self, assembled: Assembled, blocked: frozenset[int] = frozenset()) -> tuple[Decision | None, PlannedPath]:
        """The next decision and the predicted path; (None, empty path) when nothing is
        allowed (the sortie is over for now). ``blocked``: hovering points the planner may
        not use (in a fleet, the others' next points and holds: the offline ``claims``
        planner's rule); the planner is then built on the others, renumbered, and its tree
        is lost whenever they change. Runs in a worker thread: CPU-bound, nogil."""
        n = len(assembled.user_ids)
        scenario = self.scenario_for(n)
        keep = np.setdiff1d(np.arange(len(self.points)), np.array(sorted(blocked), dtype=np.int64))
        if n != self._users or not np.array_equal(keep, self._keep) or (
                self._planner is None and self.algo in ("mcts", "ts-mcts", "mcts-paper")):
            self._keep = keep
            self._planner = self._build(scenario, self.points[keep])
            self._users = n
        if n == 0 or len(keep) == 0:
            return None, predict_path(scenario, self.points, assembled, ())
        state = assembled.state
        if len(keep) < len(self.points):  # the view without the blocked points
            state = state.copy()
            where = np.flatnonzero(keep == state.hover_index)
            state.hover_index = int(where[0]) if len(where) else AT_BASE
        try:
            decision = self._plan(scenario, state, self.points[keep])
        except ValueError:  # no hovering point allowed: nobody eligible or no energy
            return None, predict_path(scenario, self.points, assembled, ())
        decision = replace(decision, action=int(keep[decision.action]),
                           line=tuple(int(keep[a]) for a in decision.line))
        return decision, predict_path(scenario, self.points, assembled, decision.line, self.max_points)

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel this planner uses in flight, so
        that the first real decision compiles nothing (``mcts.warm_up``, then this
        planner's own decision and path on a small state)."""
        warm_up(self.base, algos=(self.algo,))
        probe = Planner(self.base, self.config, 0, self.max_points, self.algo)
        probe.decide(warm_up_assembled(self.base))
        planning_battery_j(self.base, self.base.battery_j, 1.0, 0.0)

    def _build(self, scenario: Scenario, points: np.ndarray) -> MctsPlanner | PaperMctsPlanner | None:
        if self.algo == "mcts":
            return MctsPlanner(scenario, points, self.config, self.rng)
        if self.algo in ("mcts-paper", "ts-mcts"):
            n = self.config.iterations or PAPER_ITERATIONS
            schedule = "timesaving" if self.algo == "ts-mcts" else "paper"
            return PaperMctsPlanner(scenario, points, n, self.rng, schedule=schedule)
        return None

    def _plan(self, scenario: Scenario, state: SortieState, points: np.ndarray) -> Decision:
        if self._planner is not None:
            return self._planner.plan(state)
        start = time.perf_counter()
        if self.algo == "greedy":
            line = one_step_line(scenario, points, state, lambda q: int(np.argmax(q)), self.max_points)
        else:
            line = one_step_line(scenario, points, state,
                                 lambda q: int(self.rng.choice(np.flatnonzero(np.isfinite(q)))), self.max_points)
        if not line:
            raise ValueError("no hovering point is allowed in this state: the sortie is over")
        return Decision(action=line[0], line=line, wall_s=time.perf_counter() - start)


def warm_up_assembled(scenario: Scenario) -> Assembled:
    """A small state as the service assembles it, in the air part-way through a sortie:
    three users with requests, one served already."""
    users = [UserRow(user_id=f"warm-up-{i}", x_m=100.0 + 150.0 * i, y_m=150.0 + 100.0 * i, z_m=0.0,
                     services=int(i == 0)) for i in range(3)]
    pending = [RequestRow(request_id=i + 1, user_id=u.user_id, x_m=u.x_m, y_m=u.y_m, z_m=u.z_m,
                          tasks=18 if i == 0 else 8 + i, client_ref=None, accepted_at_s=0.0, status="pending",
                          reason="") for i, u in enumerate(users)]
    fix = VehicleFix(50.0, 50.0, scenario.altitude_m, 0.9 * scenario.battery_j, True)
    return assemble(scenario, users, pending, [], fix, 0)
