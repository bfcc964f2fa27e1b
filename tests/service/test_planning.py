"""Planning numbers checked by hand on the field preset (B = 2 kHz, P_u = 0.1 W, rho_0 =
-50 dB, sigma^2 = -120 dBm, P_h = 168.49 W, 100 kJ, reserve theta = 0.1 + the way home)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner_service.mcts import MctsConfig
from planner_service.model import field, hover_points, pack
from planner_service.model.energy import flight_energy_j
from planner_service.model.world import evaluate, scene_of
from planner_service.service.config import FLIGHT_ALGOS, build_config
from planner_service.service.errors import PlanningError
from planner_service.service.rows import RequestRow, ServiceRow, UserRow
from planner_service.service.planning import (PlannedPath, PlannedPoint, Planner, VehicleFix, after_hold, assemble,
                                              check_path,
                                              hold_time_s, not_served_reason, planning_battery_j, predict_path)
from protocol import Area

S = field()
P = pack(S)
HP = hover_points(S)
RATE_BELOW = 2000.0 * math.log2(1.0 + 0.1 * (1e-5 / 100.0 ** 2) / 1e-15)  # 33 219.3 bit/s at 100 m


def users_below(a: int, b: int, tasks: tuple[int, int], battery_j: float = 100_000.0):
    users = [UserRow("u0", HP[a][0], HP[a][1], 0.0, 0), UserRow("u1", HP[b][0], HP[b][1], 0.0, 0)]
    pending = [RequestRow(i + 1, f"u{i}", users[i].x_m, users[i].y_m, 0.0, t, None, 0.0, "pending", "")
               for i, t in enumerate(tasks) if t > 0]
    return assemble(S, users, pending, [], VehicleFix(0.0, 0.0, 0.0, battery_j, False), -1)


def test_hold_is_bits_over_rate() -> None:
    assert RATE_BELOW == pytest.approx(33_219.3, abs=0.1)
    hold = hold_time_s(P, HP[5], np.array([HP[5][0], HP[5][1], 0.0]), 10 * 1e5)
    assert hold == pytest.approx(1e6 / 33_219.3, rel=1e-6)  # 30.10 s for 10 tasks straight below


def test_assemble_from_the_ground_starts_at_base() -> None:
    a = users_below(5, 11, (10, 0))
    assert a.state.hover_index == -1 and list(a.state.uav_xyz) == [0.0, 0.0, 100.0]
    assert list(a.state.tasks) == [10, 0] and a.request_ids == (1, 0) and a.user_ids == ("u0", "u1")
    assert a.state.task_table.shape == (0, 2)


def test_the_state_after_a_hold_counts_its_interval_with_its_reward() -> None:
    """Planning on arrival at a point: the state is the one after its hold, in which the
    user is served and the sortie has one more interval, earning the hold's q; the past
    average that ``mcts`` maximises is then what the journal will say once it ends."""
    users = [UserRow("u0", HP[5][0], HP[5][1], 0.0, 1), UserRow("u1", HP[11][0], HP[11][1], 0.0, 0)]
    pending = [RequestRow(7, "u0", HP[5][0], HP[5][1], 0.0, 12, None, 0.0, "pending", ""),
               RequestRow(8, "u1", HP[11][0], HP[11][1], 0.0, 9, None, 0.0, "pending", "")]
    done = [ServiceRow(1, 3, "u0", 10, 1e6, 2, *HP[2], 0.35, 90_000.0, 0.0)]
    fix = VehicleFix(*HP[5], 80_000.0, True)
    a = assemble(S, users, pending, done, fix, 2)
    assert (a.state.interval, a.state.reward_sum) == (1, 0.35)
    here = PlannedPoint(5, *HP[5], 36.0, "u0", 7, 12, 1.2e6, 7000.0, 0.25)
    after = after_hold(a, here, "u0", 0.25)
    assert after.state.hover_index == 5 and list(after.state.uav_xyz) == list(HP[5])
    assert list(after.state.tasks) == [0, 9] and list(after.state.served) == [2, 0]
    assert after.state.interval == 2 and after.state.reward_sum == pytest.approx(0.60)
    assert (a.state.interval, a.state.reward_sum, list(a.state.tasks)) == (1, 0.35, [12, 9]), "a copy"
    nobody = after_hold(a, here, None, 0.25)  # nobody bound there: no service, no interval
    assert (nobody.state.interval, nobody.state.reward_sum, nobody.state.hover_index) == (1, 0.35, 5)


def test_path_steps_the_model_along_the_line() -> None:
    a = users_below(5, 11, (10, 12))
    path = predict_path(S, HP, a, (5, 11))
    assert [(p.hover_index, p.user_id, p.request_id, p.tasks) for p in path.points] == [(5, "u0", 1, 10), (11, "u1", 2, 12)]
    assert path.points[0].hold_s == pytest.approx(1e6 / RATE_BELOW, rel=1e-6)
    assert path.points[1].hold_s == pytest.approx(1.2e6 / RATE_BELOW, rel=1e-6)
    # energy of the first interval: hover P_h * hold + computation + flight from base
    d = math.dist((0.0, 0.0, 100.0), HP[5])
    e_c = 1e3 * 1e-28 * (2e9) ** 2 * 1e6  # (6): C gamma f^2 S = 0.4 J
    expected = 168.49 * 1e6 / RATE_BELOW + e_c + flight_energy_j(P, d)
    assert path.points[0].energy_j == pytest.approx(expected, rel=1e-9)
    home = flight_energy_j(P, math.dist(HP[11], (0.0, 0.0, 100.0)))
    assert path.predicted_energy_j == pytest.approx(sum(p.energy_j for p in path.points) + home, rel=1e-9)


def test_path_is_cut_to_the_mission_capacity() -> None:
    a = users_below(5, 11, (10, 12))
    whole = predict_path(S, HP, a, (5, 11))
    cut = predict_path(S, HP, a, (5, 11), max_points=1)
    assert cut.points == whole.points[:1] and cut.stop_reason == "the autopilot's mission capacity"
    home = flight_energy_j(P, math.dist(HP[5], (0.0, 0.0, 100.0)))  # home from the last point kept
    assert cut.predicted_energy_j == pytest.approx(cut.points[0].energy_j + home, rel=1e-9)
    assert predict_path(S, HP, a, (5, 11), max_points=2).points == whole.points


def test_path_stops_where_nobody_known_is_eligible() -> None:
    a = users_below(5, 11, (10, 0))
    path = predict_path(S, HP, a, (5, 11, 3))
    assert [p.hover_index for p in path.points] == [5]
    assert path.stop_reason == "nobody known is eligible further on"


def test_path_stops_at_the_energy_reserve() -> None:
    a = users_below(5, 11, (10, 12))
    first = predict_path(S, HP, a, (5,)).points[0].energy_j
    # just enough for the first interval, the way home from it and the 10 kJ floor
    battery = first + flight_energy_j(P, math.dist(HP[5], (0.0, 0.0, 100.0))) + 10_000.0 + 1.0
    path = predict_path(S, HP, users_below(5, 11, (10, 12), battery), (5, 11))
    assert [p.hover_index for p in path.points] == [5] and path.stop_reason == "the energy reserve"
    assert path.battery_after_j == pytest.approx(10_001.0, abs=1e-6)
    check_path(path, Area(500.0, 120.0, 10.0), S, battery)  # exactly within the reserve


def _point(x: float, y: float, z: float, energy: float = 100.0) -> PlannedPoint:
    return PlannedPoint(0, x, y, z, 1.0, "u", 1, 1, 1e5, energy, 0.0)


@pytest.mark.parametrize("point, check", [
    (_point(600.0, 10.0, 100.0), "area"),
    (_point(10.0, -1.0, 100.0), "area"),
    (_point(10.0, 10.0, 130.0), "altitude"),
    (_point(10.0, 10.0, 5.0), "altitude"),
    (_point(10.0, 10.0, 100.0, energy=95_000.0), "energy"),
])
def test_check_path_refuses(point: PlannedPoint, check: str) -> None:
    path = PlannedPath((point,), point.energy_j + 500.0, 0.0, "")
    with pytest.raises(PlanningError) as err:
        check_path(path, Area(500.0, 120.0, 10.0), S, 100_000.0)
    assert err.value.check == check


def test_planning_battery_keeps_the_drain_the_descent_and_the_margin() -> None:
    cruise_w = flight_energy_j(P, 20.0)  # one second at 20 m/s
    assert cruise_w == pytest.approx(178.3, abs=0.1)  # Zeng's P(20), docs/MODEL.md
    descent = flight_energy_j(P, 100.0)
    assert descent == pytest.approx(100.0 * cruise_w / 20.0)
    assert planning_battery_j(S, 50_000.0, 10.0, 1_000.0) == pytest.approx(50_000.0 - 10 * cruise_w - descent - 1_000.0)


def test_not_served_reasons() -> None:
    assert not_served_reason(S, 0, 0, "x") == "no tasks to offload"
    assert not_served_reason(S, 18, 2, "x") == "fairness: already served 2 times (limit 2)"
    assert not_served_reason(S, 15, 1, "x") == "fairness: a repeat needs more than 15 tasks, asked 15"
    assert not_served_reason(S, 16, 1, "sortie ended") == "sortie ended"


def crowd(battery_j: float = 100_000.0):
    """Six users with requests around the area, the vehicle on the ground."""
    spots = [(3, 12), (8, 18), (11, 7), (14, 16), (17, 9), (19, 11)]
    users = [UserRow(f"u{i}", HP[k][0] + 5.0, HP[k][1] - 5.0, 0.0, 0) for i, (k, _) in enumerate(spots)]
    pending = [RequestRow(i + 1, u.user_id, u.x_m, u.y_m, 0.0, t, None, 0.0, "pending", "")
               for i, (u, (_, t)) in enumerate(zip(users, spots))]
    return assemble(S, users, pending, [], VehicleFix(0.0, 0.0, 0.0, battery_j, False), -1)


@pytest.mark.parametrize("algo", FLIGHT_ALGOS)
def test_each_algorithm_flies_through_the_planner(algo: str) -> None:
    a = crowd()
    planner = Planner(S, MctsConfig(iterations=300), seed=4, max_points=4, algo=algo)
    decision, path = planner.decide(a)
    q = np.empty(len(HP))
    evaluate(scene_of(P, HP, a.state.task_table), a.state.world(), q)
    assert np.isfinite(q[decision.action]), "the decision is an allowed point"
    assert decision.line[0] == decision.action
    # the path is the algorithm's line, cut where the model stops it or at the capacity
    assert [pt.hover_index for pt in path.points] == list(decision.line[:len(path.points)])
    assert 1 <= len(path.points) <= 4
    if algo == "greedy":
        assert decision.action == int(np.argmax(q))
        # the repeated decision along the predicted state: each point the best q there
        assert len(path.points) == min(4, len(a.user_ids))
    if algo in ("greedy", "random"):
        assert len(decision.line) <= 4
    again = Planner(S, MctsConfig(iterations=300), seed=4, max_points=4, algo=algo).decide(a)[0]
    assert (again.action, again.line) == (decision.action, decision.line)  # seeded


def test_the_operator_picks_the_algorithm_in_the_configuration() -> None:
    assert build_config({}).planner.algo == "mcts"
    assert build_config({}, {"planner.algo": "greedy"}).planner.algo == "greedy"
    with pytest.raises(PlanningError):
        Planner(S, MctsConfig(), 0, algo="dqn")


def test_random_draws_among_the_allowed_points() -> None:
    a = crowd()
    firsts = {Planner(S, MctsConfig(), seed, max_points=3, algo="random").decide(a)[0].action for seed in range(12)}
    q = np.empty(len(HP))
    evaluate(scene_of(P, HP, a.state.task_table), a.state.world(), q)
    assert len(firsts) > 3 and all(np.isfinite(q[k]) for k in firsts)


@pytest.mark.parametrize("algo", FLIGHT_ALGOS)
def test_a_fleet_members_planner_plans_without_the_points_the_others_claim(algo: str) -> None:
    """In a fleet each member plans without the hovering points the other live members claim
    (their next points and holds): its decision and line are indices of every point, none of
    them claimed; with every point claimed there is nothing to decide."""
    a = crowd()
    planner = Planner(S, MctsConfig(iterations=300), seed=4, max_points=4, algo=algo)
    free, _ = planner.decide(a)
    assert free is not None
    blocked = frozenset({free.action, *free.line[1:2]})
    decision, path = planner.decide(a, blocked)
    assert decision is not None and decision.action not in blocked and not blocked & set(decision.line)
    assert decision.line[0] == decision.action and 0 <= decision.action < len(HP)
    assert [pt.hover_index for pt in path.points] == list(decision.line[:len(path.points)])
    q = np.empty(len(HP))
    evaluate(scene_of(P, HP, a.state.task_table), a.state.world(), q)
    assert np.isfinite(q[decision.action]), "an allowed point of the whole set"
    assert planner.decide(a, frozenset(range(len(HP))))[0] is None
