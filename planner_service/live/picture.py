"""The operator's one read model of the fleet (pure): what the services publish in, a picture
out, for ``operator watch`` (text), ``operator web`` (the live map) and GeoJSON.

Fed with the messages already on the wire (statuses, plans, events, users' places, the
services' liveliness, the fleet's members, claims and separation) and the observer's clocks;
it does no I/O and reads no clock, so every decision here has a millisecond test.

Positions are put in one frame: metres east and north of the picture's origin (the first
member's announced origin, or the one given). Each member states its own origin; a member
whose origin differs is shifted by the offset of its origin in the picture's tangent plane
(exact at the origins, centimetres over a field of a few kilometres).

Unknown stays unknown: a vehicle with no status has no position (it is not drawn at 0, 0); a
battery not reported is ``None``; a fleet with members but no judgement of their separation
is "unknown", never "ok".
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from protocol import Event, GeoOrigin, PendingRequest, Plan, Status, UserPlace, global_to_local
from protocol.messages import FleetMember

from ..service.fleet.separation import Judgement

TRAIL_POINTS = 200
"""Positions kept per vehicle for its trail (at 2 Hz: the last 100 s of flight, once it moves)."""
TRAIL_STEP_M = 2.0
"""A position closer than this to the last one kept adds nothing to the trail (a hold)."""
EVENTS_KEPT = 8
STATUS_STALE_S = 3.0
"""A status older than this (the observer's clock) is stale: the vehicle is drawn grey and
alerted on (the services publish at 2 Hz or more)."""
ALERT_EVENTS = ("authority_revoked", "degraded", "link_lost", "upload_failed", "command_failed")
"""The events that become an alert while they are the vehicle's last word on the matter."""


@dataclass
class VehicleRecord:
    """Everything heard of one vehicle's service."""

    vehicle: str
    status: Status | None = None
    status_at: float | None = None
    """When ``status`` arrived (the observer's monotonic clock)."""
    alive: bool | None = None
    """The service's liveliness token: seen, gone, or not yet known."""
    plan: Plan | None = None
    events: deque[Event] = field(default_factory=lambda: deque(maxlen=EVENTS_KEPT))
    trail: deque[tuple[float, float]] = field(default_factory=lambda: deque(maxlen=TRAIL_POINTS))
    """Positions in the vehicle's own frame, oldest first."""
    pending: list[PendingRequest] | None = None
    pending_note: str = ""
    """Why ``pending`` is not known ("" when it is)."""
    served_after_plan: set[str] = field(default_factory=set)
    """Users served (or skipped) since ``plan`` was made: the plan's next point is the first
    point whose user is not among them."""


@dataclass
class UserRecord:
    """One user as the services see it: where it asked from, and its place in a plan."""

    user_id: str
    x_m: float | None = None
    y_m: float | None = None
    frame_of: str | None = None
    """The vehicle in whose frame ``x_m``/``y_m`` were given (its pending request)."""
    places: dict[str, UserPlace] = field(default_factory=dict)
    """Each service's last place for this user."""


@dataclass(frozen=True)
class Alert:
    severity: str
    """"error" (act now: separation lost, authority revoked, degraded, a member gone armed) or
    "warning" (look: a stale status, a position not planned on, a clock)."""
    text: str
    vehicle: str | None = None


class FleetPicture:
    """The read model: ``on_*`` take what arrived (with the observer's clock), ``snapshot``
    and ``alerts`` give the picture at a moment."""

    def __init__(self, prefix: str, origin: GeoOrigin | None = None, trail_points: int = TRAIL_POINTS,
                 events_kept: int = EVENTS_KEPT) -> None:
        self.prefix = prefix
        self.origin = origin
        """The picture's frame; None until given or the first member announces its own."""
        self.trail_points = trail_points
        self.events_kept = events_kept
        self.vehicles: dict[str, VehicleRecord] = {}
        self.users: dict[str, UserRecord] = {}
        self.members: dict[str, FleetMember | None] = {}
        self.separation: Judgement | None = None
        self.claims: dict[str, list[str]] = {}
        self.lost: list[str] = []
        self.ignored = 0
        self.version = 0
        """Increases with every change: a page redraws when it moves."""

    # -- what arrived ---------------------------------------------------------------------

    def vehicle(self, vehicle: str) -> VehicleRecord:
        """The record of ``vehicle`` (made empty on first mention)."""
        record = self.vehicles.get(vehicle)
        if record is None:
            record = self.vehicles[vehicle] = VehicleRecord(vehicle, events=deque(maxlen=self.events_kept),
                                                            trail=deque(maxlen=self.trail_points))
        return record

    def on_status(self, vehicle: str, status: Status, at: float) -> None:
        v = self.vehicle(vehicle)
        v.status, v.status_at = status, at
        if status.position_ok:
            here = (status.x_m, status.y_m)
            if not v.trail or math.dist(v.trail[-1], here) >= TRAIL_STEP_M:
                v.trail.append(here)
        self.version += 1

    def on_plan(self, vehicle: str, plan: Plan) -> None:
        v = self.vehicle(vehicle)
        if v.plan is not None and plan.plan_id < v.plan.plan_id and plan.time_s <= v.plan.time_s:
            return  # an older plan arriving late (a cached publication)
        v.plan = plan
        v.served_after_plan = set()
        self.version += 1

    def on_event(self, vehicle: str, event: Event) -> None:
        v = self.vehicle(vehicle)
        v.events.append(event)
        if event.event in ("user_served", "waypoint_skipped") and event.user_id is not None:
            if v.plan is None or event.time_s >= v.plan.time_s:
                v.served_after_plan.add(event.user_id)
        self.version += 1

    def on_alive(self, vehicle: str, alive: bool) -> None:
        self.vehicle(vehicle).alive = alive
        self.version += 1

    def on_place(self, vehicle: str, place: UserPlace) -> None:
        user = self.users.setdefault(place.user_id, UserRecord(place.user_id))
        user.places[vehicle] = place
        self.version += 1

    def on_pending(self, vehicle: str, pending: list[PendingRequest] | None, note: str = "") -> None:
        """The service's pending requests (its state), or None and why they are not known."""
        v = self.vehicle(vehicle)
        v.pending, v.pending_note = pending, note
        for r in pending or ():  # where each user asked from: kept once its request is served
            user = self.users.setdefault(r.user_id, UserRecord(r.user_id))
            user.x_m, user.y_m, user.frame_of = r.x_m, r.y_m, vehicle
        self.version += 1

    def on_fleet(self, members: Mapping[str, FleetMember | None], separation: Judgement | None,
                 claims: Mapping[str, Iterable[str]], lost: Iterable[str] = (), ignored: int = 0) -> None:
        """The fleet as the roster and the claims' ledger see it (members with their layers,
        the separation judged on signed positions, what each member claims)."""
        members, claims = dict(members), {v: sorted(c) for v, c in claims.items()}
        lost = sorted(lost)
        if (members, separation, claims, lost, ignored) == (self.members, self.separation, self.claims, self.lost,
                                                            self.ignored):
            return
        self.members, self.separation, self.claims, self.lost, self.ignored = members, separation, claims, lost, ignored
        if self.origin is None:
            for m in (m for _, m in sorted(members.items()) if m is not None):
                self.origin = _origin(m)
                break
        self.version += 1

    # -- the picture ------------------------------------------------------------------------

    def shift(self, vehicle: str | None) -> tuple[float, float]:
        """What to add to ``vehicle``'s own coordinates to put them in the picture's frame."""
        member = self.members.get(vehicle) if vehicle is not None else None
        if member is None or self.origin is None:
            return 0.0, 0.0
        own = _origin(member)
        if own == self.origin:
            return 0.0, 0.0
        east, north, _ = global_to_local(self.origin, own.lat_deg, own.lon_deg, own.alt_m)
        return east, north

    def next_point(self, vehicle: str) -> int | None:
        """The index in the vehicle's plan of the point it flies to or holds at: the first
        whose user was not served (nor skipped) since the plan was made; None with no plan or
        when every point is behind it."""
        v = self.vehicles.get(vehicle)
        if v is None or v.plan is None:
            return None
        for i, p in enumerate(v.plan.points):
            if p.user_id is None or p.user_id not in v.served_after_plan:
                return i
        return None

    def eta(self, vehicle: str, index: int | None, now_wall: float) -> float | None:
        """Seconds until the vehicle reaches point ``index`` of its plan, by its service's own
        estimate (the user's place, made with the plan); None when not known."""
        v = self.vehicles.get(vehicle)
        if v is None or v.plan is None or index is None:
            return None
        user = v.plan.points[index].user_id
        place = self.users[user].places.get(vehicle) if user in self.users else None
        if place is None or place.eta_s is None or place.plan_id != v.plan.plan_id:
            return None
        return max(place.time_s + place.eta_s - now_wall, 0.0)

    def user_state(self, user: UserRecord) -> tuple[str, str | None, UserPlace | None]:
        """(state, the vehicle whose place counts, that place): "next" when it is the user of
        a vehicle's next point, "planned" with a place in a plan, "served" once served with
        no backlog left (by the newest word of a service on it), else "waiting"."""
        for vehicle in sorted(self.vehicles):
            i = self.next_point(vehicle)
            plan = self.vehicles[vehicle].plan
            if i is not None and plan is not None and plan.points[i].user_id == user.user_id:
                return "next", vehicle, user.places.get(vehicle)
        placed = sorted((p.time_s, v) for v, p in user.places.items() if p.place is not None)
        if placed:
            vehicle = placed[-1][1]
            return "planned", vehicle, user.places[vehicle]
        newest = max(user.places.items(), key=lambda vp: vp[1].time_s, default=(None, None))
        if newest[1] is not None and newest[1].backlog == 0 and any(p.services for p in user.places.values()):
            return "served", newest[0], newest[1]
        return "waiting", newest[0] if newest[0] is not None else user.frame_of, newest[1]

    def alerts(self, now: float) -> list[Alert]:
        """What the operator must see now (``now``: the observer's monotonic clock), the
        errors first."""
        out: list[Alert] = []
        j = self.separation
        if j is not None:
            out += [Alert("error", f"SEPARATION LOST {c}") for c in j.conflicts]
        out += [Alert("error", f"{v} left the fleet with its vehicle armed: its airspace is unknown", v)
                for v in self.lost]
        for name, v in sorted(self.vehicles.items()):
            s = v.status
            if v.alive is False:
                armed = s is not None and s.armed
                out.append(Alert("error" if armed else "warning",
                                 "service gone" + (" with its vehicle armed" if armed else ""), name))
            if s is None:
                continue
            if s.degraded:
                out.append(Alert("error", f"DEGRADED {s.degraded}", name))
            if s.authority == "revoked":
                out.append(Alert("error", f"authority revoked: {s.authority_detail}", name))
            if v.status_at is not None and now - v.status_at > STATUS_STALE_S and v.alive is not False:
                out.append(Alert("warning", f"no status for {now - v.status_at:.0f} s", name))
            if s.armed and not s.position_ok:
                out.append(Alert("warning", "position not known to the service (not planned on)", name))
            if s.battery_fraction is None and s.armed:
                out.append(Alert("warning", "battery unknown", name))
        if j is not None:
            out += [Alert("warning", f"separation unknown: {u}") for u in j.unknown]
        if self.ignored:
            out.append(Alert("warning", f"{self.ignored} fleet messages ignored (not enrolled, unsigned, stale or "
                                        "replayed)"))
        return sorted(out, key=lambda a: a.severity != "error")

    def separation_state(self) -> str:
        """"none" for a lone UAV (no members), "lost", "unknown" or "ok"."""
        j = self.separation
        if not self.members and not self.lost:
            return "none"
        if j is None or j.unknown and not j.conflicts:
            return "unknown"
        return "lost" if j.conflicts else "ok"

    def snapshot(self, now: float, now_wall: float) -> dict[str, Any]:
        """The whole picture as JSON-ready data (the live map's schema, docs/LIVE-MAP.md):
        ``now`` the observer's monotonic clock, ``now_wall`` its wall clock."""
        o = self.origin
        return {
            "prefix": self.prefix, "time_s": now_wall, "version": self.version,
            "frame": {"origin": None if o is None else {"lat_deg": o.lat_deg, "lon_deg": o.lon_deg, "alt_m": o.alt_m}},
            "vehicles": [self._vehicle_json(name, now, now_wall) for name in sorted(self.vehicles)],
            "users": [self._user_json(u, now_wall) for _, u in sorted(self.users.items())],
            "separation": self._separation_json(),
            "alerts": [{"severity": a.severity, "vehicle": a.vehicle, "text": a.text} for a in self.alerts(now)],
            "ignored": self.ignored,
        }

    def _vehicle_json(self, name: str, now: float, now_wall: float) -> dict[str, Any]:
        v = self.vehicles[name]
        s, (dx, dy) = v.status, self.shift(name)
        member = self.members.get(name)
        out: dict[str, Any] = {
            "id": name, "alive": v.alive, "status_age_s": None if v.status_at is None else max(now - v.status_at, 0.0),
            "layer_m": None if member is None else member.layer_m, "claims": self.claims.get(name, []),
            "trail": [[x + dx, y + dy] for x, y in v.trail],
            "events": [{"time_s": e.time_s, "event": e.event, "user_id": e.user_id, "detail": e.detail}
                       for e in v.events],
            "plan": None,
        }
        if s is not None:
            out.update(x_m=s.x_m + dx, y_m=s.y_m + dy, z_m=s.z_m, phase=s.phase, mode=s.mode, armed=s.armed,
                       battery=s.battery_fraction, battery_source=s.battery_source, authority=s.authority,
                       authority_detail=s.authority_detail, position_ok=s.position_ok, degraded=s.degraded,
                       waiting_for=s.waiting_for, mission_seq=s.mission_seq, mission_total=s.mission_total,
                       pending_requests=s.pending_requests, served_users=s.served_users)
        else:
            out.update(x_m=None, y_m=None, z_m=None, phase=None, mode=None, armed=None, battery=None,
                       battery_source="unknown", authority=None, authority_detail="", position_ok=False, degraded="",
                       waiting_for="", mission_seq=0, mission_total=0, pending_requests=None, served_users=None)
        if v.plan is not None:
            i = self.next_point(name)
            out["plan"] = {"plan_id": v.plan.plan_id, "next": i, "eta_s": self.eta(name, i, now_wall),
                           "points": [{"x_m": p.x_m + dx, "y_m": p.y_m + dy, "z_m": p.z_m, "hold_s": p.hold_s,
                                       "user_id": p.user_id} for p in v.plan.points]}
        return out

    def _user_json(self, user: UserRecord, now_wall: float) -> dict[str, Any]:
        state, vehicle, place = self.user_state(user)
        dx, dy = self.shift(user.frame_of)
        eta = None
        if place is not None and place.eta_s is not None:
            eta = max(place.time_s + place.eta_s - now_wall, 0.0)
        return {
            "id": user.user_id, "x_m": None if user.x_m is None else user.x_m + dx,
            "y_m": None if user.y_m is None else user.y_m + dy, "vehicle": vehicle, "state": state,
            "place": None if place is None else place.place, "eta_s": eta,
            "backlog": None if place is None else place.backlog,
            "served_tasks": sum(p.served_tasks for p in user.places.values()),
            "services": sum(p.services for p in user.places.values()),
        }

    def _separation_json(self) -> dict[str, Any]:
        j = self.separation
        return {"state": self.separation_state(), "conflicts": list(j.conflicts) if j else [],
                "unknown": list(j.unknown) if j else [], "closest": j.closest if j else ""}


def _origin(member: FleetMember) -> GeoOrigin:
    return GeoOrigin(member.origin_lat_deg, member.origin_lon_deg, member.origin_alt_m)
