"""When a claim of this member has settled: every claim another vehicle made before it is
known here (docs/OPERATIONS.md, "A claim settles").

A claim (a hovering point flown to or held, a user bound at a hold) settles once the
intentions of every vehicle it settles on, signed ``margin_s`` or more after it, were heard.
It settles on every vehicle that may be a member now (``FleetRoster.unsure``: tokens alive,
silent ones too, and tokens gone within ``within_s``) and on every vehicle that was alive
when it was made: a vehicle that could have claimed first still counts after its lease ran
out, which is what this member sees when its own radio is cut."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from .ledger import FleetLedger
from .roster import FleetRoster


@dataclass(frozen=True)
class ClaimSettling:
    """Judges this member's claims, each by the wall-clock time it was made."""

    roster: FleetRoster
    ledger: FleetLedger
    within_s: float
    """How long a vehicle whose token went still counts (``fleet.settle_max_s``)."""
    margin_s: float
    """How much later than the claim the others' intentions must be signed
    (``fleet.settle_margin_s``)."""
    wall: Callable[[], float] = time.time

    def waited_on(self, claimed_at: float) -> set[str]:
        """The vehicles a claim made at ``claimed_at`` (wall clock) settles on."""
        claimed_mono = time.monotonic() - (self.wall() - claimed_at)  # (the roster's clock)
        return self.roster.unsure(self.within_s, claimed_mono)

    def settled(self, claimed_at: float) -> bool:
        """Whether a claim made at ``claimed_at`` has settled (``FleetLedger.heard_since``).
        A member whose own session dropped sees nobody now; on the vehicles now alone it
        would settle at once (at 20 UAVs one did, in 0.36 s, and flew to a point another
        had claimed 8 s before)."""
        return claimed_at <= self.ledger.heard_since(self.waited_on(claimed_at)) - self.margin_s

    def unheard(self, claimed_at: float) -> list[str]:
        """The vehicles a claim made at ``claimed_at`` settles on whose intentions signed
        ``margin_s`` after it were not heard here, sorted."""
        return self.ledger.not_heard_since(claimed_at + self.margin_s, self.waited_on(claimed_at))
