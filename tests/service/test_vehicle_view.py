"""The vehicle as the sortie logic sees it: an unknown battery is never full, a restarted
autopilot's battery is not believed above what was known, a fix far outside the area is
not a position."""

from __future__ import annotations

from dataclasses import replace

from planner_service.model import preset
from planner_service.service.link import Telemetry
from planner_service.service.vehicle_view import VehicleView
from protocol import Area, GeoOrigin, local_to_global

ORIGIN = GeoOrigin()
FLYING = Telemetry(connected=True, position_ok=True, lat_deg=ORIGIN.lat_deg, lon_deg=ORIGIN.lon_deg, rel_alt_m=50.0,
                   armed=True, airborne=True, landed_known=True, mode="AUTO", boot_s=100.0, battery_at=1.0,
                   battery_fraction=0.6, waiting_for="", time_rate=1.0)


def view() -> VehicleView:
    return VehicleView(preset("field"), ORIGIN, Area(500.0, 120.0, 10.0))


def test_a_battery_is_not_carried_on_while_the_vehicles_clock_rate_is_unknown() -> None:
    v = view()
    v.see(FLYING, 1.0)
    later, _ = v.see(replace(FLYING, battery_fraction=None, time_rate=None), 2.0)
    assert later.battery_fraction is None and later.battery_source == "unknown"


def test_an_unknown_battery_is_carried_on_by_the_model_then_unknown() -> None:
    v = view()
    assert v.see(replace(FLYING, battery_fraction=None), 1.0)[0].battery_fraction is None  # never known
    v.see(FLYING, 1.0)
    later, _ = v.see(replace(FLYING, battery_fraction=None), 11.0)
    assert later.battery_source == "model" and later.battery_fraction < 0.6


def test_a_restarted_autopilots_full_battery_is_not_believed_in_the_air() -> None:
    v = view()
    v.see(FLYING, 1.0)
    after, _ = v.see(replace(FLYING, boot_s=2.0, battery_fraction=1.0, energy_used_j=0.0), 2.0)
    assert after.battery_source == "model" and after.battery_fraction <= 0.6
    landed = replace(FLYING, boot_s=3.0, battery_fraction=1.0, energy_used_j=None, airborne=False, armed=False)
    v.see(landed, 3.0)
    swapped, _ = v.see(landed, 4.0)
    assert swapped.battery_fraction == 1.0 and swapped.battery_source == "autopilot"


def test_a_fix_far_outside_the_area_is_not_a_position() -> None:
    lat, lon, _ = local_to_global(ORIGIN, 250.0, 250.0, 50.0)
    inside, waiting = view().see(replace(FLYING, lat_deg=lat, lon_deg=lon), 1.0)
    assert inside.position_ok and not waiting
    lat, lon, _ = local_to_global(ORIGIN, 5000.0, 250.0, 50.0)
    far, waiting = view().see(replace(FLYING, lat_deg=lat, lon_deg=lon), 1.0)
    assert not far.position_ok and far.xyz == (0.0, 0.0, 0.0) and "4.5 km outside" in waiting
