"""The operator's live view as text (``python -m planner_service operator watch``), pure: one
vehicle of the fleet picture (``live.picture``, the live map's read model too: what the
services published and answered) in, plain text lines out. No terminal control here: the
command decides how to redraw.

Every text from the wire (modes, user ids, details, the degraded reason) goes through
``protocol.text.printable``: a peer that publishes an ESC sequence or a newline shows as
escapes, it cannot rewrite the operator's screen or forge a line.
"""

from __future__ import annotations

import time

from protocol import PendingRequest, Plan, Status
from protocol.messages import FleetMember
from protocol.text import printable

from .live.picture import FleetPicture, VehicleRecord

MAX_POINTS_SHOWN = 8
MAX_PENDING_SHOWN = 8


def _t(text: object, limit: int = 80) -> str:
    return printable(text, limit)


def _clock(time_s: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(time_s)) if time_s > 0 else "--:--:--"


def render(picture: FleetPicture, vehicle: str, now: float) -> list[str]:
    """``vehicle``'s view as lines of plain text (no control characters), newest events last;
    ``now``: the monotonic clock the picture was fed with."""
    view = picture.vehicles.get(vehicle) or VehicleRecord(vehicle)
    alive = {None: "not seen yet", True: "alive", False: "GONE (liveliness withdrawn)"}[view.alive]
    age = "no status yet" if view.status_at is None else f"status {max(now - view.status_at, 0.0):.1f} s old"
    lines = [f"{_t(picture.prefix, 64)}/{_t(vehicle, 64)}: service {alive}; {age}"]
    if view.status is not None:
        lines += status_lines(view.status)
    lines += _fleet_lines(picture, vehicle)
    lines += _plan_lines(view.plan)
    lines += _pending_lines(view.pending, view.pending_note)
    lines.append("events" if view.events else "events     none yet")
    for ev in view.events:
        who = f" {_t(ev.user_id, 64)}" if ev.user_id else ""
        rid = f" request {ev.request_id}" if ev.request_id is not None else ""
        detail = f": {_t(ev.detail, 100)}" if ev.detail else ""
        lines.append(f"  {_clock(ev.time_s)} {_t(ev.event, 32)}{who}{rid}{detail}")
    return lines


def status_lines(s: Status) -> list[str]:
    """A status as lines: phase and mode, authority, battery and its source, position and
    whether it is planned on, mission progress, what the service waits for, degraded."""
    battery = "unknown" if s.battery_fraction is None else f"{s.battery_fraction:.0%}"
    lines = [
        f"phase      {_t(s.phase, 32):<12} mode {_t(s.mode, 32) or '-':<14} armed {'yes' if s.armed else 'no'}",
        f"authority  {_t(s.authority, 32)}: {_t(s.authority_detail, 120) or '-'}",
        f"battery    {battery} ({_t(s.battery_source, 32)})",
        f"position   x {s.x_m:.1f}  y {s.y_m:.1f}  z {s.z_m:.1f} m  "
        f"({'ok' if s.position_ok else 'NOT OK: not planned on'})",
        f"mission    item {s.mission_seq} of {s.mission_total}; {s.pending_requests} requests pending, "
        f"{s.served_users} users served",
    ]
    if s.waiting_for:
        lines.append(f"waiting    for {_t(s.waiting_for, 120)}")
    if s.degraded:
        lines.append(f"DEGRADED   {_t(s.degraded, 160)}")
    return lines


def _fleet_lines(view: FleetPicture, this: str) -> list[str]:
    """One line for the fleet's members (none for a lone UAV): vehicle, layer, this one."""
    ignored = [f"fleet      {view.ignored} messages ignored (not enrolled, unsigned, stale or replayed)"]
    if not view.members:
        return ignored if view.ignored else []

    def one(vehicle: str, m: FleetMember | None) -> str:
        layer = "layer unknown" if m is None else f"{m.layer_m:g} m"
        return f"{_t(vehicle, 64)} {layer}" + (" (this)" if vehicle == this else "")
    lines = [f"fleet      {len(view.members)} member{'s' if len(view.members) != 1 else ''}: "
             + ", ".join(one(v, m) for v, m in sorted(view.members.items()))]
    claimed = [f"{_t(v, 64)} {', '.join(_t(u, 64) for u in users)}" for v, users in sorted(view.claims.items())
               if v in view.members and users]
    if claimed:
        lines.append("claims     " + "; ".join(claimed))
    if view.ignored:
        lines += ignored
    j = view.separation
    if j is not None:
        lines += [f"SEPARATION LOST {_t(c, 120)}" for c in j.conflicts]
        lines += [f"separation unknown: {_t(u, 120)}" for u in j.unknown]
        if not j.conflicts and not j.unknown:
            lines.append(f"separation ok{': closest ' + _t(j.closest, 120) if j.closest else ''}")
    return lines


def _plan_lines(plan: Plan | None) -> list[str]:
    if plan is None:
        return ["plan       none yet"]
    lines = [f"plan {plan.plan_id:<5} {len(plan.points)} points, {plan.predicted_energy_j / 1e3:.1f} kJ predicted, "
             f"made {_clock(plan.time_s)}" + (":" if plan.points else "")]
    for i, p in enumerate(plan.points[:MAX_POINTS_SHOWN], 1):
        who = _t(p.user_id, 64) if p.user_id else "-"
        lines.append(f"  {i:>2}. ({p.x_m:.0f}, {p.y_m:.0f}, {p.z_m:.0f}) hold {p.hold_s:.0f} s  {who}")
    if len(plan.points) > MAX_POINTS_SHOWN:
        lines.append(f"      ... {len(plan.points) - MAX_POINTS_SHOWN} more, then return to launch")
    elif plan.points:
        lines.append("      then return to launch")
    return lines


def _pending_lines(pending: list[PendingRequest] | None, note: str) -> list[str]:
    if pending is None:
        return [f"pending    {_t(note, 120) or 'not known yet'}"]
    if not pending:
        return ["pending    none"]
    shown = ", ".join(f"{_t(r.user_id, 64)} ({r.tasks} tasks at {r.x_m:.0f}, {r.y_m:.0f})"
                      for r in pending[:MAX_PENDING_SHOWN])
    more = f", and {len(pending) - MAX_PENDING_SHOWN} more" if len(pending) > MAX_PENDING_SHOWN else ""
    return [f"pending    {len(pending)}: {shown}{more}"]
