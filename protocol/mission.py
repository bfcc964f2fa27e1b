"""A planned path in local metres <-> MAVLink mission items (MISSION_ITEM_INT), and back.

A plan becomes: [home placeholder (ArduPilot only)], a takeoff to the first point's
altitude, one ``MAV_CMD_NAV_WAYPOINT`` per hovering point with param1 = hold time, and a
final ``MAV_CMD_NAV_RETURN_TO_LAUNCH``: the mission is complete and safe on its own, so a
lost link never leaves the aircraft without a way home.

ArduPilot keeps its home position in item 0 and overwrites whatever is uploaded there;
PX4 has no such item. ``flavour`` selects the convention.

An autopilot does not store every field as it was sent: ArduPilot returns frame 3 for a
waypoint sent in frame 6, frame 0 for return to launch, 0 where NaN was sent, and the
waypoint hold as whole seconds (a uint16: 46.117 s is flown as 46 s). ``stored_item`` says
what a flavour keeps; ``same_mission`` and ``mission_digest`` compare in that form, and the
holds are rounded up to whole seconds for ArduPilot when encoding, so no hold is cut short.

A mission replaced in flight keeps its index on both autopilots (ArduPilot keeps its current
item across an upload and restarts the command there; PX4 keeps it unless an uploaded item
is marked current): ``replacement_items`` builds the index-preserving mission, see there.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Sequence

from pymavlink.dialects.v20 import common as mavlink

from .area import Area
from .autopilot import Autopilot, Flavour, autopilot_for
from .errors import MissionError
from .geodesy import GeoOrigin, global_to_local, local_to_global

AnyAutopilot = Flavour | Autopilot
"""An autopilot as the configuration names it or as its profile (``autopilot``)."""

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


INT_FRAMES = {FRAME_GLOBAL_INT: FRAME_GLOBAL, FRAME_RELATIVE_INT: FRAME_RELATIVE,
              mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT: mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT}
"""The ``_INT`` frames and the frames an autopilot stores for them (the same meaning)."""
UINT16_MAX = 65535


def stored_item(item: MissionItem, flavour: AnyAutopilot = "ardupilot") -> MissionItem:
    """``item`` as the autopilot stores it and returns it on a download (``current`` left
    as it is: it marks where to fly, not what).

    Both flavours: an ``_INT`` frame is its plain twin (frame 6 is 3), values as float32.
    ArduPilot (read back from ArduCopter 4.7 SITL): NaN parameters are 0; a command without
    a position (return to launch, change speed) has frame 0 and no position; a waypoint
    keeps only its hold, in whole seconds (uint16, truncated), not its acceptance radius,
    pass radius or yaw (``AP_Mission::mavlink_int_to_mission_cmd``)."""
    autopilot = _check_flavour(flavour)
    frame = INT_FRAMES.get(item.frame, item.frame)
    params = [item.param1, item.param2, item.param3, item.param4]
    x, y, z = item.x, item.y, item.z
    if autopilot.compacts_items:
        params = [0.0 if math.isnan(p) else p for p in params]
        if item.command == NAV_RTL:
            frame, x, y, z = FRAME_GLOBAL, 0, 0, 0.0
        if item.command == NAV_WAYPOINT:
            hold = params[0]
            params = [float(min(max(int(hold), 0), UINT16_MAX)) if math.isfinite(hold) else 0.0, 0.0, 0.0, 0.0]
    params = [p if math.isnan(p) else f32(p) for p in params]
    return MissionItem(seq=item.seq, frame=frame, command=item.command, current=item.current,
                       autocontinue=item.autocontinue, param1=params[0], param2=params[1], param3=params[2],
                       param4=params[3], x=x, y=y, z=z if math.isnan(z) else f32(z), mission_type=item.mission_type)


def mission_digest(items: Sequence[MissionItem], flavour: AnyAutopilot = "ardupilot") -> str:
    """A short fingerprint (CRC-32, 8 hex digits) of what a mission flies: each item's
    command, frame, parameters and position as the autopilot stores them (``stored_item``,
    float32), in order. ``current`` is left out (it marks where to start, not what to
    fly), and so is ArduPilot's item 0, which the autopilot replaces with home. The
    vehicle stub logs it for every mission it commits, so a test can tell which upload the
    vehicle holds; a mission read back from ArduPilot has the digest of the one uploaded."""
    autopilot = _check_flavour(flavour)
    start = autopilot.home_slots if items else 0
    crc = 0
    for item in (stored_item(i, flavour) for i in items[start:]):
        params = (item.param1, item.param2, item.param3, item.param4, item.z)
        crc = zlib.crc32(struct.pack("<3H5f2i", item.command, item.frame, item.autocontinue,
                                     *(math.nan if math.isnan(v) else f32(v) for v in params),
                                     item.x, item.y), crc)
    return f"{crc:08x}"


def same_mission(a: Sequence[MissionItem], b: Sequence[MissionItem], flavour: AnyAutopilot = "ardupilot") -> bool:
    """``a`` and ``b`` fly the same (a mission read back from the vehicle against the one
    uploaded: compared as the autopilot stores them, ``stored_item``; ArduPilot's item 0
    and ``current`` aside)."""
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


def _check_flavour(flavour: AnyAutopilot) -> Autopilot:
    return autopilot_for(flavour)


def home_item(origin: GeoOrigin) -> MissionItem:
    """ArduPilot's item 0: home, in absolute altitude."""
    return MissionItem(
        seq=0, frame=FRAME_GLOBAL, command=NAV_WAYPOINT, x=_to_int(origin.lat_deg * E7, "home.x"),
        y=_to_int(origin.lon_deg * E7, "home.y"), z=f32(origin.alt_m),
    )


