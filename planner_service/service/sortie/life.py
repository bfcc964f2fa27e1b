"""Where a sortie is in its life: its number, started, flown, over, the next one asked for,
and the service's own condition (warming up, degraded). Pure.

Its fields change together with the vehicle's take-off, landing and the journal's answers;
a new sortie is a new ``Life``."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .. import events as ev
from ..link.telemetry import AIRBORNE_ALT_M
from . import effects as fx
from . import inputs as ins
from .authority import Authority

FLOWN_HEIGHT_M = AIRBORNE_ALT_M
"""Metres above home the vehicle's own position must show, while its autopilot reports it in
the air, before the sortie counts as flown (and a landing ends it). PX4's land detector can say
"in the air" for a moment at an arming on the ground (Takeoff detected, then Landing detected
within milliseconds): the autopilot's word alone is a belief, the height is the vehicle's. The
height the link's own landed state takes where the autopilot gives none."""

START_LAPSE_S = 5.0
"""Wall seconds after an accepted start before a vehicle still on the ground, disarmed, is
taken as not started."""


@dataclass(frozen=True)
class Life:
    """The sortie's life cycle."""

    number: int = 1
    over: str | None = None
    """Why the sortie ended; None while it runs."""
    flown: bool = False
    """The vehicle has been airborne in this sortie (so a landing ends it)."""
    started: bool = False
    """The mission was started (by the service or, seen airborne, by someone)."""
    started_at: float = -math.inf
    beginning: bool = False
    """The next sortie was asked of the journal (``BeginSortie``)."""
    next_authority: Authority | None = None
    """The authority the next sortie begins with, when the operator gave it."""
    services: int = 0
    """Services recorded in this sortie (the interval count)."""
    just_started: bool = False
    """The service has just started (restored from its journal) and has not yet seen whether
    the vehicle is in the air: if it is, the authority ends."""
    disarmed_at: float | None = None
    """When a disarming on the service's own return, not yet reported landed, was seen
    (``_disarm_check``)."""
    return_seen_at: float | None = None
    """When the autopilot's switch to the return mode of the held mission's return item was
    seen before its MISSION_CURRENT showed that item (``_return_check``)."""
    homing: bool = False
    """The vehicle was seen on the service's own way home (``_homing``)."""
    degraded: str | None = None
    warming: bool = False
    """The planner's kernels are being compiled: no plan, no start until they are."""

    def airborne(self, v: ins.VehicleSnapshot) -> tuple[Life, list[fx.Effect]]:
        """The vehicle is seen in the air, its autopilot says so and its height shows it: this
        sortie has flown (the journal notes it, so a landing while the service is down still
        ends it)."""
        if self.flown or self.over is not None or not flying(v):
            return self, []
        return replace(self, flown=True), [fx.MarkFlown()]

    def ended(self, why: str) -> tuple[Life, list[fx.Effect]]:
        return replace(self, over=why), [fx.EndSortie(why)]

    def next_wanted(self, v: ins.VehicleSnapshot, *, repeat: bool,
                    next_battery_fraction: float) -> tuple[Life, list[fx.Effect]]:
        """Ask for the next sortie once the vehicle is ready again: on the ground, disarmed,
        its battery swapped or charged (a known reading)."""
        if self.over is None or not repeat or self.degraded is not None or self.beginning:
            return self, []
        if not (v.connected and v.position_ok) or v.airborne or v.armed:
            return self, []
        if v.battery_source != "autopilot" or v.battery_fraction is None or v.battery_fraction < next_battery_fraction:
            return self, []
        return replace(self, beginning=True), [fx.BeginSortie(v.battery_fraction)]

    def started_now(self, now: float) -> Life:
        return replace(self, started=True, started_at=now)

    def start_lapsed(self, v: ins.VehicleSnapshot, now: float, granted: bool) -> tuple[Life, list[fx.Effect]]:
        """A start the autopilot accepted but that never took off (it disarmed on the ground
        again: its own auto-disarm, a refused takeoff, the ground crew) is not started: the
        disarming ended the authority (``_arming``), and the operator's start starts it again."""
        if (not self.started or self.flown or v.airborne or v.armed or not v.landed_known
                or now - self.started_at < START_LAPSE_S):
            return self, []
        then = "starting it again" if granted else "the operator's start starts it again"
        return replace(self, started=False), [
            fx.Log("warning", f"the vehicle is on the ground and disarmed after the mission was started: {then}")]

    def degrade(self, why: str) -> tuple[Life, list[fx.Effect]]:
        """A part of the service failed: no more plans nor commands (the first reason stays)."""
        if self.degraded is not None:
            return self, []
        return replace(self, degraded=why), [fx.Emit(ev.Degraded(why[:256])), fx.Log("error", f"degraded: {why}")]

    def served(self) -> Life:
        return replace(self, services=self.services + 1)

    def start_refusal(self, v: ins.VehicleSnapshot) -> str | None:
        """Why the operator's start cannot be taken now, or None."""
        if self.degraded is not None:
            return f"the service is degraded: {self.degraded}"
        if not v.connected:
            return "the autopilot is not connected"
        if self.over is not None and (v.airborne or v.armed):
            return f"sortie {self.number} is over and the vehicle is not on the ground and disarmed"
        if not v.airborne and not v.position_ok:
            return "the autopilot has no position yet"
        if not v.airborne and v.battery_source != "autopilot":
            return f"the battery's charge is {v.battery_source}: no arming on it"
        return None

    def next_sortie(self, number: int) -> Life:
        """The life of sortie ``number``: only the planner's warming carries over."""
        return Life(number=number, warming=self.warming)


def flying(v: ins.VehicleSnapshot) -> bool:
    """In the air by the autopilot's word and off the ground by the vehicle's own position."""
    return v.airborne and v.position_ok and v.xyz[2] >= FLOWN_HEIGHT_M
