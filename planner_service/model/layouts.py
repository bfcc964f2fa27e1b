"""Where the users start and where the UAV may hover.

Positions are (N, 3) float64 arrays in local metres (x east, y north, z up).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import ScenarioError
from .scenario import Scenario

ORIGINAL_HOVER_POINTS_XY = (
    (20, 20), (30, 120), (50, 250), (70, 355), (80, 220), (120, 140), (150, 300),
    (200, 200), (220, 300), (250, 150), (280, 70), (330, 200), (350, 30), (380, 180),
    (400, 400), (200, 450), (450, 60), (470, 160), (475, 300), (490, 400),
)
"""The 20 hovering points of the authors' public code, on the 500 m area."""


def user_rows(num_users: int, area_side_m: float) -> np.ndarray:
    """Users in "two neat rows" with equal spacing (Section IV).

    Rows at 0.4 R and 0.8 R north; each row's users are spaced R / n apart, starting half a
    space in. For I = 10 and R = 500 this is the authors' layout: x = 50..450 at y = 200
    and y = 400. An odd user goes to the first row.
    """
    first = (num_users + 1) // 2
    rows = ((first, 0.4), (num_users - first, 0.8))
    points = []
    for count, frac in rows:
        for j in range(count):
            points.append(((j + 0.5) * area_side_m / count, frac * area_side_m, 0.0))
    return np.array(points, dtype=np.float64).reshape(num_users, 3)


def _grid(count: int, area_side_m: float) -> np.ndarray:
    """``count`` points on the most nearly square grid with cell-centred points."""
    cols = math.ceil(math.sqrt(count))
    while count % cols:
        cols += 1
    rows = count // cols
    xs = (np.arange(cols) + 0.5) * area_side_m / cols
    ys = (np.arange(rows) + 0.5) * area_side_m / rows
    gx, gy = np.meshgrid(xs, ys)
    return np.column_stack([gx.ravel(), gy.ravel()])


def _original_xy(count: int, area_side_m: float, seed: int) -> np.ndarray:
    """The authors' 20 points (scaled to the area), then seeded uniform draws for more."""
    base = np.array(ORIGINAL_HOVER_POINTS_XY, dtype=np.float64) * (area_side_m / 500.0)
    if count <= len(base):
        return base[:count]
    extra = np.random.default_rng(seed).uniform(0.0, area_side_m, size=(count - len(base), 2))
    return np.vstack([base, np.round(extra)])


def hover_points(s: Scenario) -> np.ndarray:
    """The K fixed hovering points of scenario ``s``; (K, 3).

    2-D: every point at ``altitude_m``. 3-D (Appendix B): K / planes points on a grid on
    each plane of ``plane_altitudes_m`` (27 points = 3 planes of 3 x 3).
    """
    k = s.num_hover_points
    if s.dimensions == 3:
        planes = s.plane_altitudes_m
        if k % len(planes):
            raise ScenarioError(
                "num_hover_points", f"3-D: {k} hovering points do not split over {len(planes)} planes"
            )
        per_plane = _grid(k // len(planes), s.area_side_m)
        stacks = [np.column_stack([per_plane, np.full(len(per_plane), h)]) for h in planes]
        return np.vstack(stacks).astype(np.float64)
    if s.hover_layout == "uniform":
        xy = _grid(k, s.area_side_m)
    else:
        xy = _original_xy(k, s.area_side_m, s.layout_seed)
    return np.column_stack([xy, np.full(k, s.altitude_m)]).astype(np.float64)


def base_position(s: Scenario) -> np.ndarray:
    """Where the UAV starts and returns to; (3,)."""
    return np.array([s.base_x_m, s.base_y_m, s.base_z_m], dtype=np.float64)