def encode_path(
    points: Iterable[HoverPoint],
    origin: GeoOrigin,
    flavour: AnyAutopilot = "ardupilot",
    *,
    takeoff: bool = True,
    acceptance_radius_m: float = 0.0,
) -> list[MissionItem]:
    """Hovering points -> mission items, ending in return to launch: the first mission of
    a sortie, flown from the ground. ArduPilot: [home placeholder, takeoff, points...,
    return to launch] (``VehicleLink.start`` arms and MISSION_START flies it from item 1);
    PX4: the same without the placeholder. Holds are rounded up to whole seconds for
    ArduPilot (``encoded_hold_s``). In flight, replace a mission with
    ``replacement_items``, which keeps the vehicle's index.

    The takeoff item climbs over home to the first point's altitude; a vehicle already in
    the air completes it at once, so a re-planned mission may keep it.
    """
    autopilot = _check_flavour(flavour)
    points = list(points)
    for i, point in enumerate(points):
        _check_point(f"points[{i}]", point)
    items: list[MissionItem] = []
    if autopilot.home_slots:
        items.append(home_item(origin))
    if takeoff and points:
        items.append(MissionItem(
            seq=len(items), frame=FRAME_RELATIVE_INT, command=NAV_TAKEOFF, param4=math.nan,
            x=_to_int(origin.lat_deg * E7, "takeoff.x"), y=_to_int(origin.lon_deg * E7, "takeoff.y"),
            z=f32(points[0].z_m),
        ))
    items.extend(_waypoints(points, len(items), origin, flavour, acceptance_radius_m))
    items.append(MissionItem(seq=len(items), frame=FRAME_MISSION, command=NAV_RTL))
    # Exactly one item is marked current, the first, as QGroundControl writes missions
    # (MAVSDK refuses an upload with none: CURRENT_INVALID).
    items[0] = replace(items[0], current=1)
    return items


def encoded_hold_s(hold_s: float, flavour: AnyAutopilot = "ardupilot") -> float:
    """The hold as encoded in a waypoint's param1: ArduPilot flies whole seconds (it stores
    a uint16 and truncates), so the hold is rounded up there, never cut short (46.117 s
    is sent as 47 s); PX4 takes the float."""
    return float(math.ceil(hold_s)) if autopilot_for(flavour).whole_second_holds else f32(hold_s)


def _waypoints(points: Sequence[HoverPoint], first_seq: int, origin: GeoOrigin, flavour: AnyAutopilot,
               acceptance_radius_m: float) -> list[MissionItem]:
    items = []
    for i, point in enumerate(points):
        where = f"points[{i}]"
        lat, lon, _ = local_to_global(origin, point.x_m, point.y_m, point.z_m)
        items.append(MissionItem(
            seq=first_seq + i, frame=FRAME_RELATIVE_INT, command=NAV_WAYPOINT,
            param1=encoded_hold_s(point.hold_s, flavour), param2=f32(acceptance_radius_m), param4=math.nan,
            x=_to_int(lat * E7, f"{where}.x_m"), y=_to_int(lon * E7, f"{where}.y_m"),
            z=f32(point.z_m),
        ))
    return items


