"""Scenario parameters: every symbol of the paper's model, plus what the paper leaves open.

One flat frozen dataclass so that any field can be overridden by name
(``--set speed_mps=10``), read by its type (``planner_service.settings``: the same reading
as the service's configuration). Units are in the field names; each bound sits beside its
field. ``docs/MODEL.md`` has the table of every value with its source and the reason for
each decision.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any, Literal, Mapping, get_args

from ..settings import SettingError, check_fields, read_fields, setting, split_assignment
from .errors import ScenarioError

HoverLayout = Literal["original", "uniform"]
PropulsionModel = Literal["paper", "rotary-wing"]
TaskModel = Literal["redraw", "backlog"]
Dimensions = Literal[2, 3]
PROPULSION_MODELS: tuple[str, ...] = get_args(PropulsionModel)
HOVER_LAYOUTS: tuple[str, ...] = get_args(HoverLayout)
TASK_MODELS: tuple[str, ...] = get_args(TaskModel)


@dataclass(frozen=True)
class Scenario:
    """The system model of Section II with the values of Section IV.

    Paper symbols are given in brackets. Fields marked *decision* are not stated in the
    paper; ``docs/MODEL.md`` says why each value was chosen.
    """

    name: str = "paper"
    """Preset this scenario was built from (informational)."""

    # --- geometry -------------------------------------------------------------------
    num_hover_points: int = setting(20, gt=0)
    """[K] fixed hovering points."""
    num_users: int = setting(10, gt=0)
    """[I] ground users."""
    hover_layout: HoverLayout = "original"
    """``original`` (the 20 points of the authors' code, extended by a seeded draw for
    K > 20) or ``uniform`` (a grid). *decision*"""
    layout_seed: int = 2022
    """Seed of the extra ``original`` points when K > 20. *decision*"""
    dimensions: Dimensions = 2
    """2: all hovering points at ``altitude_m``; 3: Appendix B's three planes."""
    altitude_m: float = setting(100.0, gt=0)
    """[H] flight altitude of the 2-D model."""
    plane_altitudes_m: tuple[float, ...] = (25.0, 50.0, 75.0)
    """[H1, H2, H3] planes of the 3-D variant (Appendix B)."""
    area_side_m: float = setting(500.0, gt=0)
    """[R] the users' area is [0, R]^2. *decision* (authors' code)"""
    base_x_m: float = 0.0
    """UAV base position, east. *decision* (authors' code)"""
    base_y_m: float = 0.0
    """UAV base position, north. *decision* (authors' code)"""
    base_z_m: float = 100.0
    """UAV base altitude: the first interval flies from here. *decision*"""

    # --- mobility (1)-(2) ------------------------------------------------------------
    user_move_range_m: float = setting(10.0, ge=0)
    """[epsilon] each coordinate moves by a draw in [-epsilon, epsilon] per interval.
    *decision* (authors' code)"""
    user_move_integer: bool = True
    """Draw whole metres, as the authors' code does. *decision*"""
    user_max_altitude_m: float = setting(20.0, ge=0)
    """3-D variant only: users' terrain height lies in [0, this]. *decision*"""

    # --- channel ---------------------------------------------------------------------
    noise_dbm: float = -120.0
    """[sigma^2] noise power."""
    gain_ref_db: float = -50.0
    """[rho_0] channel gain at 1 m."""
    upload_power_w: float = setting(0.1, gt=0)
    """[P_u] user upload power."""
    bandwidth_hz: float = setting(1.0, gt=0)
    """Bandwidth multiplying log2(1 + SNR). The paper has none: 1 is its literal reading
    (bit/s per Hz). *decision*"""

    # --- tasks -----------------------------------------------------------------------
    bits_per_task: float = setting(100e3, gt=0)
    """[B_t] 100 Kb per task."""
    task_mean: float = setting(10.0, ge=0)
    """Mean of the Gaussian task count."""
    task_std: float = setting(5.0, ge=0)
    """[phi] standard deviation of the task count."""
    task_max: int = setting(20, gt=0)
    """[u_max] task counts are rounded and clipped to [0, u_max]. *decision* (authors' code)"""
    task_model: TaskModel = "redraw"
    """What a user's task count is from one interval to the next. ``redraw`` (the paper's):
    every interval every user draws a new count u_i(t), whatever was served before.
    ``backlog``: the count is data waiting to be offloaded. The first interval's counts are
    drawn as in ``redraw``; a service offloads the served user's whole backlog (it drops
    to 0); between intervals every user's backlog grows by a Poisson number of new tasks
    of mean ``task_arrival_mean``, capped at u_max (the user's buffer). *decision*"""
    task_arrival_mean: float = setting(1.0, ge=0)
    """[lambda] ``backlog`` only: mean new tasks per user per interval. Poisson, because a
    user's tasks are generated independently at a constant rate; 1 per interval adds, over
    a sortie of m = 10 intervals, the paper's mean count (10) on top of the first backlog.
    *decision*"""
    task_arrival_period_s: float = setting(0.0, ge=0)
    """``backlog`` only: 0, the new tasks arrive once per interval, whatever it lasted (the
    model's interval as a time slot); > 0, they arrive in time, ``task_arrival_mean`` per
    this many seconds: an interval of d seconds (its flight at ``speed_mps`` and its upload)
    brings each user Poisson(lambda d / period) new tasks, so a short interval brings fewer
    than a long one, as real users' data do. The planners' playouts then draw their futures
    afresh (the shared futures' index assumes tasks that do not depend on the path's
    timing). *decision*"""

    # --- energy (6)-(8) --------------------------------------------------------------
    hover_power_w: float = setting(1.0, ge=0)
    """[P_h] hovering power while a user uploads."""
    mass_kg: float = setting(10.0, gt=0)
    """[M] UAV mass, in (7)."""
    kappa1: float = 0.03
    """[kappa_1] propulsion constant of (8)."""
    kappa2: float = 5.0
    """[kappa_2] propulsion constant of (8)."""
    accel_mps2: float = 15.0
    """[a_uav] acceleration in (8)."""
    gravity_mps2: float = 9.8
    """[g] gravitational acceleration in (8)."""
    cycles_per_bit: float = setting(1000.0, ge=0)
    """[C] CPU cycles per input bit."""
    cpu_hz: float = setting(2e9, ge=0)
    """[f_c] CPU frequency."""
    switched_capacitance: float = setting(1e-28, ge=0)
    """[gamma_c] effective switched capacitance."""
    propulsion_model: PropulsionModel = "paper"
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
    speed_mps: float = setting(20.0, gt=0)
    """[v] cruise speed between hovering points."""

    # --- battery, fairness, reward ---------------------------------------------------
    battery_j: float = setting(1_150_000.0, gt=0)
    """[E_0] battery energy. *decision*: calibrated so a sortie at 20 m/s lasts about
    m = 10 intervals and the budget (9b) binds (see docs/MODEL.md)."""
    battery_threshold: float = setting(0.1, ge=0, lt=1)
    """[theta] service stops at this fraction of E_0 (9b)."""
    reserve_return_energy: bool = False
    """Also keep the energy to fly home above the threshold. The paper does not;
    a real aircraft must. *decision*"""
    fairness_threshold_tasks: int = setting(15, ge=0)
    """[beta] a second service only when the user's tasks exceed this (3)."""
    max_services_per_user: int = setting(2, gt=0)
    """Limit of (9c)."""
    nearest_tie_m: float = setting(1.0, ge=0)
    """Users whose distance is within this of the nearest are tied; the larger task wins
    (Fig. 2 caption). *decision*"""
    energy_norm_j: float = setting(186_000.0, gt=0)
    """[w_max] energy normaliser of the reward (11). *decision* (authors' code)"""
    task_reward_weight: float = 1.0
    """Weight of u/u_max in (11). The paper's equation has 1; the authors' code 2."""
    max_intervals: int = setting(10, ge=0)
    """Sortie length limit in intervals (0: none): an outside limit, so it truncates.
    *decision* (authors' code)"""
    allow_stay: bool = False
    """May the UAV serve from the same hovering point two intervals in a row? The paper
    flies to "any other candidate point". *decision*"""

    # --- planner ---------------------------------------------------------------------
    tree_depth: int = setting(10, gt=0)
    """[m] search-tree depth; TS-MCTS's schedule uses it."""
    uct_c: float = setting(1.0 / math.sqrt(2.0), ge=0)
    """[c] UCT exploration constant (10). *decision* (authors' code)"""

    def __post_init__(self) -> None:
        try:
            check_fields(self)
        except SettingError as err:
            raise ScenarioError(err.name, f"{err.name}: {err.message}") from None
        self.check()

    def check(self) -> None:
        """The rules that tie fields together (each field's own are beside it)."""
        if self.dimensions == 3 and not self.plane_altitudes_m:
            raise ScenarioError("plane_altitudes_m", "plane_altitudes_m: the 3-D variant needs at least one plane")
        for name in ("base_x_m", "base_y_m"):
            if not 0.0 <= getattr(self, name) <= self.area_side_m:
                raise ScenarioError(name, f"{name}: the base position must lie inside the area [0, area_side_m = "
                                          f"{self.area_side_m:g}]")

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
        """A copy with some fields changed (typed values); unknown names raise ``ScenarioError``."""
        names = {f.name for f in fields(self)}
        for key in changes:
            if key not in names:
                raise ScenarioError(key, f"unknown scenario field {key!r}")
        return dataclasses.replace(self, **changes)

    def with_overrides(self, overrides: Mapping[str, Any] | list[str]) -> "Scenario":
        """Apply ``name=value`` strings (command line) or a name -> value mapping (TOML values
        or text), each read by its field's type."""
        if isinstance(overrides, list):
            try:
                overrides = dict(split_assignment(item) for item in overrides)
            except SettingError as err:
                raise ScenarioError(err.name, f"override {err.message}") from None
        names = {f.name for f in fields(self)}
        for key in overrides:
            if key not in names:
                raise ScenarioError(key, f"unknown scenario field {key!r}")
        try:
            changes = read_fields(Scenario, overrides)
        except SettingError as err:
            raise ScenarioError(err.name.split("[")[0], f"{err.name}: {err.message}") from None
        return self.replace(**changes)


def _jsonable(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value
