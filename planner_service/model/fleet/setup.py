"""What differs between the UAVs of a fleet: a frozen record and each UAV's own scenario."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ScenarioError
from ..scenario import Scenario
from ...settings import SettingError, check_fields, setting


@dataclass(frozen=True)
class Fleet:
    """The fleet's own parameters; the rest is the shared ``Scenario``.

    UAV j flies the scenario with its altitude (every hovering point's and its base's) raised
    by ``j * layer_m``, its base moved ``j * base_step_m`` east, and its own speed and battery
    when ``speeds_mps`` / ``batteries_j`` give them (empty: the scenario's for every UAV).
    UAV 0 flies the scenario unchanged, so a fleet of one is today's model.
    """

    uavs: int = setting(1, gt=0, le=64)
    """[N] UAVs over the same users (64: past the 20 the scale bench flies; a bound, so a typo
    does not start a thousand searches)."""
    layer_m: float = setting(10.0, ge=0)
    """Vertical spacing of the UAVs' altitude layers: transits at different heights cannot
    collide. A higher layer hears its users less well (docs/MODEL.md, "A fleet"). *decision*"""
    base_step_m: float = setting(0.0, ge=0)
    """UAV j's base lies this many metres east of UAV j-1's (0: one ground station for all).
    *decision*"""
    speeds_mps: tuple[float, ...] = ()
    """Each UAV's cruise speed; empty: the scenario's ``speed_mps`` for all."""
    batteries_j: tuple[float, ...] = ()
    """Each UAV's battery E_0; empty: the scenario's ``battery_j`` for all."""

    def __post_init__(self) -> None:
        try:
            check_fields(self)
        except SettingError as err:
            raise ScenarioError(err.name, f"{err.name}: {err.message}") from None
        for name in ("speeds_mps", "batteries_j"):
            values = getattr(self, name)
            if values and len(values) != self.uavs:
                raise ScenarioError(name, f"{name}: {len(values)} values for {self.uavs} UAVs (give one per UAV, "
                                          "or none)")
            if any(not v > 0 for v in values):
                raise ScenarioError(name, f"{name}: every value must be positive, got {list(values)}")


def uav_scenarios(scenario: Scenario, fleet: Fleet) -> list[Scenario]:
    """Each UAV's own scenario (``Fleet``'s docstring); UAV 0's is ``scenario`` itself."""
    out = []
    for j in range(fleet.uavs):
        rise, east = j * fleet.layer_m, j * fleet.base_step_m
        changes: dict = {}
        if rise:
            changes.update(altitude_m=scenario.altitude_m + rise, base_z_m=scenario.base_z_m + rise,
                           plane_altitudes_m=tuple(h + rise for h in scenario.plane_altitudes_m))
        if east:
            if scenario.base_x_m + east > scenario.area_side_m:
                raise ScenarioError("base_step_m", f"base_step_m: UAV {j}'s base ({scenario.base_x_m + east:g} m east) "
                                                   f"lies outside the area (area_side_m = {scenario.area_side_m:g})")
            changes["base_x_m"] = scenario.base_x_m + east
        if fleet.speeds_mps:
            changes["speed_mps"] = float(fleet.speeds_mps[j])
        if fleet.batteries_j:
            changes["battery_j"] = float(fleet.batteries_j[j])
        out.append(scenario.replace(**changes) if changes else scenario)
    return out
