"""One interval of service: which user is served, what it costs, what it earns.

These kernels compose the equations of the other modules; ``world.step`` (the one step of
the world that the environment, the planners' playouts and the service's path prediction
take) and the evaluation of every action call them, so the physics exists once.
Array shapes: hover points (K, 3), users (I, 3), tasks and service counts (I,) int64,
positions (3,) in local metres (x east, y north, z up).
"""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import jit, jit_borrow
from .channel import channel_gain, distance_sq_m2, upload_rate_bps
from .energy import computation_energy_j, flight_energy_j, hover_energy_j
from .fairness import is_eligible
from .reward import interval_reward

NO_USER = -1
"""Served-user sentinel: nobody eligible."""
AT_BASE = -1
"""Hovering-point sentinel: the UAV is at its base position."""


@jit_borrow
def eligible_users(p: np.ndarray, tasks: np.ndarray, served: np.ndarray, out: np.ndarray) -> int:
    """Fill ``out`` (I,) bool with who may be served now (3); returns how many."""
    count = 0
    for i in range(tasks.shape[0]):
        out[i] = is_eligible(p, tasks[i], served[i])
        count += out[i]
    return count


@jit_borrow
def nearest_eligible(
    p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray, eligible: np.ndarray,
    distance: np.ndarray,
) -> int:
    """The nearest user among ``eligible`` (4); users within ``nearest_tie_m`` of the
    nearest are tied and the larger task wins (Fig. 2), then the lower index. ``NO_USER``
    if nobody is eligible. ``distance`` (I,) is scratch space (squared distances)."""
    nearest_sq = math.inf
    for i in range(users.shape[0]):
        if eligible[i]:
            distance[i] = distance_sq_m2(hover_xyz, users[i])
            nearest_sq = min(nearest_sq, distance[i])
    # within the tie of the nearest: d <= d_min + tie, compared squared (no square roots)
    reach = math.sqrt(nearest_sq) + p[P.TIE_M]
    reach_sq = reach * reach
    chosen = NO_USER
    for i in range(users.shape[0]):
        if eligible[i] and distance[i] <= reach_sq:
            if chosen == NO_USER or tasks[i] > tasks[chosen]:
                chosen = i
    return chosen


@jit
def served_user(
    p: np.ndarray, hover_xyz: np.ndarray, users: np.ndarray, tasks: np.ndarray, served: np.ndarray
) -> int:
    """Who is served from ``hover_xyz``: the nearest eligible user (see ``nearest_eligible``)."""
    eligible = np.empty(users.shape[0], dtype=np.bool_)
    eligible_users(p, tasks, served, eligible)
    return nearest_eligible(p, hover_xyz, users, tasks, eligible, np.empty(users.shape[0]))


@jit_borrow
def service_cost(
    p: np.ndarray, hover_xyz: np.ndarray, user_xyz: np.ndarray, tasks: int
) -> tuple[float, float, float]:
    """What serving a user with ``tasks`` at ``user_xyz`` from ``hover_xyz`` costs, wherever
    the UAV came from: (bits S = u B_t, e_hover_j, e_comp_j)."""
    bits = tasks * p[P.BITS_PER_TASK]  # S(t) = u_i(t) B_t
    rate = upload_rate_bps(p, channel_gain(p, hover_xyz, user_xyz))
    return bits, hover_energy_j(p, bits, rate), computation_energy_j(p, bits)


@jit_borrow
def hop_energy_j(p: np.ndarray, from_xyz: np.ndarray, to_xyz: np.ndarray) -> float:
    """Energy of the flight ``from_xyz`` -> ``to_xyz`` (7)-(8)."""
    return flight_energy_j(p, math.sqrt(distance_sq_m2(from_xyz, to_xyz)))


@jit_borrow
def user_outcome(
    p: np.ndarray, from_xyz: np.ndarray, hover_xyz: np.ndarray, user_xyz: np.ndarray, tasks: int
) -> tuple[float, float, float, float, float]:
    """Fly ``from_xyz`` -> ``hover_xyz`` and serve a user with ``tasks`` at ``user_xyz``:
    (bits, e_hover_j, e_comp_j, e_flight_j, q)."""
    bits, e_h, e_c = service_cost(p, hover_xyz, user_xyz, tasks)
    e_f = hop_energy_j(p, from_xyz, hover_xyz)
    q = interval_reward(p, tasks, e_h + e_c + e_f)
    return bits, e_h, e_c, e_f, q


