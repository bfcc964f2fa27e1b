"""Where a sortie is in its life: its number, started, flown, over, the next one asked for,
and the service's own condition (warming up, degraded). Pure.

Its fields change together with the vehicle's take-off, landing and the journal's answers;
a new sortie is a new ``Life``."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .authority import Authority


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
    homing: bool = False
    """The vehicle was seen on the service's own way home (``_homing``)."""
    degraded: str | None = None
    warming: bool = False
    """The planner's kernels are being compiled: no plan, no start until they are."""