def replacement_items(
    held: Sequence[MissionItem],
    keep_through_seq: int,
    points: Sequence[HoverPoint],
    origin: GeoOrigin,
    flavour: AnyAutopilot = "ardupilot",
    *,
    acceptance_radius_m: float = 0.0,
) -> tuple[list[MissionItem], int]:
    """A mission that replaces ``held`` in flight without moving the vehicle's index:
    items ``0..keep_through_seq`` copied from ``held`` as they are (ArduPilot's home, the
    takeoff, the points already flown or being flown), then the new ``points``, then
    return to launch. Returns the items and the seq the vehicle must fly next
    (``keep_through_seq + 1``: the first new point, or the return to launch when
    ``points`` is empty), which is the only item marked ``current``.

    Why this layout: both autopilots keep their current index across an upload. ArduPilot
    (``AP_Mission_ChangeDetector::check_for_mission_change``, Copter's ``ModeAuto::run``)
    compares the next three navigation commands from the current index before and after
    the upload and, if they differ while the index did not move, restarts the command at
    the current index with the new content; PX4 (``MissionBase::updateMavlinkMission``)
    keeps its index unless an uploaded item is marked current, which it then flies at
    once (it honours the mark set here; ArduPilot ignores it). So a vehicle flying towards
    item ``keep_through_seq + 1`` goes straight to the new plan's first point, and
    ``VehicleLink.upload(items, current_seq=next)`` moves any vehicle that is elsewhere.

    The caller's rule: replace once the vehicle has finished item ``keep_through_seq``
    (its MISSION_CURRENT is past it), or when it means to end it. An upload that lands
    while the vehicle still holds at ``keep_through_seq`` changes the commands after it, so
    ArduPilot restarts that hold from zero (the three-command window includes the new
    ones), and setting the current item to the next one ends the hold at once (PX4 does
    the same on its own, from the ``current`` mark).
    """
    _check_flavour(flavour)
    held = list(held)
    if not 0 <= keep_through_seq < len(held):
        raise MissionError("keep_through_seq", f"{keep_through_seq} is not an item of the {len(held)} held")
    takeoff = next((i for i, item in enumerate(held) if item.command == NAV_TAKEOFF), None)
    if takeoff is not None and keep_through_seq < takeoff:
        raise MissionError("keep_through_seq", f"{keep_through_seq} would drop the takeoff (item {takeoff}): "
                           "the mission must stay complete on its own; encode a new one with encode_path")
    ended = next((i for i, item in enumerate(held[:keep_through_seq + 1]) if item.command in (NAV_RTL, NAV_LAND)), None)
    if ended is not None:
        raise MissionError("keep_through_seq", f"item {ended} already ends the held mission (return or land)")
    points = list(points)
    for i, point in enumerate(points):
        _check_point(f"points[{i}]", point)
    kept = [replace(item, current=0) for item in held[:keep_through_seq + 1]]
    items = kept + _waypoints(points, len(kept), origin, flavour, acceptance_radius_m)
    items.append(MissionItem(seq=len(items), frame=FRAME_MISSION, command=NAV_RTL))
    next_seq = keep_through_seq + 1
    items[next_seq] = replace(items[next_seq], current=1)
    return items, next_seq


def max_points(max_items: int, flavour: AnyAutopilot = "ardupilot") -> int:
    """The most hovering points ``encode_path`` fits in ``max_items`` mission items: the
    items around them are ArduPilot's home, the takeoff and the return to launch."""
    around = _check_flavour(flavour).home_slots + 2  # the takeoff and the return
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


def decode_path(items: Sequence[MissionItem], origin: GeoOrigin, flavour: AnyAutopilot = "ardupilot") -> MissionPlan:
    """Mission items -> the hovering points (with hold times) they fly, in order."""
    autopilot = _check_flavour(flavour)
    points: list[HoverPoint] = []
    takeoff_alt: float | None = None
    start = autopilot.home_slots if items else 0
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
    flavour: AnyAutopilot = "ardupilot",
    *,
    max_items: int = MAX_MISSION_ITEMS,
) -> None:
    """Refuse a mission that is not safe to fly on its own; ``MissionError`` names the item.

    Checks: 1..max_items items numbered 0..n-1, supported commands and frames, finite
    parameters (NaN only in param4, yaw, where MAVLink gives it a meaning), positions inside
    the area and altitudes within the limits, holds in [0, MAX_HOLD_S], and a last item
    that brings the aircraft down (return to launch or land).
    """
    autopilot = _check_flavour(flavour)
    if not items:
        raise MissionError("items", "the mission is empty")
    if len(items) > max_items:
        raise MissionError("items", f"{len(items)} items exceed the limit of {max_items}")
    for i, item in enumerate(items):
        _validate_item(i, item, origin, area, skip_position=i < autopilot.home_slots)
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
