"""One step of the world: the only place where an interval happens.

``step`` flies the UAV to a hovering point, serves the nearest eligible user there, counts
the service, offloads that user's tasks, charges the battery, advances the interval, and
then applies the chance between two intervals (the users' moves (1)-(2) and their new task
counts). The environment, every planner's playouts, the reference planner and the
service's path prediction all call it, so an interval means the same thing everywhere.

The state is passed as a named record of arrays (``World``) that numba compiles, so a
kernel changes it in place; scalars sit in one-element arrays for that reason. What stays
fixed during a sortie is a second record (``Scene``). ``Outcome`` is what one step did.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import params as P
from ._jit import jit, jit_borrow
from .interval import NO_USER, evaluate_actions, served_user, user_outcome
from .mobility import apply_moves, draw_arrivals, draw_moves, draw_tasks, draw_timed_arrivals


class Scene(NamedTuple):
    """What a sortie's steps read and never change.

    ``p`` (P.SIZE,) the kernel parameter vector (``params.pack``), ``hover_points`` (K, 3),
    ``task_table`` (T, I) int64: a known task schedule, row t used at interval t (T may be
    0: tasks are drawn). Under ``task_model = "backlog"`` row 0 is the first backlog and
    row t >= 1 the tasks that arrive before interval t.
    """

    p: np.ndarray
    hover_points: np.ndarray
    task_table: np.ndarray


class World(NamedTuple):
    """The state one step changes (in place). Shapes: ``uav_xyz`` (3,), ``users`` (I, 3),
    ``tasks`` and ``served`` (I,) int64; the scalars are (1,) arrays: ``hover`` (int64,
    the current hovering point or ``AT_BASE``), ``battery_j``, ``interval`` (int64, the
    next interval's index), ``energy_used_j``, ``reward_sum`` (sum of q so far)."""

    uav_xyz: np.ndarray
    hover: np.ndarray
    users: np.ndarray
    tasks: np.ndarray
    served: np.ndarray
    battery_j: np.ndarray
    interval: np.ndarray
    energy_used_j: np.ndarray
    reward_sum: np.ndarray


class Outcome(NamedTuple):
    """What one step did: the user served (``NO_USER``: nobody, and nothing else happened
    but the interval passing), its task count, the bits offloaded, the three energies and
    the reward q (11)."""

    user: int
    tasks: int
    bits: float
    e_hover_j: float
    e_comp_j: float
    e_flight_j: float
    reward: float


NO_MOVES = np.zeros((0, 3))
"""``moves`` for "the users stay where they are" (a prediction that knows no future)."""
NO_NEWS = np.zeros(0, dtype=np.int64)
"""``news`` for "no new task counts": the counts stay, less what was served."""


def scene_of(p: np.ndarray, hover_points: np.ndarray, task_table: np.ndarray) -> Scene:
    """A ``Scene`` with the array types the kernels are compiled for."""
    return Scene(np.ascontiguousarray(p, dtype=np.float64),
                 np.ascontiguousarray(hover_points, dtype=np.float64),
                 np.ascontiguousarray(task_table, dtype=np.int64))


def world_from(uav_xyz: np.ndarray, hover: int, users: np.ndarray, tasks: np.ndarray, served: np.ndarray,
               battery_j: float, interval: int, energy_used_j: float = 0.0, reward_sum: float = 0.0) -> World:
    """A ``World`` from plain values. Arrays that already have the kernels' type are used as
    they are (not copied), so a step changes them."""
    users = np.ascontiguousarray(users, dtype=np.float64)
    return World(
        np.ascontiguousarray(uav_xyz, dtype=np.float64),
        np.array([hover], dtype=np.int64),
        users if users.ndim == 2 else users.reshape(-1, 3),
        np.ascontiguousarray(tasks, dtype=np.int64),
        np.ascontiguousarray(served, dtype=np.int64),
        np.array([battery_j], dtype=np.float64),
        np.array([interval], dtype=np.int64),
        np.array([energy_used_j], dtype=np.float64),
        np.array([reward_sum], dtype=np.float64),
    )


@jit
def clone(w: World) -> World:
    """A copy of ``w`` that shares no array with it."""
    return World(w.uav_xyz.copy(), w.hover.copy(), w.users.copy(), w.tasks.copy(), w.served.copy(),
                 w.battery_j.copy(), w.interval.copy(), w.energy_used_j.copy(), w.reward_sum.copy())


@jit_borrow
def copy_into(dst: World, src: World) -> None:
    """Make ``dst`` equal to ``src`` (same shapes), in place."""
    for a in range(3):
        dst.uav_xyz[a] = src.uav_xyz[a]
    users, tasks, served = dst.users, dst.tasks, dst.served
    for i in range(users.shape[0]):
        for a in range(3):
            users[i, a] = src.users[i, a]
        tasks[i] = src.tasks[i]
        served[i] = src.served[i]
    dst.hover[0] = src.hover[0]
    dst.battery_j[0] = src.battery_j[0]
    dst.interval[0] = src.interval[0]
    dst.energy_used_j[0] = src.energy_used_j[0]
    dst.reward_sum[0] = src.reward_sum[0]


@jit
def evaluate(scene: Scene, w: World, out_q: np.ndarray) -> int:
    """Each hovering point's reward q now, -inf where not allowed; returns how many are
    allowed (``interval.evaluate_actions`` on ``w``)."""
    return evaluate_actions(scene.p, scene.hover_points, w.hover[0], w.uav_xyz, w.users, w.tasks, w.served,
                            w.battery_j[0], out_q)


@jit_borrow
def serve(scene: Scene, w: World, action: int, user: int) -> Outcome:
    """Fly to hovering point ``action`` and serve ``user`` there (the nearest eligible one,
    ``served_user``; a search that knows it already passes it): count the service, offload
    the user's tasks, charge the battery, advance the interval. No chance yet."""
    if user == NO_USER:
        out = Outcome(NO_USER, 0, 0.0, 0.0, 0.0, 0.0, 0.0)
    else:
        tasks = w.tasks[user]
        bits, e_h, e_c, e_f, q = user_outcome(scene.p, w.uav_xyz, scene.hover_points[action], w.users[user], tasks)
        out = Outcome(user, tasks, bits, e_h, e_c, e_f, q)
    settle(scene, w, action, out.user, out.e_hover_j + out.e_comp_j + out.e_flight_j, out.reward)
    return out


@jit_borrow
def settle(scene: Scene, w: World, action: int, user: int, energy_j: float, reward: float) -> None:
    """``serve``'s change to ``w`` once the interval's energy and reward are known: a
    playout along a shared future knows them from its index (bit for bit what ``serve``
    computes: the same expressions on the same numbers) and need not price the step twice."""
    if user != NO_USER:
        w.served[user] += 1
        w.tasks[user] = 0  # offloaded; under the paper's redraw the next draw replaces it anyway
        for a in range(3):
            w.uav_xyz[a] = scene.hover_points[action, a]
    w.battery_j[0] -= energy_j
    w.energy_used_j[0] += energy_j
    w.reward_sum[0] += reward
    w.hover[0] = action
    w.interval[0] += 1


@jit_borrow
def advance(scene: Scene, w: World, moves: np.ndarray, news: np.ndarray) -> None:
    """The chance between two intervals, in place: the users move by ``moves`` (I, 3)
    (1)-(2), then their task counts follow ``news`` (I,) (new counts, or arrivals under
    ``backlog``), or the scene's task table where it has a row for the interval now due.
    Empty ``moves`` (``NO_MOVES``) or ``news`` (``NO_NEWS``): that part does not happen."""
    p = scene.p
    if moves.shape[0] > 0:
        apply_moves(p, w.users, moves)
    t = w.interval[0]
    table = scene.task_table
    if t < table.shape[0]:
        _take_tasks(p, w.tasks, table[t])
    elif news.shape[0] > 0:
        _take_tasks(p, w.tasks, news)


@jit_borrow
def _take_tasks(p: np.ndarray, tasks: np.ndarray, news: np.ndarray) -> None:
    """Every user's task count at the next interval: the new draw (``redraw``), or the
    backlog plus the arrivals, capped at u_max (``backlog``)."""
    if p[P.TASK_MODEL] == P.BACKLOG:
        top = int(p[P.TASK_MAX])
        for i in range(tasks.shape[0]):
            tasks[i] = min(tasks[i] + news[i], top)
    else:
        for i in range(tasks.shape[0]):
            tasks[i] = news[i]


@jit
def step(scene: Scene, w: World, action: int, moves: np.ndarray, news: np.ndarray) -> Outcome:
    """One interval: ``serve`` the nearest eligible user from hovering point ``action``,
    then ``advance`` with the chance ``moves`` and ``news`` (drawn by ``draw_chance``, or
    ``NO_MOVES`` / ``NO_NEWS``)."""
    user = served_user(scene.p, scene.hover_points[action], w.users, w.tasks, w.served)
    out = serve(scene, w, action, user)
    advance(scene, w, moves, news)
    return out


@jit
def in_time(p: np.ndarray) -> bool:
    """Whether new tasks arrive in time (``backlog`` with ``task_arrival_period_s`` > 0):
    an interval's arrivals then depend on how long it lasted (``draw_chance_after``)."""
    return p[P.TASK_MODEL] == P.BACKLOG and p[P.ARRIVAL_PERIOD] > 0.0


@jit
def draw_chance_after(p: np.ndarray, moves: np.ndarray, news: np.ndarray, duration_s: float,
                      rng: np.random.Generator) -> None:
    """``draw_chance`` for an interval known to have lasted ``duration_s``: the same draws
    unless tasks arrive in time (``in_time``), when the arrivals follow its duration."""
    if in_time(p):
        draw_moves(p, moves, rng)
        draw_timed_arrivals(p, news, duration_s, rng)
    else:
        draw_chance(p, moves, news, rng)


@jit
def draw_chance(p: np.ndarray, moves: np.ndarray, news: np.ndarray, rng: np.random.Generator) -> None:
    """Draw what happens between two intervals: every user's move, then every user's new
    task count (``redraw``) or new tasks (``backlog``). ``moves`` (I, 3) and ``news`` (I,)
    are filled in place."""
    draw_moves(p, moves, rng)
    if p[P.TASK_MODEL] == P.BACKLOG:
        draw_arrivals(p, news, rng)
    else:
        draw_tasks(p, news, rng)


__all__ = ["NO_MOVES", "NO_NEWS", "Outcome", "Scene", "World", "advance", "clone", "copy_into", "draw_chance",
           "draw_chance_after", "evaluate", "in_time", "scene_of", "serve", "settle", "step", "world_from"]
