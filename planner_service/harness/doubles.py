"""What two UAVs of a fleet did at once that the fleet's claims exist to prevent: holds over
one point (from the vehicles' reported positions side by side, whatever their layers: any
two for a second, and two hovering) and
services of one user whose holds overlapped (from the services' own events). A user served
by two UAVs one after the other is no fault: a second service is the fairness rule's to
allow."""

from __future__ import annotations

import math
import re
from typing import Iterable

from protocol import Event, Status

PAIR_WITHIN_S = 0.6
"""Two reports are side by side when this close in time (statuses come at 2 Hz)."""


HOVER_MPS = 2.0
"""A vehicle moving slower than this (its own time) hovers: a hold, not a leg flown."""


def stacked_holds(statuses: Iterable[Status], radius_m: float, rounds: int = 4, hovering_mps: float | None = None,
                  speedup: float = 1.0) -> list[str]:
    """Pairs of armed vehicles reported within ``radius_m`` of each other horizontally in at
    least ``rounds`` comparisons in a row (each report against the other's last: two a status
    period, so 4 is about a second; a crossing on different layers passes in one or two):
    ``"uav1-uav2 6 rounds"``, the longest run per pair. With ``hovering_mps``, only while both
    hover (each slower than that since its report before, in its own time: ``speedup`` times
    the wall's): two holding over one point, not one flying a leg over the other's hold."""
    last: dict[str, Status] = {}
    speed: dict[str, float] = {}
    run: dict[tuple[str, str], int] = {}
    longest: dict[tuple[str, str], int] = {}
    for s in sorted(statuses, key=lambda s: s.time_s):
        if not s.armed:
            last.pop(s.vehicle, None)
            continue
        before = last.get(s.vehicle)
        if before is not None and s.time_s > before.time_s:
            moved = ((s.x_m - before.x_m) ** 2 + (s.y_m - before.y_m) ** 2) ** 0.5
            speed[s.vehicle] = moved / ((s.time_s - before.time_s) * speedup)
        for other, o in last.items():
            if other == s.vehicle or s.time_s - o.time_s > PAIR_WITHIN_S:
                continue
            pair = (min(s.vehicle, other), max(s.vehicle, other))
            close = ((s.x_m - o.x_m) ** 2 + (s.y_m - o.y_m) ** 2) ** 0.5 < radius_m
            if hovering_mps is not None:
                close = close and all(speed.get(v, math.inf) < hovering_mps for v in pair)
            run[pair] = run.get(pair, 0) + 1 if close else 0
            longest[pair] = max(longest.get(pair, 0), run[pair])
        last[s.vehicle] = s
    return [f"{a}-{b} {n} rounds" for (a, b), n in sorted(longest.items()) if n >= rounds]


HELD = re.compile(r"held ([0-9.]+) s")
RECORDED = re.compile(r"recorded ([0-9.]+) s after the hold")


def served_at_once(events: Iterable[tuple[str, Event]], speedup: float) -> list[str]:
    """Users served by two UAVs whose holds overlapped in time (``user_served`` events: the
    hold ends at the event, or ``recorded X s after the hold`` before it (wall seconds: a
    fleet member records once its binding has settled), ``held X s`` of the vehicle's time
    before that, ``speedup`` times faster than the wall): ``"user-3 uav1+uav2"``."""
    holds: dict[str, list[tuple[float, float, str]]] = {}
    for vehicle, e in events:
        m = HELD.search(e.detail)
        if e.event == "user_served" and e.user_id and m:
            late = RECORDED.search(e.detail)
            end = e.time_s - (float(late[1]) if late else 0.0)
            holds.setdefault(e.user_id, []).append((end - float(m[1]) / speedup, end, vehicle))
    out = set()
    for user, spans in holds.items():
        for i, (a0, a1, va) in enumerate(spans):
            for b0, b1, vb in spans[i + 1:]:
                if va != vb and a0 < b1 and b0 < a1:
                    out.add(f"{user} {min(va, vb)}+{max(va, vb)}")
    return sorted(out)
