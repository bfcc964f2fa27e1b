"""The fleet's separation, judged on the vehicles' own positions (pure).

Each member publishes its vehicle's position as its autopilot reports it (``fleet_position``: metres
east, north and up of its own origin, which its announcement names); here they are put in
one frame and every pair of armed vehicles is judged by the fleet's one rule
(``airspace.separation_lost``: closer than ``min_horizontal_m`` horizontally while closer than
``vertical_separation_m`` vertically). A member whose position is not known or is stale is reported as such: unknown
is never "separated". Vehicles on the ground and disarmed are not judged (they stand at
their homes, which may lie close together).

A member whose service is gone (its token withdrawn) while its vehicle was last seen armed is
not forgotten: its vehicle may still be flying its uploaded mission, and no position will
come from it. It is reported unknown until its service is back (``lost``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Iterable, Mapping, Sequence

from protocol import GeoOrigin, global_to_local, local_to_global
from protocol.messages import FleetMember, FleetPosition

from .airspace import MIN_HORIZONTAL_M, VERTICAL_SEPARATION_M, separation_lost
STALE_S = 3.0
"""A position older than this (seconds since it arrived) is not known
(``fleet.position_stale_s``): it comes with each status, at 2 Hz or more."""


@dataclass(frozen=True)
class Seen:
    """A member's last position and when it arrived (the watcher's monotonic clock)."""

    position: FleetPosition
    at_s: float


@dataclass(frozen=True)
class Judgement:
    """Pairs that lost separation, and the members whose position is not known."""

    conflicts: tuple[str, ...]
    """"uav1-uav2: 12 m apart horizontally, 3 m vertically" for each pair too close."""
    unknown: tuple[str, ...]
    """"uav3: no position" or "uav3: position 5.2 s old" for each member not judged."""
    closest: str = ""
    """The closest armed pair's distance, for the operator ("" with fewer than two)."""


def origin_of(member: FleetMember) -> GeoOrigin:
    """The origin ``member``'s positions are measured from (its announcement's)."""
    return GeoOrigin(member.origin_lat_deg, member.origin_lon_deg, member.origin_alt_m)


def in_frame(frame: GeoOrigin, member: FleetMember, position: FleetPosition) -> tuple[float, float, float]:
    """``member``'s ``position`` (of its own origin) in metres east, north and up of ``frame``:
    as it is when the origins are one (the fleet's usual case: one area; ``global_to_local``
    is the exact inverse of ``local_to_global``, and the two cost 4 geodetic conversions, the
    largest share of a member's CPU at 20 UAVs)."""
    origin = origin_of(member)
    if origin == frame:
        return position.x_m, position.y_m, position.z_m
    return global_to_local(frame, *local_to_global(origin, position.x_m, position.y_m, position.z_m))


def whereabouts(frame: GeoOrigin, vehicles: Iterable[str], members: Mapping[str, FleetMember | None],
                seen: Mapping[str, Seen], now_s: float, stale_s: float = STALE_S) -> dict[str, tuple[float, float]]:
    """Where each of ``vehicles`` is (east, north of ``frame``) by its last position, if it
    is armed, fresh (``stale_s``) and its member announced: the others are left out."""
    out = {}
    for vehicle in vehicles:
        member, last = members.get(vehicle), seen.get(vehicle)
        if member is None or last is None or now_s - last.at_s > stale_s or not last.position.armed:
            continue
        x, y, _ = in_frame(frame, member, last.position)
        out[vehicle] = (x, y)
    return out


def occupied(where: Mapping[str, tuple[float, float]], points: Sequence[tuple[float, float]],
             radius_m: float) -> frozenset[int]:
    """The hovering points (indices into ``points``) within ``radius_m`` horizontally of a
    vehicle in ``where`` (another member's, from its signed positions: ``whereabouts``)."""
    r2 = radius_m * radius_m
    return frozenset(k for k, (px, py) in enumerate(points)
                     if any((x - px) ** 2 + (y - py) ** 2 <= r2 for x, y in where.values()))


def judge(members: Mapping[str, FleetMember | None], seen: Mapping[str, Seen], now_s: float,
          min_horizontal_m: float = MIN_HORIZONTAL_M, stale_s: float = STALE_S,
          lost: Mapping[str, Seen] | None = None,
          vertical_separation_m: float = VERTICAL_SEPARATION_M, silent: Mapping[str, Seen] | None = None) -> Judgement:
    """The separation of ``members`` (alive, with their announcements) from the positions
    ``seen`` of each, at ``now_s``; ``lost``: the last positions, armed, of members whose
    service is gone; ``silent``: of those whose announcements stopped, their tokens alive."""
    unknown = [f"{vehicle}: its service is gone; its vehicle was armed when last seen "
               f"{now_s - last.at_s:.0f} s ago" for vehicle, last in sorted((lost or {}).items())
               if vehicle not in members]
    unknown += [f"{vehicle}: not heard (its announcements stopped); its vehicle was armed when last seen "
                f"{now_s - last.at_s:.0f} s ago" for vehicle, last in sorted((silent or {}).items())
                if vehicle not in members and vehicle not in (lost or {})]
    where: dict[str, tuple[float, float, float]] = {}
    frame: GeoOrigin | None = None
    for vehicle, member in sorted(members.items()):
        last = seen.get(vehicle)
        if member is None or last is None:
            unknown.append(f"{vehicle}: no position" if member is not None else f"{vehicle}: no announcement")
            continue
        age = now_s - last.at_s
        if age > stale_s:
            unknown.append(f"{vehicle}: position {age:.1f} s old")
            continue
        if not last.position.armed:
            continue
        frame = frame or origin_of(member)
        where[vehicle] = in_frame(frame, member, last.position)
    conflicts, closest = [], ""
    best = float("inf")
    for (a, pa), (b, pb) in combinations(sorted(where.items()), 2):
        horizontal = ((pa[0] - pb[0]) ** 2 + (pa[1] - pb[1]) ** 2) ** 0.5
        vertical = abs(pa[2] - pb[2])
        text = f"{a}-{b}: {horizontal:.0f} m apart horizontally, {vertical:.0f} m vertically"
        if separation_lost(horizontal, vertical, min_horizontal_m, vertical_separation_m):
            conflicts.append(text)
        if horizontal < best:
            best, closest = horizontal, text
    return Judgement(tuple(conflicts), tuple(unknown), closest)
