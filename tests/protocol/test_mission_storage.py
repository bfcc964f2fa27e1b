"""Missions compared as the autopilot stores them, and the index-preserving replacement.

The read-back below is what ArduCopter V4.7.0-dev SITL (commit 90700977) returned for the
upload of ``encode_path([(100, 50, 30, 46.117 s), (200, 80, 30, 0.4 s)], acceptance 2 m)``
before holds were rounded up (tests/service/test_link_sitl.py checks today's encoding
against the live SITL): frame 3 for 6, frame 0 for return to launch, NaN as 0, the hold
truncated to whole seconds, the acceptance radius dropped, home in item 0."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from protocol import (Area, GeoOrigin, HoverPoint, MissionError, MissionItem, encode_path, replacement_items,
                      same_mission, stored_item, validate_mission)
from protocol.mission import NAV_RTL, NAV_TAKEOFF, NAV_WAYPOINT, mission_digest

ORIGIN = GeoOrigin()
AREA = Area(side_m=500.0, max_altitude_m=150.0, min_flight_altitude_m=5.0)
POINTS = [HoverPoint(100.0, 50.0, 30.0, 46.117), HoverPoint(200.0, 80.0, 30.0, 0.4)]

SITL_READ_BACK = [  # MISSION_ITEM_INT fields as ArduCopter SITL returned them
    MissionItem(0, 0, 16, 0, 1, 0.0, 0.0, 0.0, 0.0, 473977420, 85455940, 488.0999755859375),
    MissionItem(1, 3, 22, 0, 1, 0.0, 0.0, 0.0, 0.0, 473977420, 85455940, 30.0),
    MissionItem(2, 3, 16, 0, 1, 46.0, 0.0, 0.0, 0.0, 473981917, 85469186, 30.0),
    MissionItem(3, 3, 16, 0, 1, 0.0, 0.0, 0.0, 0.0, 473984615, 85482432, 30.0),
    MissionItem(4, 0, 20, 0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0),
]


def as_sent_then(items: list[MissionItem]) -> list[MissionItem]:
    """The items as they were sent before holds were rounded up (truncated there by SITL)."""
    return [MissionItem(**{**i.__dict__, "param1": p.hold_s}) if i.command == NAV_WAYPOINT and i.seq >= 2 else i
            for i, p in zip(items, [None, None, *POINTS, None])]  # type: ignore[list-item]


def test_a_read_back_matches_what_was_uploaded_as_ardupilot_stores_it() -> None:
    sent = as_sent_then(encode_path(POINTS, ORIGIN, "ardupilot", acceptance_radius_m=2.0))
    assert sent[2].param1 == pytest.approx(46.117) and sent[2].frame == 6 and math.isnan(sent[2].param4)
    assert same_mission(SITL_READ_BACK, sent, "ardupilot")
    for got, want in zip(SITL_READ_BACK[1:], sent[1:]):
        stored = stored_item(want, "ardupilot")
        assert (stored.frame, stored.param1, stored.param2, stored.param4) == (got.frame, got.param1, got.param2,
                                                                               got.param4)


def test_holds_are_rounded_up_so_none_is_cut_short() -> None:
    items = encode_path(POINTS, ORIGIN, "ardupilot")
    assert [i.param1 for i in items[1:] if i.command == NAV_WAYPOINT] == [47.0, 1.0]
    assert [i.param1 for i in encode_path(POINTS, ORIGIN, "px4") if i.command == NAV_WAYPOINT] == [
        pytest.approx(46.117), pytest.approx(0.4)]
    # What ArduPilot stores of our encoding is what we sent: the read-back of today's
    # upload matches it, and the 46 s of the old truncated read-back does not.
    stored = [stored_item(i, "ardupilot") for i in items]
    assert [s.param1 for s in stored[1:] if s.command == NAV_WAYPOINT] == [47.0, 1.0]
    assert not same_mission(SITL_READ_BACK, items, "ardupilot")


@pytest.mark.parametrize("change", ["moved", "hold", "altitude", "dropped", "command"])
def test_a_different_mission_is_still_refused(change: str) -> None:
    sent = as_sent_then(encode_path(POINTS, ORIGIN, "ardupilot"))
    other = list(SITL_READ_BACK)
    wp = other[2]
    if change == "moved":
        other[2] = MissionItem(**{**wp.__dict__, "x": wp.x + 10})
    elif change == "hold":
        other[2] = MissionItem(**{**wp.__dict__, "param1": 45.0})
    elif change == "altitude":
        other[2] = MissionItem(**{**wp.__dict__, "z": 31.0})
    elif change == "dropped":
        other = other[:2] + other[3:]
    else:
        other[2] = MissionItem(**{**wp.__dict__, "command": mavlink.MAV_CMD_NAV_LAND})
    assert not same_mission(other, sent, "ardupilot")


def test_px4_keeps_nan_and_fractions_but_takes_int_frames_as_their_twins() -> None:
    items = encode_path(POINTS, ORIGIN, "px4")
    twins = [MissionItem(**{**i.__dict__, "frame": 3 if i.frame == 6 else i.frame}) for i in items]
    assert same_mission(twins, items, "px4")
    truncated = [MissionItem(**{**i.__dict__, "param1": float(int(i.param1))}) for i in items]
    assert not same_mission(truncated, items, "px4")  # PX4 flies the fraction: a different hold
    assert mission_digest(items, "px4") != mission_digest(items, "ardupilot")


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_a_replacement_keeps_the_index_and_marks_the_next_item(flavour: str) -> None:
    held = encode_path([HoverPoint(20, 20, 40, 5), HoverPoint(60, 20, 40, 5), HoverPoint(90, 90, 40, 5)], ORIGIN,
                       flavour)
    first_point = 2 if flavour == "ardupilot" else 1
    keep = first_point  # the first point was flown; the vehicle is on its way to the second
    new = [HoverPoint(300, 300, 50, 12.2), HoverPoint(400, 100, 50, 0.0)]
    items, next_seq = replacement_items(held, keep, new, ORIGIN, flavour)
    assert next_seq == keep + 1
    assert [i.seq for i in items] == list(range(len(items)))
    for kept, was in zip(items[:keep + 1], held):
        assert MissionItem(**{**kept.__dict__, "current": was.current}) == was  # as it was, but not current
    assert [i.current for i in items] == [1 if i == next_seq else 0 for i in range(len(items))]
    assert items[next_seq].command == NAV_WAYPOINT and items[-1].command == NAV_RTL
    assert len(items) == keep + 1 + len(new) + 1
    assert items[next_seq].param1 == (13.0 if flavour == "ardupilot" else pytest.approx(12.2))
    validate_mission(items, ORIGIN, AREA, flavour)


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_return_to_launch_alone_lands_on_the_next_index(flavour: str) -> None:
    held = encode_path([HoverPoint(20, 20, 40, 5), HoverPoint(60, 20, 40, 5)], ORIGIN, flavour)
    keep = len(held) - 3  # the first point flown, the second replaced by nothing
    items, next_seq = replacement_items(held, keep, [], ORIGIN, flavour)
    assert next_seq == len(items) - 1 and items[next_seq].command == NAV_RTL and items[next_seq].current == 1
    validate_mission(items, ORIGIN, AREA, flavour)


def test_replacements_that_cannot_fly_exactly_are_refused() -> None:
    held = encode_path([HoverPoint(20, 20, 40, 5)], ORIGIN, "ardupilot")  # home, takeoff, point, RTL
    with pytest.raises(MissionError, match="keep_through_seq"):
        replacement_items(held, len(held), [], ORIGIN, "ardupilot")
    with pytest.raises(MissionError, match="takeoff"):
        replacement_items(held, 0, [HoverPoint(30, 30, 40)], ORIGIN, "ardupilot")
    with pytest.raises(MissionError, match="already ends"):
        replacement_items(held, 3, [HoverPoint(30, 30, 40)], ORIGIN, "ardupilot")
    with pytest.raises(MissionError, match=r"points\[0\].hold_s"):
        replacement_items(held, 2, [HoverPoint(30, 30, 40, -1.0)], ORIGIN, "ardupilot")
    assert held[1].command == NAV_TAKEOFF
