"""The decision benchmark: the fast planner and the plain reference in one run, the same decisions."""

from __future__ import annotations

import pytest

from planner_service.bench.run import SIZES, format_table, run_bench


@pytest.mark.slow  # the pure-Python reference takes about 30 s even on this small run
def test_bench_times_both_and_they_decide_alike():
    results = run_bench(2, 20, 1, sizes=((20, 10),))
    row = results["sizes"][0]
    assert (row["K"], row["I"], row["decisions"]) == (20, 10, 2)
    assert row["median_ms"] > 0 and row["playouts_per_s"] > 0
    ref = row["reference"]
    assert ref["decisions"] == 1 and ref["same_decisions"] == 1  # pure-Python reference, same seeds
    assert ref["speedup_median"] > 1.0
    assert "reference" in format_table(results)


def test_bench_sizes_reach_a_fleet():
    assert SIZES == ((20, 10), (40, 100), (200, 1000), (400, 5000))
