"""The mean and its 95 % t interval, checked by hand."""

from __future__ import annotations

import math

import pytest

from planner_service.experiments.stats import mean_interval, t_critical_95


def test_interval_of_one_to_five_by_hand():
    # mean 3; s^2 = (4 + 1 + 0 + 1 + 4) / 4 = 2.5; se = sqrt(2.5 / 5) = sqrt(0.5); t(4) = 2.776445105
    iv = mean_interval([1, 2, 3, 4, 5])
    half = 2.776445105 * math.sqrt(0.5)
    assert iv.n == 5
    assert iv.mean == 3.0
    assert iv.lo == pytest.approx(3.0 - half, abs=1e-9) and iv.hi == pytest.approx(3.0 + half, abs=1e-9)
    assert iv.lo == pytest.approx(1.036757, abs=1e-6)


def test_interval_of_two_values_by_hand():
    # mean 3, s = sqrt(2), se = 1, t(1) = 12.706204736
    iv = mean_interval([2.0, 4.0])
    assert (iv.mean, iv.lo, iv.hi) == pytest.approx((3.0, 3.0 - 12.706204736, 3.0 + 12.706204736))


def test_constant_values_have_a_zero_width_interval():
    iv = mean_interval([0.25] * 7)
    assert iv.lo == iv.mean == iv.hi == 0.25


def test_one_value_has_no_interval_and_none_has_no_mean():
    one = mean_interval([4.0])
    assert one.mean == 4.0 and one.n == 1 and math.isnan(one.lo) and math.isnan(one.hi)
    assert one.as_dict() == {"mean": 4.0, "lo": None, "hi": None, "n": 1}
    assert math.isnan(mean_interval([]).mean)


@pytest.mark.parametrize("df, t", [
    (1, 12.706204736), (2, 4.302652730), (10, 2.228138852), (30, 2.042272456),
    # past the table: the Cornish-Fisher expansion against published values
    (31, 2.039513446), (40, 2.021075390), (60, 2.000297822), (120, 1.979930405), (1000, 1.962339081),
])
def test_t_critical_values(df, t):
    assert t_critical_95(df) == pytest.approx(t, abs=2e-7)


def test_t_critical_decreases_towards_the_normal_quantile():
    values = [t_critical_95(df) for df in range(1, 200)]
    assert all(a > b for a, b in zip(values, values[1:]))
    assert values[-1] > 1.959963984540054
    with pytest.raises(ValueError):
        t_critical_95(0)
