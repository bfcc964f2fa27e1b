"""A planned path in local metres <-> MAVLink mission items (MISSION_ITEM_INT), and back.

A plan becomes: [home placeholder (ArduPilot only)], a takeoff to the first point's
altitude, one ``MAV_CMD_NAV_WAYPOINT`` per hovering point with param1 = hold time, and a
final ``MAV_CMD_NAV_RETURN_TO_LAUNCH``: the mission is complete and safe on its own, so a
lost link never leaves the aircraft without a way home.

ArduPilot keeps its home position in item 0 and overwrites whatever is uploaded there;
PX4 has no such item. ``flavour`` selects the convention.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any, Iterable, Literal, Sequence

from pymavlink.dialects.v20 import common as mavlink

from .area import Area
from .errors import MissionError
from .geodesy import GeoOrigin, global_to_local, local_to_global

Flavour = Literal["ardupilot", "px4"]
FLAVOURS: tuple[str, ...] = ("ardupilot", "px4")

MAX_MISSION_ITEMS = 512
MAX_HOLD_S = 3600.0
E7 = 1e7
XY_TOLERANCE_M = 0.5
"""Slack on the area test: 1e-7 degree rounding moves a point by about a centimetre."""
MAX_LOCAL_M = 1e6
"""No local coordinate lies farther than this from the origin: the tangent plane means
nothing beyond, a float32 altitude overflows, and the geodesy returns NaN."""

NAV_WAYPOINT = mavlink.MAV_CMD_NAV_WAYPOINT
NAV_TAKEOFF = mavlink.MAV_CMD_NAV_TAKEOFF
NAV_LAND = mavlink.MAV_CMD_NAV_LAND
NAV_RTL = mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
DO_CHANGE_SPEED = mavlink.MAV_CMD_DO_CHANGE_SPEED
SUPPORTED_COMMANDS = frozenset({NAV_WAYPOINT, NAV_TAKEOFF, NAV_LAND, NAV_RTL, DO_CHANGE_SPEED})
NAV_POSITION_COMMANDS = frozenset({NAV_WAYPOINT, NAV_TAKEOFF, NAV_LAND})

FRAME_GLOBAL = mavlink.MAV_FRAME_GLOBAL
FRAME_GLOBAL_INT = mavlink.MAV_FRAME_GLOBAL_INT
FRAME_RELATIVE = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
FRAME_RELATIVE_INT = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
FRAME_MISSION = mavlink.MAV_FRAME_MISSION
GLOBAL_FRAMES = frozenset({FRAME_GLOBAL, FRAME_GLOBAL_INT, FRAME_RELATIVE, FRAME_RELATIVE_INT})
RELATIVE_FRAMES = frozenset({FRAME_RELATIVE, FRAME_RELATIVE_INT})
SUPPORTED_FRAMES = GLOBAL_FRAMES | {FRAME_MISSION}


@dataclass(frozen=True)
class MissionItem:
    """The fields of MISSION_ITEM_INT (x, y: degrees * 1e7 in global frames)."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    mission_type: int = mavlink.MAV_MISSION_TYPE_MISSION

    def to_message(self, target_system: int, target_component: int) -> Any:
        """The MISSION_ITEM_INT message for this item."""
        return mavlink.MAVLink_mission_item_int_message(
            target_system, target_component, self.seq, self.frame, self.command, self.current,
            self.autocontinue, self.param1, self.param2, self.param3, self.param4, self.x,
            self.y, self.z, self.mission_type,
        )

    def to_legacy_message(self, target_system: int, target_component: int) -> Any:
        """The legacy MISSION_ITEM (float degrees), answering a legacy MISSION_REQUEST."""
        scale = E7 if self.frame in GLOBAL_FRAMES else 1.0
        return mavlink.MAVLink_mission_item_message(
            target_system, target_component, self.seq, self.frame, self.command, self.current,
            self.autocontinue, self.param1, self.param2, self.param3, self.param4,
            self.x / scale, self.y / scale, self.z, self.mission_type,
        )

    @classmethod
    def from_message(cls, msg: Any) -> "MissionItem":
        """From a MISSION_ITEM_INT or a legacy MISSION_ITEM message."""
        x, y = msg.x, msg.y
        if msg.get_type() == "MISSION_ITEM":
            scale = E7 if msg.frame in GLOBAL_FRAMES else 1.0
            x, y = _to_int(x * scale, "x"), _to_int(y * scale, "y")
        return cls(
            seq=int(msg.seq), frame=int(msg.frame), command=int(msg.command),
            current=int(msg.current), autocontinue=int(msg.autocontinue),
            param1=float(msg.param1), param2=float(msg.param2), param3=float(msg.param3),
            param4=float(msg.param4), x=int(x), y=int(y), z=float(msg.z),
            mission_type=int(getattr(msg, "mission_type", 0)),
        )

    def same_as(self, other: "MissionItem") -> bool:
        """Field-wise equality with NaN equal to NaN (NaN yaw means "keep heading")."""
        return all(_same(getattr(self, f), getattr(other, f)) for f in _FIELDS)


