"""The fleet's traffic model (``bench --fleet --scale``): bytes per UAV per second as a line
in N, fitted on the measured sizes and projected; its worst error on them is reported."""

from __future__ import annotations

import pytest

from planner_service.bench.fleet_scale import fit_line, traffic_model


def test_a_line_is_found_and_projected() -> None:
    rows = [{"uavs": n, "radio_down_bytes_per_s": 2380.0 * n - 900.0} for n in (5, 10, 20)]
    model = traffic_model(rows, [100])["radio_down_bytes_per_s"]
    assert model["a"] == pytest.approx(-900.0) and model["b"] == pytest.approx(2380.0)
    assert model["worst_fit_error"] == pytest.approx(0.0, abs=1e-9)
    assert model["projected"][100] == pytest.approx(237100.0)


def test_the_worst_error_is_the_fits_and_one_size_has_no_slope() -> None:
    rows = [{"uavs": 5, "fleet_keys_bytes_per_s": 100.0}, {"uavs": 10, "fleet_keys_bytes_per_s": 300.0},
            {"uavs": 20, "fleet_keys_bytes_per_s": 500.0}]
    model = traffic_model(rows, [])["fleet_keys_bytes_per_s"]
    assert 0.1 < model["worst_fit_error"] < 1.0  # three points off one line
    assert fit_line([(10.0, 4.0), (10.0, 6.0)]) == (5.0, 0.0)
    assert fit_line([]) == (0.0, 0.0)
