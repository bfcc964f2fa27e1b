"""QGroundControl .plan and WPL 110: written and read back identically."""

from __future__ import annotations

import json

import pytest

from protocol import GeoOrigin, HoverPoint, MissionError, MissionItem, encode_path, read_plan, read_wpl, same_items, write_plan, write_wpl

ORIGIN = GeoOrigin()
POINTS = [HoverPoint(20.0, 20.0, 100.0, 31.123), HoverPoint(250.0, 150.0, 100.0, 0.0), HoverPoint(490.0, 400.0, 75.5, 7.0)]


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
@pytest.mark.parametrize("write, read", [(write_plan, read_plan), (write_wpl, read_wpl)])
def test_round_trip(flavour, write, read) -> None:
    items = encode_path(POINTS, ORIGIN, flavour)
    text = write(items, flavour, ORIGIN)
    back, home = read(text, flavour)
    assert same_items(back, items)
    assert home == ORIGIN
    assert write(back, flavour, home) == text


def test_plan_is_what_qgroundcontrol_reads() -> None:
    items = encode_path(POINTS, ORIGIN, "px4")
    doc = json.loads(write_plan(items, "px4", ORIGIN))
    assert doc["fileType"] == "Plan" and doc["mission"]["version"] == 2
    assert doc["mission"]["plannedHomePosition"] == [ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m]
    first = doc["mission"]["items"][1]
    assert first["type"] == "SimpleItem" and first["command"] == 16 and first["frame"] == 6
    assert first["params"][3] is None  # NaN yaw is null, as QGroundControl writes it
    assert first["params"][0] == pytest.approx(31.123, abs=1e-5)
    assert len(doc["mission"]["items"]) == len(items)
    # ArduPilot's home item becomes plannedHomePosition, not a plan item.
    ardu = json.loads(write_plan(encode_path(POINTS, ORIGIN, "ardupilot"), "ardupilot"))
    assert len(ardu["mission"]["items"]) == len(items)


def test_wpl_is_what_mission_planner_reads() -> None:
    lines = write_wpl(encode_path(POINTS, ORIGIN, "px4"), "px4", ORIGIN).splitlines()
    assert lines[0] == "QGC WPL 110"
    home = lines[1].split("\t")
    assert len(home) == 12 and home[:4] == ["0", "0", "0", "16"] and home[8:11] == ["47.39774200", "8.54559400", "488.0"]
    assert lines[-1].split("\t")[3] == "20"  # return to launch
    assert len(lines) == 1 + 1 + 1 + len(POINTS) + 1  # header, home, takeoff, waypoints, RTL


@pytest.mark.parametrize("text, where", [
    ("{", "plan"),
    ('{"fileType": "Nope"}', "plan.fileType"),
    ('{"fileType": "Plan", "mission": {"plannedHomePosition": [1, 2, 3], "items": [{"type": "ComplexItem"}]}}',
     "plan.mission.items[0]"),
    ('{"fileType": "Plan", "mission": {"plannedHomePosition": [1, 2, 3], "items": '
     '[{"type": "SimpleItem", "command": 16, "frame": 6, "params": [0, 0, 0, 0, "x", 1, 1]}]}}',
     "plan.mission.items[0].params[4]"),
])
def test_bad_plan_files_name_the_problem(text: str, where: str) -> None:
    with pytest.raises(MissionError) as err:
        read_plan(text, "px4")
    assert err.value.where == where


def test_bad_wpl_files_name_the_line() -> None:
    with pytest.raises(MissionError) as err:
        read_wpl("QGC WPL 120\n", "px4")
    assert err.value.where == "wpl.header"
    with pytest.raises(MissionError) as err:
        read_wpl("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t47.3\t8.5\t488\t1\n1\t0\t3\t16\t0\t0\n", "px4")
    assert err.value.where == "wpl.line[3]"


@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_wpl_marks_exactly_one_line_current(flavour: str) -> None:
    """The PX4 export marked both home and the first item current; MAVSDK's importer and
    MAVProxy want one."""
    items = encode_path(POINTS, ORIGIN, flavour)
    rows = [line.split("\t") for line in write_wpl(items, flavour, ORIGIN).splitlines()[1:]]
    assert [row[1] for row in rows].count("1") == 1
    unmarked = [MissionItem(**{**i.__dict__, "current": 0}) for i in items]
    rows = [line.split("\t") for line in write_wpl(unmarked, flavour, ORIGIN).splitlines()[1:]]
    assert [row[1] for row in rows].count("1") == (1 if flavour == "px4" else 0)
