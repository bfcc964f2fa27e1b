"""Planned path <-> MISSION_ITEM_INT items, both flavours, and validate_mission."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink

from protocol import Area, GeoOrigin, HoverPoint, MissionError, MissionItem, decode_path, encode_path, validate_mission
from protocol.mission import MAX_MISSION_ITEMS, f32, same_items

ORIGIN = GeoOrigin()
AREA = Area(side_m=500.0, max_altitude_m=150.0, min_flight_altitude_m=5.0)
POINTS = [HoverPoint(20.0, 20.0, 100.0, 31.25), HoverPoint(250.0, 150.0, 100.0, 0.0), HoverPoint(475.0, 300.0, 60.0, 12.5)]


@pytest.mark.parametrize("flavour, home", [("ardupilot", 1), ("px4", 0)])
def test_structure(flavour: str, home: int) -> None:
    items = encode_path(POINTS, ORIGIN, flavour)
    assert len(items) == home + 1 + len(POINTS) + 1
    assert [i.seq for i in items] == list(range(len(items)))
    assert [i.current for i in items] == [1] + [0] * (len(items) - 1)
    if home:
        assert (items[0].command, items[0].frame) == (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_FRAME_GLOBAL)
        assert (items[0].x, items[0].y, items[0].z) == (473977420, 85455940, 488.0)
    takeoff = items[home]
    assert takeoff.command == mavlink.MAV_CMD_NAV_TAKEOFF and takeoff.z == 100.0
    waypoints = items[home + 1:-1]
    assert all(w.command == mavlink.MAV_CMD_NAV_WAYPOINT for w in waypoints)
    assert all(w.frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT for w in waypoints)
    # ArduPilot flies whole seconds: holds are rounded up, never cut short.
    assert [w.param1 for w in waypoints] == ([32.0, 0.0, 13.0] if flavour == "ardupilot" else [31.25, 0.0, 12.5])
    assert items[-1].command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH
    validate_mission(items, ORIGIN, AREA, flavour)


def test_the_first_waypoint_is_where_the_ellipsoid_says() -> None:
    wp = encode_path(POINTS, ORIGIN, "px4")[1]
    a, e2 = 6378137.0, 0.00669437999014  # WGS84
    phi = math.radians(ORIGIN.lat_deg)
    m = a * (1 - e2) / (1 - e2 * math.sin(phi) ** 2) ** 1.5  # meridian radius
    n = a / math.sqrt(1 - e2 * math.sin(phi) ** 2)  # prime vertical radius
    metres_per_deg_lat = math.radians(1.0) * (m + ORIGIN.alt_m)  # 111_239 m here
    metres_per_deg_lon = math.radians(1.0) * (n + ORIGIN.alt_m) * math.cos(phi)  # 75_488 m
    assert (wp.x - 473977420) == pytest.approx(20.0 / metres_per_deg_lat * 1e7, abs=1.0)
    assert (wp.y - 85455940) == pytest.approx(20.0 / metres_per_deg_lon * 1e7, abs=1.0)


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_decode_recovers_the_path(flavour: str) -> None:
    plan = decode_path(encode_path(POINTS, ORIGIN, flavour), ORIGIN, flavour)
    assert plan.ends_with_rtl and plan.takeoff_alt_m == 100.0
    assert len(plan.points) == len(POINTS)
    for got, want in zip(plan.points, POINTS):
        # 1e-7 degree is 1.1 cm of latitude and 0.75 cm of longitude here.
        assert math.hypot(got.x_m - want.x_m, got.y_m - want.y_m) < 0.01
        assert got.z_m == want.z_m and got.hold_s == (math.ceil(want.hold_s) if flavour == "ardupilot" else want.hold_s)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 500), st.floats(0, 500), st.floats(5, 150), st.floats(0, 3600)),
                min_size=1, max_size=30),
       st.sampled_from(["ardupilot", "px4"]))
def test_round_trip_property(points, flavour) -> None:
    path = [HoverPoint(*p) for p in points]
    items = encode_path(path, ORIGIN, flavour)
    validate_mission(items, ORIGIN, AREA, flavour)
    plan = decode_path(items, ORIGIN, flavour)
    for got, want in zip(plan.points, path):
        assert math.hypot(got.x_m - want.x_m, got.y_m - want.y_m) < 0.01
        assert got.z_m == f32(want.z_m)
        assert got.hold_s == (math.ceil(want.hold_s) if flavour == "ardupilot" else f32(want.hold_s))
    # Encoding what was decoded gives the same items again.
    assert same_items(encode_path(plan.points, ORIGIN, flavour), items)


def test_items_survive_the_wire() -> None:
    for item in encode_path(POINTS, ORIGIN, "ardupilot"):
        msg = item.to_message(1, 1)
        parsed = mavlink.MAVLink(None).decode(bytearray(msg.pack(mavlink.MAVLink(None, 255, 190))))
        assert MissionItem.from_message(parsed).same_as(item)


def refused(items, flavour="px4", **kwargs) -> MissionError:
    with pytest.raises(MissionError) as err:
        validate_mission(items, ORIGIN, AREA, flavour, **kwargs)
    return err.value


def replace(item: MissionItem, **changes) -> MissionItem:
    return MissionItem(**{**item.__dict__, **changes})


def test_validate_mission_refusals_name_the_item() -> None:
    items = encode_path(POINTS, ORIGIN, "px4")
    outside = encode_path([HoverPoint(520.0, 20.0, 100.0)], ORIGIN, "px4")
    assert refused(outside).where == "items[1].x"
    too_high = encode_path([HoverPoint(20.0, 20.0, 200.0)], ORIGIN, "px4")
    assert refused(too_high).where == "items[0].z"  # the takeoff climbs to it first
    too_low = list(items)
    too_low[2] = replace(items[2], z=1.0)
    assert refused(too_low).where == "items[2].z"
    nan = list(items)
    nan[1] = replace(items[1], param1=math.nan)
    assert refused(nan).where == "items[1].param1"
    no_rtl = items[:-1]
    assert refused(no_rtl).where == f"items[{len(no_rtl) - 1}].command"
    unsupported = list(items)
    unsupported[2] = replace(items[2], command=mavlink.MAV_CMD_DO_JUMP)
    assert refused(unsupported).where == "items[2].command"
    gap = list(items)
    gap[2] = replace(items[2], seq=7)
    assert refused(gap).where == "items[2].seq"
    assert refused([]).where == "items"
    many = encode_path([HoverPoint(10.0, 10.0, 50.0)] * MAX_MISSION_ITEMS, ORIGIN, "px4")
    assert refused(many).where == "items"


def test_encode_refuses_non_finite_points() -> None:
    with pytest.raises(MissionError) as err:
        encode_path([HoverPoint(1.0, math.inf, 50.0)], ORIGIN, "px4")
    assert err.value.where == "points[0].y_m"
    with pytest.raises(MissionError) as err:
        encode_path(POINTS, ORIGIN, "inav")  # type: ignore[arg-type]
    assert err.value.where == "flavour"
