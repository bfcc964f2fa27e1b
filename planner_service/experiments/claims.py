"""The paper's claims as checks on measured numbers, each with a verdict from its interval.

A check is one number with its 95 % interval over seeds and a rule:
- ``positive``: the claim says a difference is above zero. It *holds* when the whole
  interval is above zero, *fails* when the whole interval is below zero, and is
  *unresolved* when the interval straddles zero (the seeds cannot tell).
- ``near``: the claim gives a value ("about 8.35"). It holds when our mean is within the
  stated tolerance of it, fails otherwise.
- ``within``: the claim says two things are similar. It holds when the whole interval of
  the difference lies within +-tolerance, fails when it lies wholly outside, else unresolved.
A claim's verdict sums its checks: every check holds, none does, or "mixed" with counts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .stats import Interval

HOLDS, FAILS, UNRESOLVED = "holds", "fails", "unresolved"


@dataclass(frozen=True)
class Check:
    """One measured number behind a claim."""

    where: str
    quantity: str
    estimate: Interval
    verdict: str
    rule: str

    def as_dict(self) -> dict[str, Any]:
        return {"where": self.where, "quantity": self.quantity, **self.estimate.as_dict(),
                "rule": self.rule, "verdict": self.verdict}


def positive(where: str, quantity: str, iv: Interval) -> Check:
    """``quantity`` should be above zero."""
    if iv.lo > 0:
        verdict = HOLDS
    elif iv.hi < 0:
        verdict = FAILS
    else:  # straddles zero, or nan bounds (fewer than two seeds)
        verdict = UNRESOLVED
    return Check(where, quantity, iv, verdict, "> 0 (95% interval)")


def near(where: str, quantity: str, iv: Interval, target: float, tol: float) -> Check:
    """``quantity`` should be about ``target``: its mean within +-``tol``."""
    verdict = HOLDS if abs(iv.mean - target) <= tol else FAILS
    return Check(where, quantity, iv, verdict, f"mean within {target:g} +- {tol:g}")


def within(where: str, quantity: str, iv: Interval, tol: float) -> Check:
    """``quantity`` (a difference) should be about zero: its interval within +-``tol``."""
    if -tol <= iv.lo and iv.hi <= tol:
        verdict = HOLDS
    elif iv.lo > tol or iv.hi < -tol or (math.isnan(iv.lo) and abs(iv.mean) > tol):
        verdict = FAILS
    else:
        verdict = UNRESOLVED
    return Check(where, quantity, iv, verdict, f"95% interval within +-{tol:.3g}")


@dataclass(frozen=True)
class Claim:
    """A claim of the paper (or, with source "context", a comparison the paper omits)."""

    id: str
    source: str
    text: str
    checks: tuple[Check, ...]

    @property
    def verdict(self) -> str:
        counts = {v: sum(c.verdict == v for c in self.checks) for v in (HOLDS, FAILS, UNRESOLVED)}
        n = len(self.checks)
        if n == 0:
            return "no data"
        if counts[HOLDS] == n:
            return "holds"
        if counts[FAILS] == n:
            return "does not hold"
        return f"mixed: holds at {counts[HOLDS]}, fails at {counts[FAILS]}, unresolved at {counts[UNRESOLVED]} of {n}"

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.id, "source": self.source, "claim": self.text, "verdict": self.verdict,
                "checks": [c.as_dict() for c in self.checks]}


__all__ = ["Check", "Claim", "FAILS", "HOLDS", "UNRESOLVED", "near", "positive", "within"]
