"""What the vehicle really flew against what the service recorded: a service counts only if
the vehicle's own position log (the stub's ``--track``, ``stub_track``; SITL's dataflash POS
messages, ``sitl_track``) shows it within ``radius_m`` of the service's hovering point for
as long as the upload recorded needs, less a stated tolerance (the service judges holds from
position reports a reporting gap apart, and ArduPilot holds whole seconds).

``false_services`` returns a line for each service the log does not bear out; an empty
list is the pass. Services are matched in order to the vehicle's stays at their points, one
stay per service, each after the one before."""

from __future__ import annotations

import math
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from planner_service.model import Scenario, pack
from planner_service.service.planning import hold_time_s
from protocol import GeoOrigin, global_to_local


@dataclass(frozen=True)
class Fix:
    """The vehicle's position at a time of its own clock (seconds), local metres."""

    time_s: float
    xyz: tuple[float, float, float]


@dataclass(frozen=True)
class Recorded:
    """A service as the journal holds it, with where its user was."""

    service_id: int
    user_id: str
    tasks: int
    point: tuple[float, float, float]
    user: tuple[float, float, float]


def stays(track: Sequence[Fix], point: tuple[float, float, float], radius_m: float) -> list[tuple[float, float]]:
    """The (start, end) vehicle times of each stretch the track stays within ``radius_m``
    of ``point`` (consecutive fixes inside)."""
    out: list[tuple[float, float]] = []
    start: float | None = None
    last = 0.0
    for fix in track:
        inside = math.dist(fix.xyz, point) <= radius_m
        if inside and start is None:
            start = fix.time_s
        if not inside and start is not None:
            out.append((start, last))
            start = None
        last = fix.time_s
    if start is not None:
        out.append((start, last))
    return out


def false_services(services: Iterable[Recorded], track: Sequence[Fix], scenario: Scenario, radius_m: float,
                   tolerance_s: float) -> list[str]:
    """The services the track does not bear out, each in words."""
    p = pack(scenario)
    problems = []
    after = -math.inf
    for s in services:
        needed = hold_time_s(p, np.array(s.point), np.array(s.user), s.tasks * scenario.bits_per_task)
        found = [(a, b) for a, b in stays(track, s.point, radius_m) if a >= after]
        long_enough = [(a, b) for a, b in found if b - a >= needed - tolerance_s]
        if not long_enough:
            best = max((b - a for a, b in found), default=0.0)
            problems.append(f"service {s.service_id} ({s.user_id}, {s.tasks} tasks at {tuple(round(v) for v in s.point)}) "
                            f"needs {needed:.1f} s within {radius_m} m; the vehicle stayed at most {best:.1f} s there "
                            f"{'after the last service' if found else '(never came)'}")
            continue
        after = long_enough[0][1]
    return problems


def recorded_services(journal: Path, sortie: int | None = None) -> list[Recorded]:
    """The services of a journal (read-only, beside a running service), with the positions
    of the requests they served."""
    db = sqlite3.connect(f"file:{journal}?mode=ro", uri=True)
    try:
        where = "WHERE s.sortie = ?" if sortie is not None else ""
        rows = db.execute(
            "SELECT s.service_id, s.user_id, s.tasks, s.x_m, s.y_m, s.z_m, r.x_m, r.y_m, r.z_m FROM services s "
            f"JOIN requests r ON r.request_id = s.request_id {where} ORDER BY s.service_id",
            (sortie,) if sortie is not None else ()).fetchall()
    finally:
        db.close()
    return [Recorded(int(r[0]), r[1], int(r[2]), (r[3], r[4], r[5]), (r[6], r[7], r[8])) for r in rows]


def one_clock(fixes: Iterable[Fix]) -> list[Fix]:
    """``fixes`` in the order they were logged, on one clock: where the clock steps back (a
    new boot of the autopilot, or a stub restarted from the flight it saved a moment before
    it was killed), the later fixes are moved on to 1 s past the last one, so that
    ``false_services``, which matches services to stays in time order, sees them after it."""
    out: list[Fix] = []
    offset = 0.0
    last = -math.inf
    for fix in fixes:
        t = fix.time_s + offset
        if t < last:
            offset = last + 1.0 - fix.time_s
            t = last + 1.0
        last = t
        out.append(Fix(t, fix.xyz))
    return out


def stub_track(path: Path) -> list[Fix]:
    """The stub's ``--track`` file as fixes (airborne or not), on one clock (``one_clock``)."""
    from sim_bridge.vehicle.track import read_track

    return one_clock(Fix(p.time_s, p.xyz) for p in read_track(path))


def sitl_track(log_messages: Iterable[Mapping[str, Any]], origin: GeoOrigin) -> list[Fix]:
    """ArduPilot's own flight from its dataflash POS messages (``Sitl.read_log``, oldest
    first; other kinds are skipped), local metres from ``origin`` (the service's, which is
    SITL's ``--home``), the height above home as the service takes it (RelHomeAlt, as
    GLOBAL_POSITION_INT's relative altitude). Times are the autopilot's clock (TimeUS); a
    restarted autopilot counts from 0 again in a new log: each boot's times are moved on
    past the last one's (``one_clock``)."""
    return one_clock(Fix(m["TimeUS"] / 1e6, global_to_local(origin, m["Lat"], m["Lng"], origin.alt_m + m["RelHomeAlt"]))
                     for m in log_messages if m.get("mavpackettype") == "POS")


def px4_track(fixes: Iterable[Any], origin: GeoOrigin) -> list[Fix]:
    """PX4's own flight from the GLOBAL_POSITION_INT it sent the harness's monitor on its
    ground-station link (``Px4.fixes``: another link than the service's), local metres from
    ``origin`` (PX4's home), the height above home (relative_alt); times are PX4's clock
    (time_boot_ms), each boot moved on past the last (``one_clock``)."""
    return one_clock(Fix(f.boot_ms / 1e3, global_to_local(origin, f.lat_e7 / 1e7, f.lon_e7 / 1e7,
                                                          origin.alt_m + f.relative_alt_mm / 1e3))
                     for f in fixes)
