"""``bench --link`` run small: uploads through the lossy proxy at 0 and 20 % loss each way.
The figures must be sane: every upload at 0 % accepted, in about one round trip per item
(20 +- 20 ms each way), and loss costs time but no upload (the retries cover 20 %)."""

from __future__ import annotations

import pytest

from planner_service.bench.link import DELAY_MS, format_link, run_link_bench


@pytest.mark.timeout(120)
def test_link_bench_figures_are_sane() -> None:
    r = run_link_bench(uploads=4, rates=(0.0, 0.2), seed=3)
    clean, lossy = r["rates"]
    print("\n" + format_link(r))
    assert clean["accepted"] == 4 and clean["failures"] == 0
    assert lossy["accepted"] + lossy["failures"] == 4 and lossy["failures"] == 0
    exchanges = r["items"] + 1  # MISSION_COUNT, then one request per item; the ACK ends the last
    round_trip_ms = 2 * DELAY_MS
    assert 0.5 * exchanges * round_trip_ms < clean["median_ms"] < 3 * exchanges * round_trip_ms, clean
    assert lossy["median_ms"] > clean["median_ms"] and lossy["ratio"] > 1.0
    # The retry wait follows the measured round trip, well under the 0.5 s ceiling.
    assert 100 <= clean["retry_wait_ms"] < 500
    with pytest.raises(ValueError):
        run_link_bench(uploads=0)
