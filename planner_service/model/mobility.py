"""Random-waypoint user moves (1)-(2), the per-interval task draws and the arrivals of the
backlog task model (once per interval, or in time).

Drawing and applying are separate so a planner can draw many futures up front and apply
them later (common random numbers); ``move_users`` does both in the environment's order.
"""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import HAVE_NUMBA, jit, jit_borrow

try:  # numba's own scalar draw behind Generator.integers, without its one-element array
    from numba.np.random.random_methods import buffered_bounded_lemire_uint32 as _lemire32
except ImportError:  # pragma: no cover - no numba, or a numba that moved it
    _lemire32 = None

if HAVE_NUMBA and _lemire32 is not None:

    @jit
    def draw_int(rng: np.random.Generator, low: int, high: int) -> int:
        """``rng.integers(low, high)`` for a span below 2^32, the same number from the same
        generator state. Compiled, ``integers`` allocates a one-element array at each call
        (most of its cost); this calls the draw it makes directly (checked against it in
        ``tests/model/test_equations.py``)."""
        span = high - 1 - low
        if span <= 0:
            return low  # one possible value: integers draws nothing either
        return low + np.int64(_lemire32(rng.bit_generator, span))

else:  # pragma: no cover - exercised where numba is missing

    def draw_int(rng: np.random.Generator, low: int, high: int) -> int:
        """``rng.integers(low, high)``."""
        return int(rng.integers(low, high))

    draw_int.py_func = draw_int  # type: ignore[attr-defined]


@jit
def _axes(p: np.ndarray) -> int:
    return 3 if p[P.DIMENSIONS] > 2.5 else 2


@jit
def _step(p: np.ndarray, rng: np.random.Generator) -> float:
    reach = p[P.MOVE_RANGE]
    if reach <= 0.0:
        return 0.0
    if p[P.MOVE_INTEGER] > 0.5:
        r = int(reach)
        return float(draw_int(rng, -r, r + 1))
    return rng.uniform(-reach, reach)


@jit
def draw_moves(p: np.ndarray, moves: np.ndarray, rng: np.random.Generator) -> None:
    """alpha_1, alpha_2 (and the 3-D variant's vertical step) of every user, uniform in
    [-epsilon, epsilon]; ``moves`` (I, 3) is filled in place, user by user."""
    axes = _axes(p)
    for i in range(moves.shape[0]):
        for a in range(3):
            moves[i, a] = _step(p, rng) if a < axes else 0.0


@jit_borrow
def apply_moves(p: np.ndarray, users: np.ndarray, moves: np.ndarray) -> None:
    """x_i(t) = clip(x_i(t-1) + alpha_1, 0, R), the same for y (1)-(2); in the 3-D variant
    z stays within [0, user_max_altitude]. ``users`` (I, 3) is updated in place."""
    side = p[P.AREA]
    for i in range(users.shape[0]):
        for a in range(_axes(p)):
            top = side if a < 2 else p[P.USER_ZMAX]
            users[i, a] = min(max(users[i, a] + moves[i, a], 0.0), top)


@jit
def move_users(p: np.ndarray, users: np.ndarray, rng: np.random.Generator) -> None:
    """Draw and apply one interval's moves (1)-(2); ``users`` (I, 3) in place."""
    moves = np.empty_like(users)
    draw_moves(p, moves, rng)
    apply_moves(p, users, moves)


@jit
def draw_tasks(p: np.ndarray, tasks: np.ndarray, rng: np.random.Generator) -> None:
    """u_i(t) ~ N(mean, phi^2), rounded half up and clipped to [0, u_max]; in place."""
    top = p[P.TASK_MAX]
    for i in range(tasks.shape[0]):
        value = math.floor(rng.normal(p[P.TASK_MEAN], p[P.TASK_STD]) + 0.5)
        tasks[i] = int(min(max(value, 0.0), top))


@jit
def draw_arrivals(p: np.ndarray, arrivals: np.ndarray, rng: np.random.Generator) -> None:
    """New tasks of every user in one interval (``task_model = "backlog"``): Poisson with
    mean ``task_arrival_mean``; in place."""
    mean = p[P.ARRIVAL_MEAN]
    for i in range(arrivals.shape[0]):
        arrivals[i] = rng.poisson(mean) if mean > 0.0 else 0


@jit
def arrival_mean(p: np.ndarray, duration_s: float) -> float:
    """A user's mean new tasks in an interval of ``duration_s`` when they arrive in time
    (``task_arrival_period_s`` > 0): lambda d / period."""
    return p[P.ARRIVAL_MEAN] * duration_s / p[P.ARRIVAL_PERIOD]


@jit
def poisson_quantile(mean: float, u: float) -> int:
    """The least n with P(N <= n) > u for N ~ Poisson(mean), u in [0, 1): a Poisson draw
    from a uniform one, so that two playouts given the same uniforms draw alike whatever
    means their timings give (common random numbers)."""
    if mean <= 0.0:
        return 0
    term = math.exp(-mean)
    total = term
    n = 0
    while total <= u and n < 10_000:
        n += 1
        term *= mean / n
        total += term
    return n


@jit
def draw_timed_arrivals(p: np.ndarray, arrivals: np.ndarray, duration_s: float, rng: np.random.Generator) -> None:
    """New tasks of every user in an interval of ``duration_s`` seconds when they arrive in
    time: Poisson of mean ``arrival_mean``, drawn as ``poisson_quantile`` of a uniform (as
    the confirmation's paired playouts draw them); in place."""
    mean = arrival_mean(p, duration_s)
    for i in range(arrivals.shape[0]):
        arrivals[i] = poisson_quantile(mean, rng.random())