_FIELDS = tuple(MissionItem.__dataclass_fields__)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def f32(value: float) -> float:
    """``value`` as MAVLink carries it (float32), so that items compare equal after a trip
    over the wire."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _to_int(value: float, where: str) -> int:
    if not math.isfinite(value):
        raise MissionError(where, f"{value} is not a finite coordinate")
    return int(round(value))


def same_items(a: Sequence[MissionItem], b: Sequence[MissionItem]) -> bool:
    """Two missions hold the same items (NaN equal to NaN)."""
    return len(a) == len(b) and all(x.same_as(y) for x, y in zip(a, b))


def mission_digest(items: Sequence[MissionItem], flavour: Flavour = "ardupilot") -> str:
    """A short fingerprint (CRC-32, 8 hex digits) of what a mission flies: each item's
    command, frame, parameters and position as MAVLink carries them (float32), in order.
    ``current`` is left out (it marks where to start, not what to fly), and so is
    ArduPilot's item 0, which the autopilot replaces with home. The vehicle stub logs it
    for every mission it commits, so a test can tell which upload the vehicle holds."""
    _check_flavour(flavour)
    start = 1 if flavour == "ardupilot" and items else 0
    crc = 0
    for item in items[start:]:
        params = (item.param1, item.param2, item.param3, item.param4, item.z)
        crc = zlib.crc32(struct.pack("<3H5f2i", item.command, item.frame, item.autocontinue,
                                     *(math.nan if math.isnan(v) else f32(v) for v in params),
                                     item.x, item.y), crc)
    return f"{crc:08x}"


def same_mission(a: Sequence[MissionItem], b: Sequence[MissionItem], flavour: Flavour = "ardupilot") -> bool:
    """``a`` and ``b`` fly the same (a mission read back from the vehicle against the one
    uploaded: ArduPilot's item 0 and ``current`` aside, float32 values as on the wire)."""
    return len(a) == len(b) and mission_digest(a, flavour) == mission_digest(b, flavour)


@dataclass(frozen=True)
class HoverPoint:
    """A point of the planned path in local metres and how long to hold there."""

    x_m: float
    y_m: float
    z_m: float
    hold_s: float = 0.0


@dataclass(frozen=True)
class MissionPlan:
    """What ``decode_path`` recovers: the hovering points and how the mission ends."""

    points: list[HoverPoint] = field(default_factory=list)
    ends_with_rtl: bool = False
    takeoff_alt_m: float | None = None


def _check_flavour(flavour: str) -> None:
    if flavour not in FLAVOURS:
        raise MissionError("flavour", f"{flavour!r} is not one of {FLAVOURS}")


def home_item(origin: GeoOrigin) -> MissionItem:
    """ArduPilot's item 0: home, in absolute altitude."""
    return MissionItem(
        seq=0, frame=FRAME_GLOBAL, command=NAV_WAYPOINT, x=_to_int(origin.lat_deg * E7, "home.x"),
        y=_to_int(origin.lon_deg * E7, "home.y"), z=f32(origin.alt_m),
    )


def encode_path(
    points: Iterable[HoverPoint],
    origin: GeoOrigin,
    flavour: Flavour = "ardupilot",
    *,
    takeoff: bool = True,
    acceptance_radius_m: float = 0.0,
) -> list[MissionItem]:
    """Hovering points -> mission items, ending in return to launch.

    The takeoff item climbs over home to the first point's altitude; a vehicle already in
    the air completes it at once, so a re-planned mission may keep it.
    """
    _check_flavour(flavour)
    points = list(points)
    for i, point in enumerate(points):
        _check_point(f"points[{i}]", point)
    items: list[MissionItem] = []
    if flavour == "ardupilot":
        items.append(home_item(origin))
    if takeoff and points:
        items.append(MissionItem(
            seq=len(items), frame=FRAME_RELATIVE_INT, command=NAV_TAKEOFF, param4=math.nan,
            x=_to_int(origin.lat_deg * E7, "takeoff.x"), y=_to_int(origin.lon_deg * E7, "takeoff.y"),
            z=f32(points[0].z_m),
        ))
    for i, point in enumerate(points):
        where = f"points[{i}]"
        lat, lon, _ = local_to_global(origin, point.x_m, point.y_m, point.z_m)
        items.append(MissionItem(
            seq=len(items), frame=FRAME_RELATIVE_INT, command=NAV_WAYPOINT,
            param1=f32(point.hold_s), param2=f32(acceptance_radius_m), param4=math.nan,
            x=_to_int(lat * E7, f"{where}.x_m"), y=_to_int(lon * E7, f"{where}.y_m"),
            z=f32(point.z_m),
        ))
    items.append(MissionItem(seq=len(items), frame=FRAME_MISSION, command=NAV_RTL))
    # Exactly one item is marked current, the first, as QGroundControl writes missions
    # (MAVSDK refuses an upload with none: CURRENT_INVALID).
    items[0] = MissionItem(**{**items[0].__dict__, "current": 1})
    return items


def max_points(max_items: int, flavour: Flavour = "ardupilot") -> int:
    """The most hovering points ``encode_path`` fits in ``max_items`` mission items: the
    items around them are ArduPilot's home, the takeoff and the return to launch."""
    _check_flavour(flavour)
    around = 3 if flavour == "ardupilot" else 2
    return max(max_items - around, 0)


def _check_point(where: str, point: HoverPoint) -> None:
    """Refuse what cannot be encoded at all (the area and altitude limits are
    ``validate_mission``'s): non-finite values, a hold out of range, a point beyond
    ``MAX_LOCAL_M``. Done for every point before any item is built: the takeoff item takes
    the first point's altitude."""
    for name in ("x_m", "y_m", "z_m", "hold_s"):
        if not math.isfinite(getattr(point, name)):
            raise MissionError(f"{where}.{name}", "must be finite")
    if not 0.0 <= point.hold_s <= MAX_HOLD_S:
        raise MissionError(f"{where}.hold_s", f"{point.hold_s} s is outside [0, {MAX_HOLD_S}]")
    for name in ("x_m", "y_m", "z_m"):
        if abs(getattr(point, name)) > MAX_LOCAL_M:
            raise MissionError(f"{where}.{name}", f"{getattr(point, name)} m lies over {MAX_LOCAL_M:g} m from the origin")


def item_local(item: MissionItem, origin: GeoOrigin) -> tuple[float, float, float]:
    """An item's position in local metres (z above the origin's altitude)."""
    if item.frame not in GLOBAL_FRAMES:
        raise MissionError(f"items[{item.seq}].frame", f"frame {item.frame} has no global position")
    x_m, y_m, z_rel = global_to_local(origin, item.x / E7, item.y / E7, origin.alt_m + item.z)
    if item.frame not in RELATIVE_FRAMES:
        z_rel = item.z - origin.alt_m
    return x_m, y_m, z_rel


def decode_path(items: Sequence[MissionItem], origin: GeoOrigin, flavour: Flavour = "ardupilot") -> MissionPlan:
    """Mission items -> the hovering points (with hold times) they fly, in order."""
    _check_flavour(flavour)
    points: list[HoverPoint] = []
    takeoff_alt: float | None = None
    start = 1 if flavour == "ardupilot" and items else 0
    for item in items[start:]:
        if item.command == NAV_WAYPOINT:
            x_m, y_m, z_m = item_local(item, origin)
            points.append(HoverPoint(x_m, y_m, z_m, float(item.param1)))
        elif item.command == NAV_TAKEOFF:
            takeoff_alt = item_local(item, origin)[2]
    ends_with_rtl = bool(items) and items[-1].command == NAV_RTL
    return MissionPlan(points=points, ends_with_rtl=ends_with_rtl, takeoff_alt_m=takeoff_alt)


def validate_mission(
    items: Sequence[MissionItem],
    origin: GeoOrigin,
    area: Area,
    flavour: Flavour = "ardupilot",
    *,
    max_items: int = MAX_MISSION_ITEMS,
) -> None:
    """Refuse a mission that is not safe to fly on its own; ``MissionError`` names the item.

    Checks: 1..max_items items numbered 0..n-1, supported commands and frames, finite
    parameters (NaN only in param4, yaw, where MAVLink gives it a meaning), positions inside
    the area and altitudes within the limits, holds in [0, MAX_HOLD_S], and a last item
    that brings the aircraft down (return to launch or land).
    """
    _check_flavour(flavour)
    if not items:
        raise MissionError("items", "the mission is empty")
    if len(items) > max_items:
        raise MissionError("items", f"{len(items)} items exceed the limit of {max_items}")
    for i, item in enumerate(items):
        _validate_item(i, item, origin, area, skip_position=(flavour == "ardupilot" and i == 0))
    if items[-1].command not in (NAV_RTL, NAV_LAND):
        raise MissionError(f"items[{len(items) - 1}].command", "the mission must end in return to launch or land")


def _validate_item(i: int, item: MissionItem, origin: GeoOrigin, area: Area, *, skip_position: bool) -> None:
    where = f"items[{i}]"
    if item.seq != i:
        raise MissionError(f"{where}.seq", f"is {item.seq}, expected {i}")
    if item.mission_type != mavlink.MAV_MISSION_TYPE_MISSION:
        raise MissionError(f"{where}.mission_type", f"{item.mission_type} is not a mission item")
    if item.command not in SUPPORTED_COMMANDS:
        raise MissionError(f"{where}.command", f"command {item.command} is not supported")
    if item.frame not in SUPPORTED_FRAMES:
        raise MissionError(f"{where}.frame", f"frame {item.frame} is not supported")
    for name in ("param1", "param2", "param3", "z"):
        if not math.isfinite(getattr(item, name)):
            raise MissionError(f"{where}.{name}", "must be finite")
    if math.isinf(item.param4):
        raise MissionError(f"{where}.param4", "must be finite or NaN")
    if skip_position or item.command not in NAV_POSITION_COMMANDS:
        return
    if item.frame not in GLOBAL_FRAMES:
        raise MissionError(f"{where}.frame", f"a position command needs a global frame, got {item.frame}")
    if not (-90 * E7 <= item.x <= 90 * E7) or not (-180 * E7 <= item.y <= 180 * E7):
        raise MissionError(f"{where}.x", "latitude or longitude out of range")
    x_m, y_m, z_m = item_local(item, origin)
    tol = XY_TOLERANCE_M
    if not (-tol <= x_m <= area.side_m + tol and -tol <= y_m <= area.side_m + tol):
        raise MissionError(f"{where}.x", f"({x_m:.1f}, {y_m:.1f}) m lies outside the area [0, {area.side_m}]^2")
    if item.command in (NAV_WAYPOINT, NAV_TAKEOFF):
        if not area.min_flight_altitude_m <= z_m <= area.max_altitude_m:
            raise MissionError(
                f"{where}.z",
                f"altitude {z_m:.1f} m is outside [{area.min_flight_altitude_m}, {area.max_altitude_m}] m",
            )
    if item.command == NAV_WAYPOINT and not 0.0 <= item.param1 <= MAX_HOLD_S:
        raise MissionError(f"{where}.param1", f"hold {item.param1} s is outside [0, {MAX_HOLD_S}]")