@jit
def service_outcome(
    p: np.ndarray,
    from_xyz: np.ndarray,
    hover_xyz: np.ndarray,
    users: np.ndarray,
    tasks: np.ndarray,
    served: np.ndarray,
) -> tuple[int, float, float, float, float, float]:
    """Fly ``from_xyz`` -> ``hover_xyz`` and serve there.

    Returns (user, bits, e_hover_j, e_comp_j, e_flight_j, q); user is ``NO_USER`` (and
    the rest zero) when nobody is eligible.
    """
    user = served_user(p, hover_xyz, users, tasks, served)
    if user == NO_USER:
        return NO_USER, 0.0, 0.0, 0.0, 0.0, 0.0
    bits, e_h, e_c, e_f, q = user_outcome(p, from_xyz, hover_xyz, users[user], tasks[user])
    return user, bits, e_h, e_c, e_f, q


@jit_borrow
def interval_duration_s(p: np.ndarray, from_xyz: np.ndarray, hover_xyz: np.ndarray, user_xyz: np.ndarray,
                        bits: float) -> float:
    """How long an interval lasts: the flight ``from_xyz`` -> ``hover_xyz`` at the
    scenario's speed, then the upload of ``bits`` from ``user_xyz`` (S / R; none when
    nobody is served, ``bits`` 0)."""
    flight_s = math.sqrt(distance_sq_m2(from_xyz, hover_xyz)) / p[P.SPEED]
    if bits <= 0.0:
        return flight_s
    return flight_s + bits / upload_rate_bps(p, channel_gain(p, hover_xyz, user_xyz))


@jit_borrow
def return_energy_j(p: np.ndarray, hover_xyz: np.ndarray) -> float:
    """Energy to fly from ``hover_xyz`` back to base."""
    dx = hover_xyz[0] - p[P.BASE_X]
    dy = hover_xyz[1] - p[P.BASE_Y]
    dz = hover_xyz[2] - p[P.BASE_Z]
    return flight_energy_j(p, math.sqrt(dx * dx + dy * dy + dz * dz))


@jit_borrow
def budget_ok(p: np.ndarray, battery_j: float, energy_j: float, home_j: float) -> bool:
    """The battery stays at or above theta E_0 after an interval of ``energy_j`` (9b), and
    also keeps ``home_j`` (the flight home from its point) when ``reserve_return_energy``."""
    left = battery_j - energy_j
    if p[P.RESERVE_RETURN] > 0.5:
        left -= home_j
    return left >= p[P.ENERGY_FLOOR]


@jit_borrow
def within_budget(p: np.ndarray, battery_j: float, energy_j: float, hover_xyz: np.ndarray) -> bool:
    """``budget_ok`` for an interval served from ``hover_xyz``."""
    home = return_energy_j(p, hover_xyz) if p[P.RESERVE_RETURN] > 0.5 else 0.0
    return budget_ok(p, battery_j, energy_j, home)


@jit
def evaluate_actions(
    p: np.ndarray,
    hover_points: np.ndarray,
    hover_index: int,
    uav_xyz: np.ndarray,
    users: np.ndarray,
    tasks: np.ndarray,
    served: np.ndarray,
    battery_j: float,
    out_q: np.ndarray,
) -> int:
    """Fill ``out_q`` (K,) with each hovering point's reward q, or -inf where the action
    is not allowed (same point without ``allow_stay``, nobody eligible, over budget).
    Returns the number of allowed actions."""
    allowed = 0
    eligible = np.empty(users.shape[0], dtype=np.bool_)
    distance = np.empty(users.shape[0])
    anyone = eligible_users(p, tasks, served, eligible) > 0
    for k in range(hover_points.shape[0]):
        out_q[k] = -math.inf
        if not anyone or (k == hover_index and p[P.ALLOW_STAY] < 0.5):
            continue
        user = nearest_eligible(p, hover_points[k], users, tasks, eligible, distance)
        bits, e_h, e_c, e_f, q = user_outcome(p, uav_xyz, hover_points[k], users[user], tasks[user])
        if not within_budget(p, battery_j, e_h + e_c + e_f, hover_points[k]):
            continue
        out_q[k] = q
        allowed += 1
    return allowed


@jit_borrow
def remaining_intervals(p: np.ndarray, num_users: int, interval: int) -> int:
    """An upper bound on the intervals left: the length limit, else the fairness limit
    (every interval serves one user, each at most ``max_services`` times)."""
    if p[P.MAX_INTERVALS] > 0:
        return max(int(p[P.MAX_INTERVALS]) - interval, 0)
    return num_users * int(p[P.MAX_SERVICES])
