"""The verdict rules of a claim's checks."""

from __future__ import annotations

import math

from planner_service.experiments.claims import FAILS, HOLDS, UNRESOLVED, Claim, near, positive, within
from planner_service.experiments.stats import Interval


def iv(mean, lo, hi, n=10):
    return Interval(mean, lo, hi, n)


def test_positive_needs_the_whole_interval_above_zero():
    assert positive("w", "d", iv(0.3, 0.1, 0.5)).verdict == HOLDS
    assert positive("w", "d", iv(-0.3, -0.5, -0.1)).verdict == FAILS
    assert positive("w", "d", iv(0.3, -0.1, 0.7)).verdict == UNRESOLVED
    assert positive("w", "d", iv(0.3, math.nan, math.nan, 1)).verdict == UNRESOLVED


def test_near_compares_the_mean_with_the_tolerance():
    assert near("w", "x", iv(8.0, 7.0, 9.0), 8.35, 0.835).verdict == HOLDS
    assert near("w", "x", iv(12.7, 12.0, 13.4), 8.35, 0.835).verdict == FAILS


def test_within_needs_the_interval_inside_the_tolerance():
    assert within("w", "d", iv(0.1, -0.2, 0.3), 0.5).verdict == HOLDS
    assert within("w", "d", iv(1.0, 0.7, 1.3), 0.5).verdict == FAILS
    assert within("w", "d", iv(0.4, 0.1, 0.7), 0.5).verdict == UNRESOLVED


def test_claim_verdict_sums_the_checks():
    good, bad, open_ = positive("a", "d", iv(1, 0.5, 1.5)), positive("b", "d", iv(-1, -1.5, -0.5)), \
        positive("c", "d", iv(0, -1, 1))
    assert Claim("x", "Fig", "t", (good, good)).verdict == "holds"
    assert Claim("x", "Fig", "t", (bad,)).verdict == "does not hold"
    assert Claim("x", "Fig", "t", (good, bad, open_)).verdict == \
        "mixed: holds at 1, fails at 1, unresolved at 1 of 3"
    d = Claim("x", "Fig", "t", (good,)).as_dict()
    assert d["verdict"] == "holds" and d["checks"][0]["mean"] == 1 and d["checks"][0]["lo"] == 0.5
