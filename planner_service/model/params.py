"""The scenario as a flat float vector, the form the compiled kernels read.

Kernels cannot take a dataclass, so ``pack`` lays the numbers they need into a vector and
the index names below say where each one sits. Flags are stored as 0.0 / 1.0.
"""

from __future__ import annotations

import numpy as np

from .scenario import Scenario

SPEED = 0
ALTITUDE = 1
AREA = 2
MOVE_RANGE = 3
MOVE_INTEGER = 4
USER_ZMAX = 5
DIMENSIONS = 6
NOISE_W = 7
GAIN_REF = 8
UPLOAD_POWER = 9
BANDWIDTH = 10
BITS_PER_TASK = 11
TASK_MEAN = 12
TASK_STD = 13
TASK_MAX = 14
HOVER_POWER = 15
MASS = 16
KAPPA1 = 17
KAPPA2 = 18
ACCEL = 19
GRAVITY = 20
CYCLES_PER_BIT = 21
CPU_HZ = 22
CAPACITANCE = 23
ROTARY = 24
P0 = 25
PI = 26
TIP_SPEED = 27
V0 = 28
DRAG_RATIO = 29
AIR_DENSITY = 30
SOLIDITY = 31
DISC_AREA = 32
ENERGY_FLOOR = 33
RESERVE_RETURN = 34
BETA = 35
MAX_SERVICES = 36
TIE_M = 37
ENERGY_NORM = 38
TASK_WEIGHT = 39
ALLOW_STAY = 40
BASE_X = 41
BASE_Y = 42
BASE_Z = 43
MAX_INTERVALS = 44
TASK_MODEL = 45
ARRIVAL_MEAN = 46
ARRIVAL_PERIOD = 47
SIZE = 48

REDRAW = 0.0
"""``p[TASK_MODEL]`` of the paper's task model: every user's count is redrawn each interval."""
BACKLOG = 1.0
"""``p[TASK_MODEL]`` of the backlog model: tasks wait until served, new ones arrive."""


def pack(s: Scenario) -> np.ndarray:
    """The kernel parameter vector of scenario ``s``; shape (SIZE,), float64."""
    p = np.zeros(SIZE, dtype=np.float64)
    p[SPEED] = s.speed_mps
    p[ALTITUDE] = s.altitude_m
    p[AREA] = s.area_side_m
    p[MOVE_RANGE] = s.user_move_range_m
    p[MOVE_INTEGER] = float(s.user_move_integer)
    p[USER_ZMAX] = s.user_max_altitude_m
    p[DIMENSIONS] = s.dimensions
    p[NOISE_W] = s.noise_w
    p[GAIN_REF] = s.gain_ref
    p[UPLOAD_POWER] = s.upload_power_w
    p[BANDWIDTH] = s.bandwidth_hz
    p[BITS_PER_TASK] = s.bits_per_task
    p[TASK_MEAN] = s.task_mean
    p[TASK_STD] = s.task_std
    p[TASK_MAX] = s.task_max
    p[HOVER_POWER] = s.hover_power_w
    p[MASS] = s.mass_kg
    p[KAPPA1] = s.kappa1
    p[KAPPA2] = s.kappa2
    p[ACCEL] = s.accel_mps2
    p[GRAVITY] = s.gravity_mps2
    p[CYCLES_PER_BIT] = s.cycles_per_bit
    p[CPU_HZ] = s.cpu_hz
    p[CAPACITANCE] = s.switched_capacitance
    p[ROTARY] = float(s.propulsion_model == "rotary-wing")
    p[P0] = s.blade_profile_power_w
    p[PI] = s.induced_power_w
    p[TIP_SPEED] = s.rotor_tip_speed_mps
    p[V0] = s.rotor_induced_velocity_mps
    p[DRAG_RATIO] = s.fuselage_drag_ratio
    p[AIR_DENSITY] = s.air_density_kgpm3
    p[SOLIDITY] = s.rotor_solidity
    p[DISC_AREA] = s.rotor_disc_area_m2
    p[ENERGY_FLOOR] = s.energy_floor_j
    p[RESERVE_RETURN] = float(s.reserve_return_energy)
    p[BETA] = s.fairness_threshold_tasks
    p[MAX_SERVICES] = s.max_services_per_user
    p[TIE_M] = s.nearest_tie_m
    p[ENERGY_NORM] = s.energy_norm_j
    p[TASK_WEIGHT] = s.task_reward_weight
    p[ALLOW_STAY] = float(s.allow_stay)
    p[BASE_X] = s.base_x_m
    p[BASE_Y] = s.base_y_m
    p[BASE_Z] = s.base_z_m
    p[MAX_INTERVALS] = s.max_intervals
    p[TASK_MODEL] = BACKLOG if s.task_model == "backlog" else REDRAW
    p[ARRIVAL_MEAN] = s.task_arrival_mean
    p[ARRIVAL_PERIOD] = s.task_arrival_period_s
    return p
