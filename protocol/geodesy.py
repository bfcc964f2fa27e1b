"""Local tangent plane (x east, y north, z up) <-> WGS84, about a configured origin.

pymap3d does the conversion (WGS84 ellipsoid through ECEF, exact, no flat-earth
approximation): it is small, pure Python, well kept and tested against reference data,
so we do not carry our own geodesy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pymap3d

from .errors import MissionError

DEFAULT_LAT_DEG = 47.397742
DEFAULT_LON_DEG = 8.545594
DEFAULT_ALT_M = 488.0
"""PX4 SITL's default home (Zurich), so that tools showing a map put the stub somewhere real."""


@dataclass(frozen=True)
class GeoOrigin:
    """The geodetic point that is local (0, 0, 0): latitude, longitude (degrees, WGS84) and
    altitude above mean sea level (metres; the local z and MAVLink relative altitudes are
    measured from it)."""

    lat_deg: float = DEFAULT_LAT_DEG
    lon_deg: float = DEFAULT_LON_DEG
    alt_m: float = DEFAULT_ALT_M

    def __post_init__(self) -> None:
        for name, limit in (("lat_deg", 90.0), ("lon_deg", 180.0), ("alt_m", 100_000.0)):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or abs(value) > limit:
                raise MissionError(f"origin.{name}", f"{value!r} is not a valid value (|x| <= {limit})")

    @classmethod
    def parse(cls, text: str) -> "GeoOrigin":
        """From ``"lat,lon,alt"`` (command lines)."""
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 3:
            raise MissionError("origin", f"{text!r} is not 'lat,lon,alt'")
        try:
            lat, lon, alt = (float(p) for p in parts)
        except ValueError:
            raise MissionError("origin", f"{text!r} is not three numbers") from None
        return cls(lat, lon, alt)


def enu_to_geodetic(origin: GeoOrigin, x_m: float, y_m: float, z_m: float) -> tuple[float, float, float]:
    """Local (east, north, up) metres -> (latitude deg, longitude deg, altitude m AMSL)."""
    lat, lon, alt = pymap3d.enu2geodetic(x_m, y_m, z_m, origin.lat_deg, origin.lon_deg, origin.alt_m)
    return float(lat), float(lon), float(alt)


def geodetic_to_enu(origin: GeoOrigin, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
    """(latitude deg, longitude deg, altitude m AMSL) -> local (east, north, up) metres."""
    e, n, u = pymap3d.geodetic2enu(lat_deg, lon_deg, alt_m, origin.lat_deg, origin.lon_deg, origin.alt_m)
    return float(e), float(n), float(u)


def local_to_global(origin: GeoOrigin, x_m: float, y_m: float, z_m: float) -> tuple[float, float, float]:
    """Local metres -> (lat deg, lon deg, altitude m AMSL) with altitude = origin + z.

    The horizontal position comes from the tangent plane; the altitude is height above the
    origin's altitude, not distance along the plane's normal (which would add the earth's
    curvature, 4 cm at 500 m): MAVLink's relative altitudes and an aircraft's altitude hold
    are both measured that way.
    """
    lat, lon, _ = enu_to_geodetic(origin, x_m, y_m, 0.0)
    return lat, lon, origin.alt_m + z_m


def global_to_local(origin: GeoOrigin, lat_deg: float, lon_deg: float, alt_m: float) -> tuple[float, float, float]:
    """Inverse of ``local_to_global``."""
    x_m, y_m, _ = geodetic_to_enu(origin, lat_deg, lon_deg, _plane_alt(origin, lat_deg, lon_deg))
    return x_m, y_m, alt_m - origin.alt_m


def _plane_alt(origin: GeoOrigin, lat_deg: float, lon_deg: float) -> float:
    """Altitude at which the tangent plane (up = 0) passes over (lat, lon): evaluating the
    inverse there makes ``global_to_local`` the exact inverse of ``local_to_global``."""
    x_m, y_m, _ = geodetic_to_enu(origin, lat_deg, lon_deg, origin.alt_m)
    return enu_to_geodetic(origin, x_m, y_m, 0.0)[2]
