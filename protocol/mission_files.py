"""Mission files: QGroundControl ``.plan`` (JSON) and WPL 110 (MAVProxy, Mission Planner).

Both hold what ``protocol.mission`` produces and read back to identical items. Positions
are written as degrees with enough digits that ``round(deg * 1e7)`` recovers the integer;
parameters are written in their shortest exact form; NaN (yaw: keep heading) is ``null``
in a .plan, as QGroundControl writes it, and ``nan`` in WPL, which MAVProxy reads.

Home: a .plan keeps it in ``plannedHomePosition``; a WPL file always has it on line 0.
With the ArduPilot flavour that is the mission's item 0; with PX4 it is not an item.
"""

from __future__ import annotations

import json
import math
from typing import Any, Sequence

from pymavlink.dialects.v20 import common as mavlink

from .errors import MissionError
from .geodesy import GeoOrigin
from .mission import E7, GLOBAL_FRAMES, AnyAutopilot, MissionItem, _check_flavour, home_item

WPL_HEADER = "QGC WPL 110"
_VEHICLE_QUADROTOR = mavlink.MAV_TYPE_QUADROTOR


def _split_home(items: Sequence[MissionItem], flavour: AnyAutopilot, home: GeoOrigin) -> tuple[GeoOrigin, list[MissionItem]]:
    if _check_flavour(flavour).home_slots:
        if not items:
            raise MissionError("items", "an ArduPilot mission has at least its home item")
        first = items[0]
        return GeoOrigin(first.x / E7, first.y / E7, first.z), list(items[1:])
    return home, list(items)


def _join_home(home: GeoOrigin, body: list[MissionItem], flavour: AnyAutopilot,
               home_current: int | None = None) -> list[MissionItem]:
    """The mission in ``flavour``'s convention. A .plan stores no ``current`` flag: the
    first item is marked, as ``encode_path`` and QGroundControl do."""
    autopilot = _check_flavour(flavour)
    if autopilot.home_slots:
        items = [home_item(home)] + [_renumber(item, i + 1) for i, item in enumerate(body)]
    else:
        items = [_renumber(item, i) for i, item in enumerate(body)]
    if items and home_current is None:
        items = [_with(item, current=int(i == 0)) for i, item in enumerate(items)]
    elif items and autopilot.home_slots:
        items[0] = _with(items[0], current=home_current)
    return items


def _renumber(item: MissionItem, seq: int) -> MissionItem:
    return item if item.seq == seq else _with(item, seq=seq)


def _with(item: MissionItem, **changes: Any) -> MissionItem:
    return MissionItem(**{**item.__dict__, **changes})


def _degrees(value: int, frame: int) -> float | int:
    return value / E7 if frame in GLOBAL_FRAMES else value


def _from_degrees(value: Any, frame: int, where: str) -> int:
    number = _number(value, where)
    if not math.isfinite(number):
        raise MissionError(where, "a position must be finite")
    return int(round(number * E7)) if frame in GLOBAL_FRAMES else int(round(number))


def _number(value: Any, where: str) -> float:
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MissionError(where, f"{value!r} is not a number")
    return float(value)


def _json_number(value: float) -> float | None:
    return None if math.isnan(value) else value


# --- QGroundControl .plan -------------------------------------------------------------


def write_plan(items: Sequence[MissionItem], flavour: AnyAutopilot, home: GeoOrigin | None = None) -> str:
    """The mission as a QGroundControl .plan document. ``home`` is needed for PX4 (whose
    missions hold no home item); for ArduPilot item 0 is the home."""
    autopilot = _check_flavour(flavour)
    home_pos, body = _split_home(items, flavour, home or GeoOrigin())
    plan_items = []
    for item in body:
        plan_items.append({
            "autoContinue": bool(item.autocontinue),
            "command": item.command,
            "doJumpId": item.seq + 1 - autopilot.home_slots,
            "frame": item.frame,
            "params": [
                _json_number(item.param1), _json_number(item.param2), _json_number(item.param3),
                _json_number(item.param4), _degrees(item.x, item.frame), _degrees(item.y, item.frame),
                _json_number(item.z),
            ],
            "type": "SimpleItem",
        })
    document = {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": [], "version": 2},
        "groundStation": "uav-mcts-planner",
        "mission": {
            "cruiseSpeed": 15,
            "firmwareType": autopilot.mav_autopilot,
            "globalPlanAltitudeMode": 1,
            "hoverSpeed": 5,
            "items": plan_items,
            "plannedHomePosition": [home_pos.lat_deg, home_pos.lon_deg, home_pos.alt_m],
            "vehicleType": _VEHICLE_QUADROTOR,
            "version": 2,
        },
        "rallyPoints": {"points": [], "version": 2},
        "version": 1,
    }
    return json.dumps(document, indent=2, allow_nan=False) + "\n"


