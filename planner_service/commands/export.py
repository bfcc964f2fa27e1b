"""Write a mission as a WPL 110 file (MAVProxy ``wp load``, Mission Planner) or a
QGroundControl ``.plan``: a mission the service uploaded, read from its journal, or the path
of a ``plan --json`` summary.

The journal is opened read-only (``mode=ro``): a running service keeps writing it. With
``--journal`` the mission is the one recorded for ``--plan-id`` (the accepted upload if
there is one), or the last accepted mission when no plan id is given; its items are written
exactly as uploaded. With ``--plan-json`` the summary's trace becomes hovering points (each
interval's UAV position, held for the upload time of the user served there, S / R) encoded
as the service encodes them: takeoff, waypoints, return to launch.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys
from pathlib import Path
from typing import Any

HELP = "write a mission (from the service's journal or a plan --json summary) as WPL or .plan"


class ExportError(Exception):
    """The mission cannot be exported; says which input is wrong."""


def configure(parser: argparse.ArgumentParser) -> None:
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--journal", metavar="FILE", help="the service's SQLite journal (opened read-only)")
    source.add_argument("--plan-json", metavar="FILE",
                        help="a summary written by 'python -m planner_service plan --json' ('-' for stdin)")
    parser.add_argument("--plan-id", type=int, default=None, metavar="N",
                        help="with --journal: the plan to export (default: the last accepted mission)")
    parser.add_argument("--format", choices=("wpl", "plan"), default="wpl",
                        help="WPL 110 text (MAVProxy, Mission Planner) or a QGroundControl .plan (default %(default)s)")
    parser.add_argument("--flavour", choices=("ardupilot", "px4"), default="ardupilot",
                        help="the autopilot convention of the mission (ArduPilot keeps home in item 0) "
                             "(default %(default)s)")
    parser.add_argument("--origin", default=None, metavar="LAT,LON,ALT",
                        help="the service's [origin]: home for PX4 missions and the local frame of --plan-json "
                             "(default 47.397742,8.545594,488)")
    parser.add_argument("--out", required=True, metavar="FILE", help="where to write ('-' for stdout)")


def journal_items(path: Path, plan_id: int | None) -> list[Any]:
    """The mission items recorded in the journal at ``path`` (read-only)."""
    from planner_service.service.sortie import item_from_dict

    if not path.is_file():
        raise ExportError(f"--journal: {path} does not exist")
    try:
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    except sqlite3.Error as err:
        raise ExportError(f"--journal: cannot open {path}: {err}") from None
    try:
        if plan_id is None:
            rows = db.execute("SELECT plan_id, items FROM missions WHERE result = 'accepted' "
                              "ORDER BY mission_id DESC LIMIT 1").fetchall()
            if not rows:
                raise ExportError(f"--journal: {path} records no accepted mission")
        else:
            rows = db.execute("SELECT plan_id, items FROM missions WHERE plan_id = ? "
                              "ORDER BY result = 'accepted' DESC, mission_id DESC LIMIT 1", (plan_id,)).fetchall()
            if not rows:
                raise ExportError(f"--plan-id: no mission with plan id {plan_id} in {path}")
    except sqlite3.Error as err:
        raise ExportError(f"--journal: {path} is not a service journal ({err})") from None
    finally:
        db.close()
    try:
        return [item_from_dict(d) for d in json.loads(rows[0][1])]
    except (ValueError, TypeError) as err:
        raise ExportError(f"--journal: the items of plan {rows[0][0]} cannot be read: {err}") from None


def summary_points(summary: Any) -> list[Any]:
    """The hovering points of a ``plan --json`` summary: the UAV's position each interval,
    held for the upload of what the user served there sent (S / R)."""
    import numpy as np

    from planner_service.model import Scenario, pack
    from planner_service.service.planning import hold_time_s
    from protocol.mission import HoverPoint

    if not isinstance(summary, dict) or not isinstance(summary.get("trace"), list):
        raise ExportError("--plan-json: not a 'plan --json' summary (no 'trace')")
    try:
        scenario = Scenario(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in summary["scenario"].items()})
    except (KeyError, TypeError, ValueError) as err:
        raise ExportError(f"--plan-json: its 'scenario' cannot be read: {err}") from None
    p = pack(scenario)
    points = []
    for i, record in enumerate(summary["trace"]):
        try:
            uav = np.asarray(record["uav_xyz"], dtype=float)
            hold = 0.0
            if record.get("user") is not None and record.get("user", -1) >= 0 and record.get("bits", 0) > 0:
                hold = hold_time_s(p, uav, np.asarray(record["user_xyz"], dtype=float), float(record["bits"]))
        except (KeyError, TypeError, ValueError) as err:
            raise ExportError(f"--plan-json: trace[{i}] cannot be read: {err}") from None
        points.append(HoverPoint(float(uav[0]), float(uav[1]), float(uav[2]), hold))
    return points


def run(args: argparse.Namespace) -> int:
    from protocol.errors import MissionError
    from protocol.geodesy import GeoOrigin
    from protocol.mission import encode_path
    from protocol.mission_files import write_plan, write_wpl

    try:
        origin = GeoOrigin.parse(args.origin) if args.origin else GeoOrigin()
        if args.journal:
            items = journal_items(Path(args.journal), args.plan_id)
        else:
            if args.plan_id is not None:
                raise ExportError("--plan-id goes with --journal")
            text = sys.stdin.read() if args.plan_json == "-" else Path(args.plan_json).read_text()
            try:
                summary = json.loads(text)
            except ValueError as err:
                raise ExportError(f"--plan-json: not JSON: {err}") from None
            items = encode_path(summary_points(summary), origin, args.flavour)
        writer = write_wpl if args.format == "wpl" else write_plan
        document = writer(items, args.flavour, origin)
    except (ExportError, MissionError, OSError, ValueError) as err:
        print(f"export: {err}", file=sys.stderr)
        return 2
    if args.out == "-":
        sys.stdout.write(document)
    else:
        Path(args.out).write_text(document)
        print(f"wrote {len(items)} mission items to {args.out} ({args.format}, {args.flavour})", file=sys.stderr)
    return 0
