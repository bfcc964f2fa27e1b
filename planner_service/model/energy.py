"""Hover, computation (6) and flight (7)-(8) energy; rotary-wing propulsion power."""

from __future__ import annotations

import math

import numpy as np

from . import params as P
from ._jit import jit_borrow


@jit_borrow
def hover_energy_j(p: np.ndarray, bits: float, rate_bps: float) -> float:
    """e_h = P_h S / R: hovering while the user uploads ``bits``."""
    return p[P.HOVER_POWER] * bits / rate_bps


@jit_borrow
def computation_energy_j(p: np.ndarray, bits: float) -> float:
    """e_c = gamma_c C S f_c^2 (6)."""
    return p[P.CAPACITANCE] * p[P.CYCLES_PER_BIT] * bits * p[P.CPU_HZ] ** 2


@jit_borrow
def rotary_wing_power_w(p: np.ndarray, speed_mps: float) -> float:
    """Level-flight power of a rotary-wing UAV (Zeng, Xu, Zhang, IEEE TWC 2019, (12)).

    Blade profile + induced + parasite power; at speed 0 it is the hover power P_0 + P_i.
    """
    v = speed_mps
    v0 = p[P.V0]
    blade = p[P.P0] * (1.0 + 3.0 * v * v / (p[P.TIP_SPEED] * p[P.TIP_SPEED]))
    induced = p[P.PI] * math.sqrt(math.sqrt(1.0 + v**4 / (4.0 * v0**4)) - v * v / (2.0 * v0 * v0))
    parasite = 0.5 * p[P.DRAG_RATIO] * p[P.AIR_DENSITY] * p[P.SOLIDITY] * p[P.DISC_AREA] * v**3
    return blade + induced + parasite


@jit_borrow
def flight_energy_j(p: np.ndarray, distance_m: float) -> float:
    """Energy to fly ``distance_m`` at the scenario's speed; nothing when not moving.

    Paper model: e_f1 = kappa v^2 with kappa = 0.5 M distance / v (7), plus the
    acceleration term e_f2 = kappa_1 v^3 + kappa_2 / v (1 + a^2 / g^2) (8) once per hop.
    Rotary-wing model: P(v) times the flight time.
    """
    if distance_m <= 0.0:
        return 0.0
    v = p[P.SPEED]
    if p[P.ROTARY] > 0.5:
        return rotary_wing_power_w(p, v) * distance_m / v
    kappa = 0.5 * p[P.MASS] * distance_m / v
    e_f1 = kappa * v * v  # (7)
    ratio = p[P.ACCEL] / p[P.GRAVITY]
    e_f2 = p[P.KAPPA1] * v**3 + p[P.KAPPA2] / v * (1.0 + ratio * ratio)  # (8)
    return e_f1 + e_f2