def read_plan(text: str, flavour: AnyAutopilot) -> tuple[list[MissionItem], GeoOrigin]:
    """A QGroundControl .plan -> (mission items in ``flavour``'s convention, home)."""
    _check_flavour(flavour)
    try:
        document = json.loads(text)
    except ValueError as exc:
        raise MissionError("plan", f"not JSON: {exc}") from None
    if not isinstance(document, dict) or document.get("fileType") != "Plan":
        raise MissionError("plan.fileType", "not a QGroundControl plan")
    mission = document.get("mission")
    if not isinstance(mission, dict):
        raise MissionError("plan.mission", "missing or not an object")
    home_raw = mission.get("plannedHomePosition")
    if not isinstance(home_raw, list) or len(home_raw) != 3:
        raise MissionError("plan.mission.plannedHomePosition", "must be [lat, lon, alt]")
    home = GeoOrigin(*(_number(v, "plan.mission.plannedHomePosition") for v in home_raw))
    raw_items = mission.get("items")
    if not isinstance(raw_items, list):
        raise MissionError("plan.mission.items", "missing or not a list")
    body = [_plan_item(i, raw) for i, raw in enumerate(raw_items)]
    return _join_home(home, body, flavour), home


def _plan_item(i: int, raw: Any) -> MissionItem:
    where = f"plan.mission.items[{i}]"
    if not isinstance(raw, dict) or raw.get("type") != "SimpleItem":
        # Complex items (surveys, corridor scans) need QGroundControl's own expansion.
        raise MissionError(where, "only SimpleItem entries are supported")
    params = raw.get("params")
    if not isinstance(params, list) or len(params) != 7:
        raise MissionError(f"{where}.params", "must be a list of 7 values")
    frame, command = raw.get("frame"), raw.get("command")
    for name, value in (("frame", frame), ("command", command)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise MissionError(f"{where}.{name}", f"{value!r} is not an integer")
    return MissionItem(
        seq=i, frame=frame, command=command, autocontinue=int(bool(raw.get("autoContinue", True))),
        param1=_number(params[0], f"{where}.params[0]"), param2=_number(params[1], f"{where}.params[1]"),
        param3=_number(params[2], f"{where}.params[2]"), param4=_number(params[3], f"{where}.params[3]"),
        x=_from_degrees(params[4], frame, f"{where}.params[4]"),
        y=_from_degrees(params[5], frame, f"{where}.params[5]"),
        z=_number(params[6], f"{where}.params[6]"),
    )


# --- WPL 110 --------------------------------------------------------------------------


def _wpl_number(value: float) -> str:
    return "nan" if math.isnan(value) else repr(float(value))


def write_wpl(items: Sequence[MissionItem], flavour: AnyAutopilot, home: GeoOrigin | None = None) -> str:
    """The mission as a WPL 110 text file (line 0 is home, as Mission Planner expects)."""
    home_pos, body = _split_home(items, flavour, home or GeoOrigin())
    lines = [WPL_HEADER]
    # Exactly one line is current (MAVSDK refuses a mission with none or two). ArduPilot's
    # item 0 keeps its own flag; for PX4 home is not an item: its line is current only when
    # no item is, as Mission Planner marks it.
    if _check_flavour(flavour).home_slots:
        home_current = items[0].current
    else:
        home_current = 0 if any(item.current for item in body) else 1
    home_line = _with(home_item(home_pos), current=home_current)
    for item in [home_line] + [_renumber(item, i + 1) for i, item in enumerate(body)]:
        x = _degrees(item.x, item.frame)
        y = _degrees(item.y, item.frame)
        fields = [
            str(item.seq), str(item.current), str(item.frame), str(item.command),
            _wpl_number(item.param1), _wpl_number(item.param2), _wpl_number(item.param3),
            _wpl_number(item.param4),
            f"{x:.8f}" if isinstance(x, float) else str(x),
            f"{y:.8f}" if isinstance(y, float) else str(y),
            _wpl_number(item.z), str(item.autocontinue),
        ]
        lines.append("\t".join(fields))
    return "\n".join(lines) + "\n"


def read_wpl(text: str, flavour: AnyAutopilot) -> tuple[list[MissionItem], GeoOrigin]:
    """A WPL 110 file -> (mission items in ``flavour``'s convention, home from line 0)."""
    _check_flavour(flavour)
    lines = [line for line in text.splitlines() if line.strip()]
    if not lines or not lines[0].startswith("QGC WPL 110"):
        raise MissionError("wpl.header", f"the first line must be {WPL_HEADER!r}")
    rows = [_wpl_item(n, line) for n, line in enumerate(lines[1:], start=2)]
    if not rows:
        raise MissionError("wpl", "no home line")
    home_row = rows[0]
    home = GeoOrigin(home_row.x / E7, home_row.y / E7, home_row.z)
    return _join_home(home, rows[1:], flavour, home_current=home_row.current), home


def _wpl_item(line_no: int, line: str) -> MissionItem:
    where = f"wpl.line[{line_no}]"
    fields = line.split("\t") if "\t" in line else line.split()
    if len(fields) != 12:
        raise MissionError(where, f"has {len(fields)} fields, expected 12")
    try:
        seq, current, frame, command = (int(v) for v in fields[:4])
        p1, p2, p3, p4 = (float(v) for v in fields[4:8])
        x, y, z = float(fields[8]), float(fields[9]), float(fields[10])
        autocontinue = int(fields[11])
    except ValueError as exc:
        raise MissionError(where, f"unreadable field: {exc}") from None
    return MissionItem(
        seq=seq, frame=frame, command=command, current=current, autocontinue=autocontinue,
        param1=p1, param2=p2, param3=p3, param4=p4,
        x=_from_degrees(x, frame, f"{where}.x"), y=_from_degrees(y, frame, f"{where}.y"), z=z,
    )
