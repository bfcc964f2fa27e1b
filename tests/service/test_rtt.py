"""The wait before a repeat, from measured round trips (RFC 6298), checked by hand."""

from __future__ import annotations

import pytest

from planner_service.service.link.rtt import RetryTimer


def test_retry_wait_follows_the_round_trip_within_its_bounds() -> None:
    timer = RetryTimer(ceiling_s=0.5, floor_s=0.1)
    assert timer.timeout_s == 0.5  # nothing measured yet: the configured wait
    timer.sample(0.04)  # srtt 0.04, rttvar 0.02: 0.04 + 4 * 0.02 = 0.12
    assert timer.timeout_s == pytest.approx(0.12)
    timer.sample(0.08)  # rttvar 0.75 * 0.02 + 0.25 * 0.04 = 0.025; srtt 0.875 * 0.04 + 0.125 * 0.08 = 0.045
    assert timer.srtt_s == pytest.approx(0.045) and timer.rttvar_s == pytest.approx(0.025)
    assert timer.timeout_s == pytest.approx(0.145)
    fast = RetryTimer(ceiling_s=0.5, floor_s=0.1)
    fast.sample(0.001)
    assert fast.timeout_s == 0.1  # never below the floor
    slow = RetryTimer(ceiling_s=0.5)
    slow.sample(2.0)
    assert slow.timeout_s == 0.5  # never above the configured wait
    with pytest.raises(ValueError):
        RetryTimer(ceiling_s=0.05, floor_s=0.1)
