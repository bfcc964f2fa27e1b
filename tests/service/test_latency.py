"""End-to-end latency on loopback through real processes (``bench --e2e`` with fewer
requests): a request to the mission accepted by the stub, the planner's time excluded,
must stay under the issue's target of 100 ms at the 99th percentile.

Marked ``alone``: ``make test`` runs it after the other tests, not beside another test
process on a 2-core machine, where a few requests in a hundred waited for the CPU
(p99 100-315 ms, median 20-38 ms, in 3 of about 15 runs)."""

from __future__ import annotations

import pytest

from planner_service.bench.e2e import run_e2e


@pytest.mark.alone
@pytest.mark.timeout(90)
def test_request_to_accepted_mission_p99_under_100_ms() -> None:
    r = run_e2e(requests=40, budget_ms=20.0)
    assert r["planner_ms_median"] >= 15.0  # the planner did run inside each measured span
    assert 0.0 < r["e2e_ms_median"] <= r["e2e_ms_p99"] < 100.0, r
    # The ack comes before the mission: compared with the whole span, the planner included
    # (e2e has it subtracted; a CI run beside two busy processes had the ack's median, whose
    # journal write waits for the disk, at 27 ms against e2e's 24 ms, for no fault).
    assert r["ack_ms_median"] < r["total_ms_median"]
