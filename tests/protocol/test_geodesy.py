"""Local tangent plane <-> WGS84, against an independent textbook computation."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.errors import MissionError
from protocol.geodesy import GeoOrigin, enu_to_geodetic, geodetic_to_enu, global_to_local, local_to_global

A = 6378137.0  # WGS84 semi-major axis (m)
F = 1 / 298.257223563
E2 = F * (2 - F)


def ecef(lat_deg: float, lon_deg: float, h: float) -> tuple[float, float, float]:
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = A / math.sqrt(1 - E2 * math.sin(lat) ** 2)
    return ((n + h) * math.cos(lat) * math.cos(lon), (n + h) * math.cos(lat) * math.sin(lon),
            (n * (1 - E2) + h) * math.sin(lat))


def reference_enu(origin: GeoOrigin, lat: float, lon: float, h: float) -> tuple[float, float, float]:
    """ECEF difference rotated into east-north-up at the origin (e.g. Hofmann-Wellenhof)."""
    x0, y0, z0 = ecef(origin.lat_deg, origin.lon_deg, origin.alt_m)
    x, y, z = ecef(lat, lon, h)
    dx, dy, dz = x - x0, y - y0, z - z0
    p, l = math.radians(origin.lat_deg), math.radians(origin.lon_deg)
    east = -math.sin(l) * dx + math.cos(l) * dy
    north = -math.sin(p) * math.cos(l) * dx - math.sin(p) * math.sin(l) * dy + math.cos(p) * dz
    up = math.cos(p) * math.cos(l) * dx + math.cos(p) * math.sin(l) * dy + math.sin(p) * dz
    return east, north, up


ORIGINS = [GeoOrigin(), GeoOrigin(-33.9, 151.2, 20.0), GeoOrigin(0.0, 0.0, 0.0), GeoOrigin(64.1, -21.9, 50.0)]


@pytest.mark.parametrize("origin", ORIGINS)
def test_enu_matches_the_textbook_rotation(origin: GeoOrigin) -> None:
    for east, north, up in [(500.0, 500.0, 100.0), (-250.0, 40.0, 0.0), (3000.0, -2000.0, 120.0)]:
        lat, lon, alt = enu_to_geodetic(origin, east, north, up)
        e, n, u = reference_enu(origin, lat, lon, alt)
        assert e == pytest.approx(east, abs=1e-6)
        assert n == pytest.approx(north, abs=1e-6)
        assert u == pytest.approx(up, abs=1e-6)


def test_one_metre_north_is_one_over_the_meridian_radius() -> None:
    origin = GeoOrigin()
    phi = math.radians(origin.lat_deg)
    meridian_radius = A * (1 - E2) / (1 - E2 * math.sin(phi) ** 2) ** 1.5
    lat, lon, _ = local_to_global(origin, 0.0, 1.0, 0.0)
    # The arc runs at the origin's height above the ellipsoid: radius M + h.
    expected = 1.0 / (meridian_radius + origin.alt_m)
    assert math.radians(lat - origin.lat_deg) == pytest.approx(expected, rel=1e-6)
    assert lon == pytest.approx(origin.lon_deg, abs=1e-12)


def test_altitudes_are_heights_above_the_origin() -> None:
    origin = GeoOrigin()
    _, _, alt = local_to_global(origin, 500.0, 500.0, 100.0)
    assert alt == origin.alt_m + 100.0
    # Along the plane's normal the same point would be 4 cm higher at 700 m.
    assert enu_to_geodetic(origin, 500.0, 500.0, 100.0)[2] - alt == pytest.approx(0.039, abs=0.002)


@settings(max_examples=200, deadline=None)
@given(st.floats(-5000, 5000), st.floats(-5000, 5000), st.floats(0, 500))
def test_round_trip(x: float, y: float, z: float) -> None:
    origin = GeoOrigin()
    back = global_to_local(origin, *local_to_global(origin, x, y, z))
    assert back == pytest.approx((x, y, z), abs=1e-6)
    assert geodetic_to_enu(origin, *enu_to_geodetic(origin, x, y, z)) == pytest.approx((x, y, z), abs=1e-6)


def test_origin_validation() -> None:
    assert GeoOrigin.parse("47.1, 8.5, 400") == GeoOrigin(47.1, 8.5, 400.0)
    for text, where in [("91,0,0", "origin.lat_deg"), ("1,2", "origin"), ("a,b,c", "origin"), ("0,nan,0", "origin.lon_deg")]:
        with pytest.raises(MissionError) as err:
            GeoOrigin.parse(text)
        assert err.value.where == where
