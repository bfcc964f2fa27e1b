"""The operator's live view (``python -m planner_service operator watch``), pure: what the
service last published (status, plan, events) and answered (the state's pending requests)
in, plain text lines out. No terminal control here: the command decides how to redraw.

Every text from the wire (modes, user ids, details, the degraded reason) goes through
``protocol.text.printable``: a peer that publishes an ESC sequence or a newline shows as
escapes, it cannot rewrite the operator's screen or forge a line.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

from protocol import Event, PendingRequest, Plan, Status
from protocol.messages import FleetMember

from .service.fleet.separation import Judgement
from protocol.text import printable

MAX_POINTS_SHOWN = 8
MAX_PENDING_SHOWN = 8


@dataclass
class WatchView:
    """What the operator's view knows; updated by the subscriptions, read by ``render``."""

    vehicle: str
    status: Status | None = None
    status_at: float | None = None
    """When ``status`` arrived (the view's monotonic clock)."""
    plan: Plan | None = None
    events: deque[Event] = field(default_factory=lambda: deque(maxlen=8))
    pending: list[PendingRequest] | None = None
    pending_note: str = ""
    """Why ``pending`` is not known ("" when it is)."""
    alive: bool | None = None
    """The service's liveliness token: seen, gone, or not yet known."""
    fleet: dict[str, FleetMember | None] = field(default_factory=dict)
    """The fleet's members alive under the prefix and their layers (None: not read yet);
    empty for a lone UAV."""
    separation: Judgement | None = None
    """The fleet's separation on the members' own positions (None for a lone UAV)."""
    claims: dict[str, list[str]] = field(default_factory=dict)
    """The users each live member claims (its next point's and its hold's)."""
    fleet_ignored: int = 0
    """Fleet messages and tokens ignored (not enrolled, unsigned, stale, replayed, beyond the
    bounds): a rogue peer at work, or a member missing from the watch's roster."""


def _t(text: object, limit: int = 80) -> str:
    return printable(text, limit)


def _clock(time_s: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(time_s)) if time_s > 0 else "--:--:--"


def render(view: WatchView, now: float) -> list[str]:
    """The view as lines of plain text (no control characters), newest events last."""
    alive = {None: "not seen yet", True: "alive", False: "GONE (liveliness withdrawn)"}[view.alive]
    age = "no status yet" if view.status_at is None else f"status {max(now - view.status_at, 0.0):.1f} s old"
    lines = [f"{_t(view.vehicle, 64)}: service {alive}; {age}"]
    if view.status is not None:
        lines += status_lines(view.status)
    lines += _fleet_lines(view)
    lines += _plan_lines(view.plan)
    lines += _pending_lines(view)
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


def _fleet_lines(view: WatchView) -> list[str]:
    """One line for the fleet's members (none for a lone UAV): vehicle, layer, this one."""
    ignored = [f"fleet      {view.fleet_ignored} messages ignored (not enrolled, unsigned, stale or replayed)"]
    if not view.fleet:
        return ignored if view.fleet_ignored else []
    this = view.vehicle.rsplit("/", 1)[-1]

    def one(vehicle: str, m: FleetMember | None) -> str:
        layer = "layer unknown" if m is None else f"{m.layer_m:g} m"
        return f"{_t(vehicle, 64)} {layer}" + (" (this)" if vehicle == this else "")
    lines = [f"fleet      {len(view.fleet)} member{'s' if len(view.fleet) != 1 else ''}: "
             + ", ".join(one(v, m) for v, m in sorted(view.fleet.items()))]
    claimed = [f"{_t(v, 64)} {', '.join(_t(u, 64) for u in users)}" for v, users in sorted(view.claims.items())
               if v in view.fleet and users]
    if claimed:
        lines.append("claims     " + "; ".join(claimed))
    if view.fleet_ignored:
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


def _pending_lines(view: WatchView) -> list[str]:
    if view.pending is None:
        return [f"pending    {_t(view.pending_note, 120) or 'not known yet'}"]
    if not view.pending:
        return ["pending    none"]
    shown = ", ".join(f"{_t(r.user_id, 64)} ({r.tasks} tasks at {r.x_m:.0f}, {r.y_m:.0f})"
                      for r in view.pending[:MAX_PENDING_SHOWN])
    more = f", and {len(view.pending) - MAX_PENDING_SHOWN} more" if len(view.pending) > MAX_PENDING_SHOWN else ""
    return [f"pending    {len(view.pending)}: {shown}{more}"]
