"""The fleet picture as GeoJSON (RFC 7946), for other tools (QGIS, a GIS layer, a ground
station that reads it): vehicles as points, their trails and plans as lines, users as
points, every property of the snapshot kept. Pure: a snapshot in, a FeatureCollection out.

GeoJSON speaks WGS84 longitude and latitude, so the picture's frame must be tied to the
earth: its origin (the members' announced origin, or ``operator web --origin``). Without one
there is nothing honest to write, and ``NoOrigin`` says so.
"""

from __future__ import annotations

from typing import Any

from protocol import GeoOrigin, local_to_global


class NoOrigin(ValueError):
    """The picture's frame has no geodetic origin: nothing to place on the earth."""


def feature_collection(snapshot: dict[str, Any]) -> dict[str, Any]:
    """The snapshot's vehicles, trails, plans and users as a FeatureCollection (altitudes in
    metres above mean sea level, as RFC 7946's third coordinate)."""
    frame = snapshot["frame"]["origin"]
    if frame is None:
        raise NoOrigin("the picture has no origin: no fleet member announced one; give --origin LAT,LON[,ALT]")
    origin = GeoOrigin(frame["lat_deg"], frame["lon_deg"], frame["alt_m"])

    def at(x: float, y: float, z: float = 0.0) -> list[float]:
        lat, lon, alt = local_to_global(origin, x, y, z)
        return [round(lon, 8), round(lat, 8), round(alt, 2)]

    features: list[dict[str, Any]] = []
    for v in snapshot["vehicles"]:
        props = {k: val for k, val in v.items() if k not in ("trail", "plan", "events")}
        if v["x_m"] is not None:
            features.append(_feature("Point", at(v["x_m"], v["y_m"], v["z_m"]), kind="vehicle", **props))
        if len(v["trail"]) >= 2:
            features.append(_feature("LineString", [at(x, y) for x, y in v["trail"]], kind="trail", vehicle=v["id"]))
        plan = v["plan"]
        if plan is not None and plan["points"]:
            points = [at(p["x_m"], p["y_m"], p["z_m"]) for p in plan["points"]]
            features.append(_feature("LineString", points if len(points) > 1 else points * 2, kind="plan",
                                     vehicle=v["id"], plan_id=plan["plan_id"], next=plan["next"], eta_s=plan["eta_s"],
                                     users=[p["user_id"] for p in plan["points"]]))
    for u in snapshot["users"]:
        if u["x_m"] is not None:
            features.append(_feature("Point", at(u["x_m"], u["y_m"]), kind="user", **u))
    return {"type": "FeatureCollection", "features": features,
            "properties": {"prefix": snapshot["prefix"], "time_s": snapshot["time_s"],
                           "separation": snapshot["separation"], "alerts": snapshot["alerts"]}}


def _feature(geometry: str, coordinates: Any, **properties: Any) -> dict[str, Any]:
    return {"type": "Feature", "geometry": {"type": geometry, "coordinates": coordinates}, "properties": properties}
