"""Each equation against numbers worked by hand from the paper's parameter table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner_service.model import pack, paper, field
from planner_service.model._jit import py
from planner_service.model.channel import channel_gain, upload_rate_bps
from planner_service.model.energy import (
    computation_energy_j,
    flight_energy_j,
    hover_energy_j,
    rotary_wing_power_w,
)
from planner_service.model.fairness import fairness_violations, is_eligible
from planner_service.model.interval import served_user, service_outcome, within_budget
from planner_service.model.mobility import draw_tasks, move_users
from planner_service.model.reward import interval_reward

P = pack(paper())


def test_units_of_the_table():
    s = paper()
    assert s.noise_w == pytest.approx(1e-15)  # -120 dBm = 1e-12 mW = 1e-15 W
    assert s.gain_ref == pytest.approx(1e-5)  # -50 dB
    assert s.energy_floor_j == pytest.approx(0.1 * s.battery_j)


def test_channel_gain_directly_above_and_offset():
    hp = np.array([100.0, 100.0, 100.0])
    below = np.array([100.0, 100.0, 0.0])
    # d^2 = H^2 = 10^4 -> g = 1e-5 / 1e4 = 1e-9  (4)-(5)
    assert channel_gain(P, hp, below) == pytest.approx(1e-9)
    offset = np.array([130.0, 140.0, 0.0])
    # d^2 = 100^2 + 30^2 + 40^2 = 12 500 -> g = 1e-5 / 12 500 = 8e-10
    assert channel_gain(P, hp, offset) == pytest.approx(8e-10)


def test_upload_rate_literal_and_with_bandwidth():
    # SNR = 0.1 W * 1e-9 / 1e-15 W = 1e5 -> log2(100 001) = 16.60966 bit/s per Hz
    assert upload_rate_bps(P, 1e-9) == pytest.approx(math.log2(100_001.0))
    assert upload_rate_bps(P, 1e-9) == pytest.approx(16.60966, abs=1e-5)
    # field preset: the same times 2 kHz
    assert upload_rate_bps(pack(field()), 1e-9) == pytest.approx(2000 * 16.60966, rel=1e-6)


def test_hover_energy_of_ten_tasks():
    # S = 10 tasks * 100 kb = 1e6 bit; e_h = 1 W * 1e6 / 16.60966 = 60 206.2 J
    assert hover_energy_j(P, 1e6, 16.60966) == pytest.approx(60_206.2, abs=0.5)


def test_computation_energy_eq6():
    # 1e-28 * 1000 cycles/bit * 1e6 bit * (2e9 Hz)^2 = 0.4 J
    assert computation_energy_j(P, 1e6) == pytest.approx(0.4)


def test_flight_energy_eq7_eq8():
    # 200 m at 20 m/s: kappa = 0.5 * 10 kg * 10 s = 50; e_f1 = 50 * 400 = 20 000 J (7)
    # e_f2 = 0.03 * 20^3 + 5 / 20 * (1 + 15^2 / 9.8^2) = 240 + 0.25 * 3.342774 = 240.8357 (8)
    assert flight_energy_j(P, 200.0) == pytest.approx(20_240.8357, abs=1e-3)
    slow = pack(paper().replace(speed_mps=10.0))
    # 200 m at 10 m/s: e_f1 = 0.5 * 10 * 20 * 100 = 10 000; e_f2 = 30 + 0.5 * 3.342774
    assert flight_energy_j(slow, 200.0) == pytest.approx(10_031.6714, abs=1e-3)
    assert flight_energy_j(P, 0.0) == 0.0  # staying put costs no flight


def test_rotary_wing_power_has_a_cruise_minimum():
    p = pack(field())
    # at speed 0 it is the hover power P_0 + P_i = 79.86 + 88.63 W (Zeng et al.)
    assert rotary_wing_power_w(p, 0.0) == pytest.approx(168.49)
    speeds = np.linspace(0.0, 30.0, 301)
    power = np.array([rotary_wing_power_w(p, v) for v in speeds])
    best = speeds[np.argmin(power)]
    assert 5.0 < best < 15.0 and power.min() < 0.8 * power[0]
    # energy per metre is least at a higher (maximum-range) speed, above 15 m/s
    per_metre = power[1:] / speeds[1:]
    assert speeds[1:][np.argmin(per_metre)] > 15.0
    # a 200 m hop is P(v) * 200 / v
    assert flight_energy_j(p, 200.0) == pytest.approx(rotary_wing_power_w(p, 20.0) * 10.0)


def test_reward_eq11():
    # u = 10 tasks, w = 80 447.4 J: q = 10 / 20 - 80 447.4 / 186 000 = 0.5 - 0.432513 = 0.067487
    assert interval_reward(P, 10, 80_447.4) == pytest.approx(0.067487, abs=1e-6)


@pytest.mark.parametrize(
    "tasks, served, expected, why",
    [
        (5, 0, True, "never served: eligible whatever the tasks"),
        (16, 1, True, "served once, 16 > beta = 15"),
        (15, 1, False, "served once, 15 is not > beta"),
        (20, 2, False, "never a third service (9c)"),
        (0, 0, False, "no task, nothing to offload"),
    ],
)
def test_fairness_rule_eq3(tasks, served, expected, why):
    assert is_eligible(P, tasks, served) is expected, why


def test_fairness_audit_counts_what_the_rule_refuses():
    # The one audit (plan summary, service report, tests): each service judged by (3)/(9c) with
    # the counts before it. a: 5 then 16 (> beta = 15) is fair, a third is past the limit;
    # b: a repeat of 15 is not > beta; c: a service of no tasks is never fair.
    services = [("a", 5), ("b", 3), ("a", 16), ("b", 15), ("c", 0), ("a", 20)]
    assert fairness_violations(paper(), services) == 3
    assert fairness_violations(paper(), services[:3]) == 0
    assert fairness_violations(paper().replace(fairness_threshold_tasks=14), [("b", 3), ("b", 15)]) == 0


class _ScriptedRng:
    """Returns scripted draws so the clip arithmetic can be checked by hand."""

    def __init__(self, normals=()):
        self.normals = list(normals)

    def normal(self, mean, std):
        assert (mean, std) == (10.0, 5.0)
        return self.normals.pop(0)


def test_mobility_clips_at_the_area_border():
    # generator seed 2 draws the moves +7, -5, -8, -4 (whole metres in [-10, 10])
    assert [int(d) for d in np.random.default_rng(2).integers(-10, 11, size=4)] == [7, -5, -8, -4]
    users = np.array([[495.0, 3.0, 0.0], [250.0, 250.0, 0.0]])
    move_users(P, users, np.random.default_rng(2))
    # 495 + 7 = 502 > R -> 500 (1); 3 - 5 = -2 < 0 -> 0 (2); 250 - 8 = 242; 250 - 4 = 246
    assert users.tolist() == [[500.0, 0.0, 0.0], [242.0, 246.0, 0.0]]


def test_tasks_rounded_and_clipped():
    tasks = np.zeros(4, dtype=np.int64)
    py(draw_tasks)(P, tasks, _ScriptedRng(normals=[-3.2, 9.5, 12.49, 27.0]))
    # -3.2 -> -3 -> 0 ; 9.5 -> 10 (half up) ; 12.49 -> 12 ; 27 -> 27 -> u_max = 20
    assert tasks.tolist() == [0, 10, 12, 20]


def test_served_user_nearest_eligible_ties_to_larger_task():
    hp = np.array([100.0, 100.0, 100.0])
    users = np.array([[100.0, 150.0, 0.0], [100.0, 50.5, 0.0], [100.0, 100.0, 0.0]])
    tasks = np.array([8, 12, 9])
    served = np.array([0, 0, 2])  # user 2, right below, has had its two services
    # users 0 and 1 are 50 m and 49.5 m away: within the 1 m tie, so the larger task wins
    assert served_user(P, hp, users, tasks, served) == 1
    tasks[1] = 7
    assert served_user(P, hp, users, tasks, served) == 0
    far = users.copy()
    far[0, 1] = 160.0  # now 60 m vs 49.5 m: no tie, the nearest wins
    assert served_user(P, hp, far, tasks, served) == 1


def test_service_outcome_sums_the_terms():
    start = np.array([0.0, 0.0, 100.0])
    hp = np.array([120.0, 160.0, 100.0])  # 200 m away
    users = np.array([[120.0, 160.0, 0.0]])
    user, bits, e_h, e_c, e_f, q = service_outcome(P, start, hp, users, np.array([10]), np.array([0]))
    assert (user, bits) == (0, 1e6)
    assert e_h == pytest.approx(60_206.2, abs=0.5)
    assert e_c == pytest.approx(0.4)
    assert e_f == pytest.approx(20_240.8357, abs=1e-3)
    assert q == pytest.approx(0.5 - (e_h + e_c + e_f) / 186_000.0)


def test_energy_budget_eq9b_boundary():
    s = paper()
    hp = np.array([20.0, 20.0, 100.0])
    # the budget is (1 - theta) E_0: spending exactly that is allowed, one joule more is not
    assert within_budget(P, s.battery_j, 0.9 * s.battery_j, hp)
    assert not within_budget(P, s.battery_j, 0.9 * s.battery_j + 1.0, hp)
    # with the return reserve, the way home (28.28 m from (0, 0)) is kept too
    reserve = pack(s.replace(reserve_return_energy=True))
    home = flight_energy_j(P, math.hypot(20.0, 20.0))
    assert within_budget(reserve, s.battery_j, 0.9 * s.battery_j - home, hp)
    assert not within_budget(reserve, s.battery_j, 0.9 * s.battery_j - home + 1.0, hp)


def test_draw_int_is_the_generators_integers():
    """``draw_int`` (compiled: numba's draw without its array) gives what ``integers`` gives,
    from the same generator state, and leaves the generator where ``integers`` leaves it."""
    from planner_service.model import HAVE_NUMBA
    from planner_service.model.mobility import draw_int

    if not HAVE_NUMBA:
        pytest.skip("without numba draw_int is rng.integers itself")
    import numba

    @numba.njit
    def with_integers(rng, lows, highs, out):
        for j in range(out.shape[0]):
            out[j] = rng.integers(lows[j], highs[j])

    @numba.njit
    def with_draw_int(rng, lows, highs, out):
        for j in range(out.shape[0]):
            out[j] = draw_int(rng, lows[j], highs[j])

    spans = np.random.default_rng(0).integers(1, 3000, size=5000)
    lows = np.random.default_rng(1).integers(-1500, 1500, size=5000)
    a, b = np.empty(5000, dtype=np.int64), np.empty(5000, dtype=np.int64)
    ra, rb = np.random.default_rng(7), np.random.default_rng(7)
    with_integers(ra, lows, lows + spans, a)
    with_draw_int(rb, lows, lows + spans, b)
    assert (a == b).all() and (a >= lows).all() and (a < lows + spans).all()
    assert ra.random() == rb.random()
