"""Scenario presets, overrides and layouts."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.model import ScenarioError, field, hover_points, paper, paper_3d, preset, user_rows
from planner_service.model.layouts import ORIGINAL_HOVER_POINTS_XY


def test_paper_preset_has_the_table_values():
    s = paper()
    table = dict(num_hover_points=20, num_users=10, altitude_m=100.0, mass_kg=10.0, noise_dbm=-120.0,
                 gain_ref_db=-50.0, hover_power_w=1.0, upload_power_w=0.1, bits_per_task=1e5,
                 kappa1=0.03, kappa2=5.0, accel_mps2=15.0, gravity_mps2=9.8, cycles_per_bit=1000.0,
                 cpu_hz=2e9, switched_capacitance=1e-28, task_mean=10.0, task_std=5.0,
                 fairness_threshold_tasks=15, battery_threshold=0.1, tree_depth=10, speed_mps=20.0,
                 bandwidth_hz=1.0, area_side_m=500.0, user_move_range_m=10.0, task_max=20,
                 energy_norm_j=186_000.0, max_intervals=10)
    assert {k: getattr(s, k) for k in table} == table


def test_overrides_by_name_with_types():
    s = paper().with_overrides(["speed_mps=10", "allow_stay=true", "num_hover_points=30"])
    assert (s.speed_mps, s.allow_stay, s.num_hover_points) == (10.0, True, 30)
    with pytest.raises(ScenarioError) as err:
        paper().with_overrides(["speed=10"])
    assert err.value.field == "speed"
    with pytest.raises(ScenarioError) as err:
        paper().with_overrides(["speed_mps=fast"])
    assert err.value.field == "speed_mps"
    for bad in ("speed_mps=-1", "speed_mps=nan", "battery_threshold=1.5", "dimensions=4"):
        with pytest.raises(ScenarioError) as err:
            paper().with_overrides([bad])
        assert err.value.field == bad.split("=")[0]
    with pytest.raises(ScenarioError):
        preset("moon")


def test_two_neat_rows_match_the_authors_layout():
    rows = user_rows(10, 500.0)
    expected = [(x, y, 0.0) for y in (200.0, 400.0) for x in (50.0, 150.0, 250.0, 350.0, 450.0)]
    assert rows.tolist() == [list(p) for p in expected]
    assert user_rows(7, 500.0).shape == (7, 3)


def test_original_and_uniform_layouts():
    hp = hover_points(paper())
    assert hp[:, :2].tolist() == [list(map(float, p)) for p in ORIGINAL_HOVER_POINTS_XY]
    assert (hp[:, 2] == 100.0).all()
    for k in (20, 30, 40):
        for layout in ("original", "uniform"):
            pts = hover_points(paper().replace(num_hover_points=k, hover_layout=layout))
            assert pts.shape == (k, 3)
            assert len({tuple(p) for p in pts}) == k  # distinct
            assert (pts[:, :2] >= 0).all() and (pts[:, :2] <= 500).all()
    grid = hover_points(paper().replace(hover_layout="uniform"))
    assert sorted(set(grid[:, 0])) == [50.0, 150.0, 250.0, 350.0, 450.0]
    assert sorted(set(grid[:, 1])) == [62.5, 187.5, 312.5, 437.5]


def test_3d_variant_has_three_planes_of_nine():
    hp = hover_points(paper_3d())
    assert hp.shape == (27, 3)
    for h in (25.0, 50.0, 75.0):
        assert (hp[:, 2] == h).sum() == 9
    with pytest.raises(ScenarioError):
        hover_points(paper_3d().replace(num_hover_points=20))


def test_field_preset_is_plausible():
    s = field()
    assert s.propulsion_model == "rotary-wing" and s.reserve_return_energy
    # a 10-task upload right below: 1e6 bit / (2000 Hz * 16.61 bit/s/Hz) = 30.1 s of hovering
    assert 1e6 / (s.bandwidth_hz * np.log2(1 + 1e5)) == pytest.approx(30.1, abs=0.1)
    assert s.as_dict()["propulsion_model"] == "rotary-wing"
