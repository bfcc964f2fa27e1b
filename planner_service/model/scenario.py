"""Scenario parameters: every symbol of the paper's model, plus what the paper leaves open.

One flat frozen dataclass so that any field can be overridden by name
(``--set speed_mps=10``). Units are in the field names. ``docs/MODEL.md`` has the table
of every value with its source and the reason for each decision.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any, Mapping

from .errors import ScenarioError

PROPULSION_MODELS = ("paper", "rotary-wing")
HOVER_LAYOUTS = ("original", "uniform")
RETURN_KINDS = ("mean", "sum")
TASK_MODELS = ("redraw", "backlog")


@dataclass(frozen=True)
class Scenario:
    """The system model of Section II with the values of Section IV.

    Paper symbols are given in brackets. Fields marked *decision* are not stated in the
    paper; ``docs/MODEL.md`` says why each value was chosen.
    """

    name: str = "paper"
    """Preset this scenario was built from (informational)."""

    # --- geometry -------------------------------------------------------------------
    num_hover_points: int = 20
    """[K] fixed hovering points."""
    num_users: int = 10
    """[I] ground users."""
    hover_layout: str = "original"
    """``original`` (the 20 points of the authors' code, extended by a seeded draw for
    K > 20) or ``uniform`` (a grid). *decision*"""
    layout_seed: int = 2022
    """Seed of the extra ``original`` points when K > 20. *decision*"""
    dimensions: int = 2
    """2: all hovering points at ``altitude_m``; 3: Appendix B's three planes."""
    altitude_m: float = 100.0
    """[H] flight altitude of the 2-D model."""
    plane_altitudes_m: tuple[float, ...] = (25.0, 50.0, 75.0)
    """[H1, H2, H3] planes of the 3-D variant (Appendix B)."""
    area_side_m: float = 500.0
    """[R] the users' area is [0, R]^2. *decision* (authors' code)"""
    base_x_m: float = 0.0
    """UAV base position, east. *decision* (authors' code)"""
    base_y_m: float = 0.0
    """UAV base position, north. *decision* (authors' code)"""
    base_z_m: float = 100.0
    """UAV base altitude: the first interval flies from here. *decision*"""

    # --- mobility (1)-(2) ------------------------------------------------------------
    user_move_range_m: float = 10.0
    """[epsilon] each coordinate moves by a draw in [-epsilon, epsilon] per interval.
    *decision* (authors' code)"""
    user_move_integer: bool = True
    """Draw whole metres, as the authors' code does. *decision*"""
    user_max_altitude_m: float = 20.0
    """3-D variant only: users' terrain height lies in [0, this]. *decision*"""

    # --- channel ---------------------------------------------------------------------
    noise_dbm: float = -120.0
    """[sigma^2] noise power."""
    gain_ref_db: float = -50.0
    """[rho_0] channel gain at 1 m."""
    upload_power_w: float = 0.1
    """[P_u] user upload power."""
    bandwidth_hz: float = 1.0
    """Bandwidth multiplying log2(1 + SNR). The paper has none: 1 is its literal reading
    (bit/s per Hz). *decision*"""

    # --- tasks -----------------------------------------------------------------------
    bits_per_task: float = 100e3
    """[B_t] 100 Kb per task."""
    task_mean: float = 10.0
    """Mean of the Gaussian task count."""
    task_std: float = 5.0
    """[phi] standard deviation of the task count."""
    task_max: int = 20
    """[u_max] task counts are rounded and clipped to [0, u_max]. *decision* (authors' code)"""
    task_model: str = "redraw"
    """What a user's task count is from one interval to the next. ``redraw`` (the paper's):
    every interval every user draws a new count u_i(t), whatever was served before.
    ``backlog``: the count is data waiting to be offloaded. The first interval's counts are
    drawn as in ``redraw``; a service offloads the served user's whole backlog (it drops
    to 0); between intervals every user's backlog grows by a Poisson number of new tasks
    of mean ``task_arrival_mean``, capped at u_max (the user's buffer). *decision*"""
    task_arrival_mean: float = 1.0
    """[lambda] ``backlog`` only: mean new tasks per user per interval. Poisson, because a
    user's tasks are generated independently at a constant rate; 1 per interval adds, over
    a sortie of m = 10 intervals, the paper's mean count (10) on top of the first backlog.
    *decision*"""

    # --- energy (6)-(8) --------------------------------------------------------------
    hover_power_w: float = 1.0
    """[P_h] hovering power while a user uploads."""
    mass_kg: float = 10.0
    """[M] UAV mass, in (7)."""
    kappa1: float = 0.03
    """[kappa_1] propulsion constant of (8)."""
    kappa2: float = 5.0
    """[kappa_2] propulsion constant of (8)."""
    accel_mps2: float = 15.0
    """[a_uav] acceleration in (8)."""
    gravity_mps2: float = 9.8
    """[g] gravitational acceleration in (8)."""
    cycles_per_bit: float = 1000.0
    """[C] CPU cycles per input bit."""
    cpu_hz: float = 2e9
    """[f_c] CPU frequency."""
    switched_capacitance: float = 1e-28
    """[gamma_c] effective switched capacitance."""
    propulsion_model: str = "paper"
    """``paper``: flight energy (7)+(8). ``rotary-wing``: Zeng, Xu, Zhang (TWC 2019)
    power P(v) times flight time, minimal at a cruise speed."""
    blade_profile_power_w: float = 79.86
    """[P_0] rotary-wing blade profile power in hover (Zeng et al., Table I)."""
    induced_power_w: float = 88.63
    """[P_i] rotary-wing induced power in hover (Zeng et al., Table I)."""
    rotor_tip_speed_mps: float = 120.0
    """[U_tip] rotor blade tip speed (Zeng et al.)."""
    rotor_induced_velocity_mps: float = 4.03
    """[v_0] mean rotor induced velocity in hover (Zeng et al.)."""
    fuselage_drag_ratio: float = 0.6
    """[d_0] fuselage drag ratio (Zeng et al.)."""
    air_density_kgpm3: float = 1.225
    """[rho] air density (Zeng et al.)."""
    rotor_solidity: float = 0.05
    """[s] rotor solidity (Zeng et al.)."""
    rotor_disc_area_m2: float = 0.503
    """[A] rotor disc area (Zeng et al.)."""
    speed_mps: float = 20.0
    """[v] cruise speed between hovering points."""

    # --- battery, fairness, reward ---------------------------------------------------
    battery_j: float = 1_150_000.0
    """[E_0] battery energy. *decision*: calibrated so a sortie at 20 m/s lasts about
    m = 10 intervals and the budget (9b) binds (see docs/MODEL.md)."""
    battery_threshold: float = 0.1
    """[theta] service stops at this fraction of E_0 (9b)."""
    reserve_return_energy: bool = False
    """Also keep the energy to fly home above the threshold. The paper does not;
    a real aircraft must. *decision*"""
    fairness_threshold_tasks: int = 15
    """[beta] a second service only when the user's tasks exceed this (3)."""
    max_services_per_user: int = 2
    """Limit of (9c)."""
    nearest_tie_m: float = 1.0
    """Users whose distance is within this of the nearest are tied; the larger task wins
    (Fig. 2 caption). *decision*"""
    energy_norm_j: float = 186_000.0
    """[w_max] energy normaliser of the reward (11). *decision* (authors' code)"""
    task_reward_weight: float = 1.0
    """Weight of u/u_max in (11). The paper's equation has 1; the authors' code 2."""
    max_intervals: int = 10
    """Sortie length limit in intervals (0: none): an outside limit, so it truncates.
    *decision* (authors' code)"""
    allow_stay: bool = False
    """May the UAV serve from the same hovering point two intervals in a row? The paper
    flies to "any other candidate point". *decision*"""

    # --- planner ---------------------------------------------------------------------
    tree_depth: int = 10
    """[m] search-tree depth; TS-MCTS's schedule uses it."""
    uct_c: float = 1.0 / math.sqrt(2.0)
    """[c] UCT exploration constant (10). *decision* (authors' code)"""

    def __post_init__(self) -> None:
        _validate(self)

    # --- derived quantities ------------------------------------------------------------
    @property
    def noise_w(self) -> float:
        """sigma^2 in watts."""
        return 10.0 ** ((self.noise_dbm - 30.0) / 10.0)

    @property
    def gain_ref(self) -> float:
        """rho_0 as a linear ratio."""
        return 10.0 ** (self.gain_ref_db / 10.0)

    @property
    def energy_floor_j(self) -> float:
        """theta * E_0: the battery level the sortie must not go below (9b)."""
        return self.battery_threshold * self.battery_j

    def as_dict(self) -> dict[str, Any]:
        """Every parameter value, JSON-ready."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in fields(self)}

    def replace(self, **changes: Any) -> "Scenario":
        """A copy with some fields changed; unknown names raise ``ScenarioError``."""
        names = {f.name for f in fields(self)}
        for key in changes:
            if key not in names:
                raise ScenarioError(key, f"unknown scenario field {key!r}")
        return dataclasses.replace(self, **changes)

    def with_overrides(self, overrides: Mapping[str, str] | list[str]) -> "Scenario":
        """Apply ``name=value`` strings (command line) or a name -> text mapping."""
        if isinstance(overrides, list):
            overrides = dict(_split_assignment(item) for item in overrides)
        by_name = {f.name: f for f in fields(self)}
        changes: dict[str, Any] = {}
        for key, text in overrides.items():
            if key not in by_name:
                raise ScenarioError(key, f"unknown scenario field {key!r}")
            changes[key] = _parse_value(key, getattr(self, key), text)
        return self.replace(**changes)


def _split_assignment(item: str) -> tuple[str, str]:
    if "=" not in item:
        raise ScenarioError(item, f"override {item!r} is not of the form name=value")
    key, _, value = item.partition("=")
    return key.strip(), value.strip()


def _parse_value(key: str, current: Any, text: Any) -> Any:
    if not isinstance(text, str):
        return text
    try:
        if isinstance(current, bool):
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError(text)
            return lowered in ("true", "1", "yes")
        if isinstance(current, int):
            return int(text)
        if isinstance(current, float):
            return float(text)
        if isinstance(current, tuple):
            return tuple(float(part) for part in text.strip("()[] ").split(",") if part.strip())
    except ValueError:
        raise ScenarioError(key, f"{key}: cannot read {text!r} as {type(current).__name__}") from None
    return text


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def _validate(s: Scenario) -> None:
    for f in fields(s):
        value = getattr(s, f.name)
        if isinstance(value, float) and not math.isfinite(value):
            raise ScenarioError(f.name, f"{f.name} must be finite, got {value}")
    positive = (
        "num_hover_points", "num_users", "altitude_m", "area_side_m", "upload_power_w",
        "bandwidth_hz", "bits_per_task", "task_max", "mass_kg", "speed_mps", "battery_j",
        "energy_norm_j", "tree_depth", "max_services_per_user",
    )
    for name in positive:
        if getattr(s, name) <= 0:
            raise ScenarioError(name, f"{name} must be positive, got {getattr(s, name)}")
    non_negative = (
        "user_move_range_m", "task_std", "hover_power_w", "cycles_per_bit", "cpu_hz",
        "switched_capacitance", "nearest_tie_m", "max_intervals", "uct_c", "task_mean",
        "user_max_altitude_m", "fairness_threshold_tasks", "task_arrival_mean",
    )
    for name in non_negative:
        if getattr(s, name) < 0:
            raise ScenarioError(name, f"{name} must not be negative, got {getattr(s, name)}")
    if not 0.0 <= s.battery_threshold < 1.0:
        raise ScenarioError("battery_threshold", "battery_threshold must lie in [0, 1)")
    if s.dimensions not in (2, 3):
        raise ScenarioError("dimensions", f"dimensions must be 2 or 3, got {s.dimensions}")
    if s.hover_layout not in HOVER_LAYOUTS:
        raise ScenarioError("hover_layout", f"hover_layout must be one of {HOVER_LAYOUTS}")
    if s.task_model not in TASK_MODELS:
        raise ScenarioError("task_model", f"task_model must be one of {TASK_MODELS}, got {s.task_model!r}")
    if s.propulsion_model not in PROPULSION_MODELS:
        raise ScenarioError("propulsion_model", f"propulsion_model must be one of {PROPULSION_MODELS}")
    if s.dimensions == 3 and not s.plane_altitudes_m:
        raise ScenarioError("plane_altitudes_m", "the 3-D variant needs at least one plane")
    inside = 0.0 <= s.base_x_m <= s.area_side_m and 0.0 <= s.base_y_m <= s.area_side_m
    if not inside:
        raise ScenarioError("base_x_m", "the base position must lie inside the area")

