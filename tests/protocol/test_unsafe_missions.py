"""Missions a planner must never emit are refused by ``protocol`` itself, with a
``MissionError`` naming the item (or point) and field: waypoints outside the area, below the
minimum flight altitude or above the maximum, NaN or infinite coordinates, holds out of
range, more items than the vehicle accepts, a mission not ending in return to launch.

Property-based: paths mixing safe and unsafe points go through ``encode_path`` and
``validate_mission``; the first unsafe point must be the one named, found by an oracle
that works on the points, not on the items. Arbitrary item lists make
``validate_mission`` raise nothing but ``MissionError``, and whatever it passes is safe.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from protocol import Area, GeoOrigin, HoverPoint, MissionError, MissionItem, encode_path, validate_mission
from protocol.mission import MAX_HOLD_S, MAX_LOCAL_M, NAV_POSITION_COMMANDS, NAV_RTL, XY_TOLERANCE_M, item_local

ORIGIN = GeoOrigin()
AREA = Area(side_m=500.0, max_altitude_m=120.0, min_flight_altitude_m=10.0)
PROPERTY = settings(max_examples=400, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])

# Safe values reach the limits exactly (the encoding must keep them in); unsafe ones stay
# 10 cm clear of the area's 0.5 m tolerance and 1 cm clear of the altitude limits, where
# the 1e-7 degree and float32 roundings (about 1 cm and 1e-5 m) cannot decide.
safe_xy = st.one_of(st.sampled_from([0.0, AREA.side_m]), st.floats(0.0, AREA.side_m))
unsafe_xy = st.one_of(st.floats(-1e6, -XY_TOLERANCE_M - 0.1), st.floats(AREA.side_m + XY_TOLERANCE_M + 0.1, 1e6),
                      st.sampled_from([-1e300, 1e300, 5e6, 1e6, -1e6, 1e6 + 1]))
safe_z = st.one_of(st.sampled_from([AREA.min_flight_altitude_m, AREA.max_altitude_m]),
                   st.floats(AREA.min_flight_altitude_m, AREA.max_altitude_m))
unsafe_z = st.one_of(st.floats(-1e4, AREA.min_flight_altitude_m - 0.01), st.floats(AREA.max_altitude_m + 0.01, 1e5),
                     st.sampled_from([0.0, -0.0, 1e300, -1e39, 1e6 + 1]))
safe_hold = st.one_of(st.sampled_from([0.0, MAX_HOLD_S]), st.floats(0.0, MAX_HOLD_S))
unsafe_hold = st.one_of(st.floats(-1e9, -1e-9), st.floats(MAX_HOLD_S + 1e-6, 1e9))
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])


@st.composite
def points(draw: st.DrawFn) -> HoverPoint:
    """A hovering point, safe or with one or more unsafe fields."""
    fields = {"x_m": safe_xy, "y_m": safe_xy, "z_m": safe_z, "hold_s": safe_hold}
    values = {name: draw(strategy) for name, strategy in fields.items()}
    for name in draw(st.lists(st.sampled_from(list(fields)), max_size=2)):
        bad = {"x_m": unsafe_xy, "y_m": unsafe_xy, "z_m": unsafe_z, "hold_s": unsafe_hold}[name]
        values[name] = draw(st.one_of(bad, non_finite))
    return HoverPoint(**values)


def expected_refusal(path: list[HoverPoint], flavour: str) -> tuple[str, str] | None:
    """("encode" or "validate", where) of the first refusal, from the points alone."""
    for i, p in enumerate(path):
        for name in ("x_m", "y_m", "z_m", "hold_s"):
            if not math.isfinite(getattr(p, name)):
                return "encode", f"points[{i}].{name}"
        if not 0.0 <= p.hold_s <= MAX_HOLD_S:
            return "encode", f"points[{i}].hold_s"
        for name in ("x_m", "y_m", "z_m"):
            if abs(getattr(p, name)) > MAX_LOCAL_M:
                return "encode", f"points[{i}].{name}"
    first = 1 if flavour == "ardupilot" else 0  # the item after home
    if path and not AREA.min_flight_altitude_m <= path[0].z_m <= AREA.max_altitude_m:
        return "validate", f"items[{first}].z"  # the takeoff climbs to the first point's altitude
    for i, p in enumerate(path):
        k = first + 1 + i
        inside = [-XY_TOLERANCE_M <= v <= AREA.side_m + XY_TOLERANCE_M for v in (p.x_m, p.y_m)]
        if not all(inside):
            return "validate", f"items[{k}].x"
        if not AREA.min_flight_altitude_m <= p.z_m <= AREA.max_altitude_m:
            return "validate", f"items[{k}].z"
    return None


@PROPERTY
@given(st.lists(points(), max_size=8), st.sampled_from(["ardupilot", "px4"]))
def test_the_first_unsafe_point_is_named(path: list[HoverPoint], flavour: Any) -> None:
    expected = expected_refusal(path, flavour)
    try:
        items = encode_path(path, ORIGIN, flavour)
    except MissionError as err:
        assert expected == ("encode", err.where), (path, err)
        return
    try:
        validate_mission(items, ORIGIN, AREA, flavour)
    except MissionError as err:
        assert expected == ("validate", err.where), (path, err)
        return
    assert expected is None, (path, "an unsafe path was passed")


@settings(PROPERTY, max_examples=150)
@given(st.integers(1, 40), st.integers(3, 40), st.sampled_from(["ardupilot", "px4"]))
def test_more_items_than_the_vehicle_accepts_are_refused(count: int, capacity: int, flavour: Any) -> None:
    items = encode_path([HoverPoint(100.0, 100.0, 50.0, 1.0)] * count, ORIGIN, flavour)
    if len(items) > capacity:
        with pytest.raises(MissionError) as err:
            validate_mission(items, ORIGIN, AREA, flavour, max_items=capacity)
        assert (err.value.where, err.value.message) == ("items", f"{len(items)} items exceed the limit of {capacity}")
    else:
        validate_mission(items, ORIGIN, AREA, flavour, max_items=capacity)


@settings(PROPERTY, max_examples=150)
@given(st.lists(points().filter(lambda p: expected_refusal([p], "px4") is None), min_size=1, max_size=5),
       st.sampled_from(["ardupilot", "px4"]), st.sampled_from(["drop", "waypoint", "takeoff", "speed"]))
def test_a_mission_not_ending_in_return_to_launch_is_refused(path: list[HoverPoint], flavour: Any, how: str) -> None:
    items = encode_path(path, ORIGIN, flavour)
    validate_mission(items, ORIGIN, AREA, flavour)
    if how == "drop":
        items = items[:-1]
    else:
        command = {"waypoint": mavlink.MAV_CMD_NAV_WAYPOINT, "takeoff": mavlink.MAV_CMD_NAV_TAKEOFF,
                   "speed": mavlink.MAV_CMD_DO_CHANGE_SPEED}[how]
        items[-1] = MissionItem(**{**items[-2].__dict__, "seq": len(items) - 1, "command": command})
    with pytest.raises(MissionError) as err:
        validate_mission(items, ORIGIN, AREA, flavour)
    assert err.value.where == f"items[{len(items) - 1}].command"


# --- arbitrary items ----------------------------------------------------------------------------
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32), st.sampled_from([0.0, 1.0, 50.0, 3600.0]))
commands = st.sampled_from([16, 21, 22, 20, 178, 177, 19, 0, 65535, 31000])
frames = st.sampled_from([0, 3, 5, 6, 2, 1, 10, 11, 255])
lat = st.one_of(st.integers(-2 ** 31, 2 ** 31 - 1), st.integers(473977420 - 10000, 473977420 + 60000))
lon = st.one_of(st.integers(-2 ** 31, 2 ** 31 - 1), st.integers(85455940 - 10000, 85455940 + 90000))


@st.composite
def hostile_items(draw: st.DrawFn) -> list[MissionItem]:
    count = draw(st.integers(0, 8))
    items = []
    for i in range(count):
        seq = i if draw(st.integers(0, 9)) else draw(st.integers(0, 65535))
        items.append(MissionItem(
            seq=seq, frame=draw(frames), command=draw(commands), current=draw(st.integers(0, 1)),
            param1=draw(floats), param2=draw(floats), param3=draw(floats), param4=draw(floats),
            x=draw(lat), y=draw(lon), z=draw(floats), mission_type=draw(st.sampled_from([0, 0, 0, 1, 2, 255]))))
    return items


def assert_safe(items: list[MissionItem], flavour: str) -> None:
    """What a passed mission must be, checked without validate_mission."""
    assert 1 <= len(items) <= 512 and [i.seq for i in items] == list(range(len(items)))
    assert items[-1].command in (NAV_RTL, mavlink.MAV_CMD_NAV_LAND)
    for k, item in enumerate(items):
        assert all(math.isfinite(v) for v in (item.param1, item.param2, item.param3, item.z))
        if item.command not in NAV_POSITION_COMMANDS or (flavour == "ardupilot" and k == 0):
            continue
        x_m, y_m, z_m = item_local(item, ORIGIN)
        assert -1.0 <= x_m <= AREA.side_m + 1.0 and -1.0 <= y_m <= AREA.side_m + 1.0, (k, item)
        if item.command != mavlink.MAV_CMD_NAV_LAND:
            assert AREA.min_flight_altitude_m <= z_m <= AREA.max_altitude_m, (k, item)
        if item.command == mavlink.MAV_CMD_NAV_WAYPOINT:
            assert 0.0 <= item.param1 <= MAX_HOLD_S


@settings(max_examples=600, deadline=None, database=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(hostile_items(), st.sampled_from(["ardupilot", "px4"]))
def test_arbitrary_items_are_refused_with_a_mission_error_or_safe(items: list[MissionItem], flavour: Any) -> None:
    try:
        validate_mission(items, ORIGIN, AREA, flavour)
    except MissionError as err:
        assert err.where and err.message
        return
    assert_safe(items, flavour)


def test_a_point_too_far_to_encode_is_refused_naming_it() -> None:
    # Regressions: an altitude beyond float32 raised OverflowError from struct.pack (the
    # takeoff item takes the first point's altitude), and x = 1e300 made the geodesy
    # return NaN, refused as "nan is not a finite coordinate".
    for point, where in ((HoverPoint(10.0, 10.0, 1e300), "points[0].z_m"), (HoverPoint(1e300, 10.0, 50.0), "points[0].x_m"),
                         (HoverPoint(10.0, -2e6, 50.0), "points[0].y_m")):
        with pytest.raises(MissionError) as err:
            encode_path([point], ORIGIN, "px4")
        assert err.value.where == where and "from the origin" in err.value.message
