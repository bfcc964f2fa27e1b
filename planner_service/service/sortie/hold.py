"""Whether the vehicle really held at a point, judged from its own position reports. Pure.

A service is recorded only when the vehicle's position shows the hold: it flew the point's
mission item, came within ``radius_m`` of the point, and stayed there. The watch is fed
every position report (the vehicle's own clock, ``boot_s``) with the item the vehicle flies
then; it notes the first and the last report inside the radius and ends when the vehicle
leaves: a report outside the radius after arriving, a later item, or its clock going back
(a restart). ``held_s`` is the time between the first and the last report inside: a lower
bound of the true hold. The vehicle came inside at most ``arrival_gap_s`` before it was
first seen there (the gap between the reports around its arrival): ``covered_s`` adds that
gap, the estimate the service records a hold by, with the reporting rate as its stated
tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

Phase = Literal["approaching", "holding", "left", "passed"]

MAX_ARRIVAL_GAP_S = 5.0
"""The arrival's reporting gap counts at most this much (a longer silence, a link gap, says
nothing about when the vehicle arrived)."""


@dataclass(frozen=True)
class Sample:
    """One position report of the vehicle: its clock, local metres, the item it flies."""

    boot_s: float
    xyz: tuple[float, float, float]
    seq: int


@dataclass(frozen=True)
class HoldWatch:
    """The watch over one mission item ``seq`` at ``xyz``."""

    seq: int
    xyz: tuple[float, float, float]
    radius_m: float
    phase: Phase = "approaching"
    arrived_s: float = math.nan
    """Vehicle time of the first report inside the radius while flying ``seq``."""
    last_in_s: float = math.nan
    """Vehicle time of the last report inside the radius."""
    last_s: float = math.nan
    """Vehicle time of the latest report, inside or not."""
    arrival_gap_s: float = 0.0
    """Vehicle seconds between the last report before the arrival and the first inside."""
    why_left: str = ""
    abandoned: bool = False
    """Ended from outside (a restart, a lost mission), not by the reports."""
    approached: bool = False
    """A report showed the vehicle outside the radius before it arrived: the arrival was
    seen (not so for a watch begun with the vehicle already there, after a restart of ours)."""

    @property
    def arrived(self) -> bool:
        return self.phase in ("holding", "left")

    @property
    def over(self) -> bool:
        return self.phase in ("left", "passed")

    @property
    def held_s(self) -> float:
        """Vehicle seconds between the first and the last report inside the radius."""
        return self.last_in_s - self.arrived_s if self.arrived else 0.0

    @property
    def covered_s(self) -> float:
        """The hold as the reports show it, the arrival's reporting gap included; only what
        was seen if the watch was abandoned (when the vehicle left is then unknown)."""
        if not self.arrived:
            return 0.0
        return self.held_s if self.abandoned else self.held_s + self.arrival_gap_s

    def feed(self, s: Sample) -> "HoldWatch":
        """The watch after report ``s`` (reports older than the last are ignored, except a
        clock gone far back: the vehicle restarted and is not holding for us any more)."""
        if self.over:
            return self
        if not math.isnan(self.last_s) and s.boot_s < self.last_s:
            if self.last_s - s.boot_s > 5.0:
                return self._end("the vehicle's clock went back (a restart)", s.boot_s)
            return self  # a reordered report: older than what is known
        inside = math.dist(s.xyz, self.xyz) <= self.radius_m
        gap = s.boot_s - self.last_s if not math.isnan(self.last_s) else 0.0
        if self.phase == "approaching":
            if s.seq > self.seq:
                return replace(self, phase="passed", last_s=s.boot_s, why_left=f"item {s.seq} flown before arriving")
            if s.seq == self.seq and inside:
                return replace(self, phase="holding", arrived_s=s.boot_s, last_in_s=s.boot_s, last_s=s.boot_s,
                               arrival_gap_s=min(gap, MAX_ARRIVAL_GAP_S) if self.approached else 0.0)
            return replace(self, last_s=s.boot_s, approached=self.approached or not inside)
        # holding
        if s.seq > self.seq:
            return self._end(f"item {s.seq} flown next", s.boot_s)
        if not inside:
            return self._end(f"{math.dist(s.xyz, self.xyz):.1f} m from the point", s.boot_s)
        return replace(self, last_in_s=s.boot_s, last_s=s.boot_s)

    def abandon(self, why: str) -> "HoldWatch":
        """End the watch from outside (the mission was lost, the link gave no reports)."""
        if self.over:
            return self
        return replace(self, phase="left" if self.arrived else "passed", why_left=why, abandoned=True)

    def _end(self, why: str, boot_s: float) -> "HoldWatch":
        phase: Phase = "left" if self.arrived else "passed"
        return replace(self, phase=phase, last_s=boot_s, why_left=why)
