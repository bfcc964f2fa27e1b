"""The vehicle as the sortie logic sees it, from the link's telemetry. Pure (given the
clock's readings), and the only place that turns the autopilot's numbers into the service's:

- **Position**: local metres from the configured origin, and only when the autopilot has a
  position (``Telemetry.position_ok``) that lies near the served area: a fix kilometres
  away (a wrong origin, a GPS glitch) is flagged, never planned on nor published.
- **Battery**: the autopilot's reading (energy consumed, or the remaining fraction). An
  unknown or impossible reading is unknown, never full: the last good reading is carried on
  less what the model says the vehicle spends since (the most power-hungry of hovering and
  cruising, in vehicle time), and said to come from the model; with no good reading ever,
  unknown. An autopilot restarted in the air counts its battery from its boot again (energy
  consumed from 0, often the remaining charge from full): until it lands, a reading is
  believed only up to what was known before the restart, less the model's spend since.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from protocol import Area, GeoOrigin, global_to_local

from ..model import Scenario, pack
from ..model.energy import flight_energy_j
from .link import Telemetry
from .sortie import VehicleSnapshot

FAR_OUTSIDE_M = 1000.0
"""A position this far outside the served area is not believed (never planned on)."""


@dataclass
class VehicleView:
    scenario: Scenario
    origin: GeoOrigin
    area: Area
    _good: tuple[float, float] | None = None
    """(fraction, monotonic time) of the last good battery reading."""
    _ceiling: tuple[float, float] | None = None
    """Since a restart in the air: (fraction, monotonic time) known before it."""
    _boot_s: float = -math.inf
    _power_w: float = field(init=False)
    _local: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    """The last position reported and its local metres: the view is asked at every input
    and tick (20 Hz and more), a new position comes a few times a second, and a conversion
    costs 3 geodetic ones (the largest share of a fleet member's CPU after the others')."""

    def __post_init__(self) -> None:
        s = self.scenario
        self._power_w = max(s.hover_power_w, flight_energy_j(pack(s), s.speed_mps))  # J in 1 s of cruise

    def see(self, t: Telemetry, now: float) -> tuple[VehicleSnapshot, str]:
        """The vehicle, and what its position waits for ('' when it is believed)."""
        xyz = (0.0, 0.0, 0.0)
        position_ok, waiting = t.position_ok, t.waiting_for
        if position_ok:
            xyz = self._to_local(t.lat_deg, t.lon_deg, t.rel_alt_m)
            out = self._outside_m(xyz)
            if out > FAR_OUTSIDE_M:
                position_ok = False
                waiting = (f"a position inside the area: the autopilot reports one {out / 1000:.1f} km outside it "
                           f"(check [origin] against the autopilot's home)")
        boot = t.position_boot_s if t.position_boot_s is not None else math.nan
        fraction, source = self._battery(t, now)
        return VehicleSnapshot(connected=t.connected, position_ok=position_ok, xyz=xyz if position_ok else (0.0, 0.0, 0.0),
                       boot_s=boot, armed=t.armed, airborne=t.airborne, landed_known=t.landed_known, mode=t.mode,
                       seq=t.mission_seq, mission_total=t.mission_total, mission_id=t.mission_id,
                       battery_fraction=fraction,
                       battery_source=source,
                       time_rate=t.time_rate), waiting

    def _to_local(self, lat_deg: float, lon_deg: float, rel_alt_m: float) -> tuple[float, float, float]:
        key = (lat_deg, lon_deg, rel_alt_m)
        if self._local is None or self._local[0] != key:
            self._local = (key, global_to_local(self.origin, lat_deg, lon_deg, self.origin.alt_m + rel_alt_m))
        return self._local[1]

    def _outside_m(self, xyz: tuple[float, float, float]) -> float:
        side = self.area.side_m
        dx = max(-xyz[0], 0.0, xyz[0] - side)
        dy = max(-xyz[1], 0.0, xyz[1] - side)
        return math.hypot(dx, dy)

    def _battery(self, t: Telemetry, now: float) -> tuple[float | None, str]:
        self._note_restart(t, now)
        if t.energy_used_j is not None:
            fraction: float | None = max(1.0 - t.energy_used_j / self.scenario.battery_j, 0.0)
        else:
            fraction = t.battery_fraction
        if fraction is not None and self._ceiling is not None:
            ceiling = self._carried(self._ceiling, t, now)
            if ceiling is None:
                return None, "unknown"
            if fraction > ceiling:
                return ceiling, "model"
        if fraction is not None:
            self._good = (fraction, t.battery_at or now)
            return fraction, "autopilot"
        carried = None if self._good is None else self._carried(self._good, t, now)
        return (None, "unknown") if carried is None else (carried, "model")

    def _carried(self, known: tuple[float, float], t: Telemetry, now: float) -> float | None:
        """A fraction known at a time, less what the model says was spent since; None while
        the vehicle's clock rate is unknown (what was spent since could be anything)."""
        fraction, at = known
        if t.time_rate is None:
            return None
        spent_j = self._power_w * t.time_rate * max(now - at, 0.0)
        return max(fraction - spent_j / self.scenario.battery_j, 0.0)

    def _note_restart(self, t: Telemetry, now: float) -> None:
        boot = t.boot_s if t.boot_s is not None else -math.inf
        restarted = boot < self._boot_s - 5.0
        self._boot_s = boot
        if restarted and t.airborne and self._good is not None:
            self._ceiling = self._good  # carried on from when it was read, as it is looked at
        elif self._ceiling is not None and t.landed_known and not t.airborne and not t.armed:
            self._ceiling = None  # on the ground: a swapped battery reads as itself again
