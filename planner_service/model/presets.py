"""Named scenarios. Presets are constructors, not copied dictionaries."""

from __future__ import annotations

from typing import Callable, Literal, get_args

from .errors import ScenarioError
from .scenario import Scenario


def paper() -> Scenario:
    """The literal model of Section IV (rate without bandwidth), the authors' geometry.

    E_0 is calibrated so that a sortie at 20 m/s lasts about m = 10 intervals and the
    energy budget (9b) binds (docs/MODEL.md, "Battery calibration").
    """
    return Scenario(name="paper")


def paper_3d() -> Scenario:
    """Appendix B: 27 hovering points on planes at 25, 50 and 75 m; users move in 3-D."""
    return Scenario(name="paper-3d", dimensions=3, num_hover_points=27, base_z_m=50.0)


def field() -> Scenario:
    """A physically plausible sortie for a real small multirotor.

    - 2 kHz per-user uplink: a 10-task (1 Mbit) upload takes about 30 s of hovering, the
      scale of a real hover-and-collect, instead of the literal model's 17 hours.
    - Zeng, Xu, Zhang (IEEE TWC 2019) rotary-wing power with their Table I aircraft
      (weight 20 N): hover 168.5 W, and the energy per metre is least near 18 m/s.
    - A 100 kJ (27.8 Wh) battery, the return flight kept in reserve, no interval limit:
      the battery and the fairness rule end the sortie.
    """
    return Scenario(
        name="field",
        bandwidth_hz=2000.0,
        propulsion_model="rotary-wing",
        hover_power_w=79.86 + 88.63,  # P_0 + P_i: rotary-wing power at speed 0
        mass_kg=20.0 / 9.8,
        battery_j=100_000.0,
        reserve_return_energy=True,
        energy_norm_j=22_000.0,
        max_intervals=0,
    )


def fleet() -> Scenario:
    """``field`` with users ample for a fleet of up to five (docs/MODEL.md, "Fleet preset"):
    60 users in the two rows (30 a row, 16.7 m apart) and 40 hovering points (the authors' 20
    and 20 seeded draws) on the same 500 m area. A field UAV flies about 8-9 intervals, so 5
    ask about 45 services: fewer than the 60 users' first services, and the 40 points leave
    at least 32 to a UAV when the 4 others each claim 2 (held and next)."""
    return field().replace(name="fleet", num_users=60, num_hover_points=40)


Preset = Literal["paper", "paper-3d", "field", "fleet"]
PRESETS: dict[str, Callable[[], Scenario]] = {
    "paper": paper,
    "paper-3d": paper_3d,
    "field": field,
    "fleet": fleet,
}
if set(PRESETS) != set(get_args(Preset)):  # pragma: no cover - a preset added to one and not the other
    raise ImportError("model.presets: PRESETS and Preset must name the same presets")


def preset(name: str) -> Scenario:
    """The scenario named ``name``; ``ScenarioError`` lists the names otherwise."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise ScenarioError("preset", f"unknown preset {name!r}; choose from {sorted(PRESETS)}") from None
