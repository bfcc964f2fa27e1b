"""Distance (4), free-space channel gain (5) and the upload rate."""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import jit_borrow


@jit_borrow
def distance_sq_m2(a: np.ndarray, b: np.ndarray) -> float:
    """Squared Euclidean distance of two (3,) points."""
    dx = a[0] - b[0]
    dy = a[1] - b[1]
    dz = a[2] - b[2]
    return dx * dx + dy * dy + dz * dz


@jit_borrow
def channel_gain(p: np.ndarray, hover_xyz: np.ndarray, user_xyz: np.ndarray) -> float:
    """g = rho_0 / d^2 with d^2 = H^2 + ||D - U||^2 (4)-(5).

    Points are 3-D, so the 2-D model's H^2 is the altitude difference; in the 3-D variant
    the same formula uses the real altitude difference. Closer than the 1 m reference
    distance the gain is held at rho_0.
    """
    d2 = distance_sq_m2(hover_xyz, user_xyz)  # (4)
    return p[P.GAIN_REF] / max(d2, 1.0)  # (5)


@jit_borrow
def upload_rate_bps(p: np.ndarray, gain: float) -> float:
    """R = B log2(1 + P_u g / sigma^2); B = 1 is the paper's literal rate."""
    return p[P.BANDWIDTH] * math.log2(1.0 + p[P.UPLOAD_POWER] * gain / p[P.NOISE_W])
