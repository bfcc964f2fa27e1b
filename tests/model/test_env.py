"""The environment: determinism, snapshots, the constraints held, bad input refused."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from planner_service.model import ScenarioError, SortieEnv, field, paper, paper_3d


def greedy_rollout(env: SortieEnv, seed: int) -> list[dict]:
    env.reset(seed=seed)
    trace = []
    while not env.done:
        *_, info = env.step(int(np.argmax(env.action_values())))
        info.pop("action_mask")
        trace.append(info)
    return trace


def test_same_seed_same_trace():
    a = greedy_rollout(SortieEnv(paper()), 11)
    b = greedy_rollout(SortieEnv(paper()), 11)
    c = greedy_rollout(SortieEnv(paper()), 12)
    assert a == b
    assert a != c


def test_trace_record_keys_and_first_hop_from_base():
    env = SortieEnv(paper())
    trace = greedy_rollout(env, 3)
    keys = {"hover_point", "uav_xyz", "user", "user_xyz", "tasks", "bits", "e_hover_j",
            "e_comp_j", "e_flight_j", "reward", "battery_j"}
    assert keys <= set(trace[0])
    first = np.array(trace[0]["uav_xyz"])
    # the first interval flies from the base (0, 0, 100): e_f = 5 d v + e_f2 at 20 m/s
    d = np.linalg.norm(first - np.array([0.0, 0.0, 100.0]))
    assert trace[0]["e_flight_j"] == pytest.approx(0.5 * 10 * d * 20 + 240.8357, abs=1e-3)


def test_snapshot_restore_continues_identically():
    env = SortieEnv(paper())
    env.reset(seed=5)
    env.step(int(np.argmax(env.action_values())))
    snap = env.snapshot()
    first = [env.step(a)[1] for a in _first_allowed(env, 3)]
    env.restore(snap)
    second = [env.step(a)[1] for a in _first_allowed(env, 3)]
    assert first == second


def _first_allowed(env: SortieEnv, n: int):
    for _ in range(n):
        yield int(np.flatnonzero(env.action_mask())[0])


def test_pickle_round_trip():
    env = SortieEnv(paper())
    env.reset(seed=9)
    env.step(int(np.argmax(env.action_values())))
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(int(np.argmax(env.action_values())))
    b = clone.step(int(np.argmax(clone.action_values())))
    assert a[1] == b[1] and a[4]["user"] == b[4]["user"]
    np.testing.assert_array_equal(a[0]["users_xyz"], b[0]["users_xyz"])


@pytest.mark.parametrize("scenario", [paper(), paper().replace(speed_mps=10.0), field(), paper_3d()])
def test_constraints_hold_and_the_budget_binds(scenario):
    env = SortieEnv(scenario)
    budget = (1 - scenario.battery_threshold) * scenario.battery_j
    ended_by_battery = 0
    for seed in range(20):
        trace = greedy_rollout(env, seed)
        used = sum(r["e_hover_j"] + r["e_comp_j"] + r["e_flight_j"] for r in trace)
        assert used <= budget + 1e-6  # (9b)
        assert trace[-1]["battery_j"] == pytest.approx(scenario.battery_j - used)
        counts = np.bincount([r["user"] for r in trace], minlength=scenario.num_users)
        assert counts.max() <= 2  # (9c)
        for i, r in enumerate(trace):  # (3): a repeat only with tasks > beta
            if [x["user"] for x in trace[:i]].count(r["user"]) == 1:
                assert r["tasks"] > scenario.fairness_threshold_tasks
        if env.state.battery_j - scenario.energy_floor_j < 0.2 * budget and not env.action_mask().any():
            ended_by_battery += 1
    if scenario.max_intervals:
        # paper presets: E_0 calibrated so the budget ends most sorties near m = 10 intervals
        assert ended_by_battery >= 10


def test_paper_calibration_lasts_about_ten_intervals():
    env = SortieEnv(paper())
    lengths = [len(greedy_rollout(env, seed)) for seed in range(30)]
    assert 8.5 <= np.mean(lengths) <= 10.0


def test_known_task_table_is_used():
    s = paper().replace(user_move_range_m=0.0)
    table = np.tile(np.arange(1, 11), (4, 1))
    env = SortieEnv(s)
    obs, _ = env.reset(seed=0, options={"task_table": table})
    assert obs["tasks"].tolist() == list(range(1, 11))
    env.step(int(np.argmax(env.action_values())))
    assert env.state.tasks.tolist() == list(range(1, 11))
    np.testing.assert_array_equal(env.state.users, obs["users_xyz"])  # no mobility


def test_bad_actions_and_options_are_refused():
    env = SortieEnv(paper())
    with pytest.raises(ScenarioError, match="reset"):
        env.step(0)
    env.reset(seed=0)
    for bad in (-1, 20, 2.5, "3"):
        with pytest.raises(ScenarioError) as err:
            env.step(bad)
        assert err.value.field == "action"
    with pytest.raises(ScenarioError) as err:
        env.reset(options={"users_xyz": [[0.0, float("nan"), 0.0]] * 10})
    assert err.value.field == "users_xyz"
    with pytest.raises(ScenarioError) as err:
        env.reset(options={"task_table": [[-1] * 10]})
    assert err.value.field == "task_table"
    with pytest.raises(ScenarioError) as err:
        env.reset(options={"wind": 3})
    assert err.value.field == "wind"


def test_cannot_stay_unless_allowed():
    env = SortieEnv(paper())
    env.reset(seed=0)
    a = int(np.argmax(env.action_values()))
    env.step(a)
    assert not env.action_mask()[a]
    stay = SortieEnv(paper().replace(allow_stay=True))
    stay.reset(seed=0)
    stay.step(a)
    assert stay.action_values()[a] > -np.inf or not stay.action_mask().any()


def test_backlog_persists_until_served_and_new_tasks_arrive():
    """task_model = backlog: the served user's tasks leave, everyone else's grow by the
    arrivals (capped at u_max); the first counts are the paper's draws."""
    s = paper().replace(task_model="backlog", task_arrival_mean=1.5)
    env = SortieEnv(s)
    first, _ = env.reset(seed=4)
    redraw = SortieEnv(paper())
    assert first["tasks"].tolist() == redraw.reset(seed=4)[0]["tasks"].tolist()  # same first draw
    grew = 0
    while not env.done:
        before = env.state.tasks.copy()
        *_, info = env.step(int(np.argmax(env.action_values())))
        after = env.state.tasks
        served = info["user"]
        assert info["tasks"] == before[served]
        assert 0 <= after[served] <= 10  # from empty, one interval's arrivals (Poisson 1.5)
        others = np.arange(s.num_users) != served
        assert (after[others] >= np.minimum(before[others], s.task_max)).all() and after.max() <= s.task_max
        grew += int((after[others] > before[others]).sum())
    assert grew > 0


def test_backlog_arrivals_are_poisson_of_the_configured_mean():
    s = paper().replace(task_model="backlog", task_arrival_mean=2.0, num_users=2000, task_max=10_000,
                        user_move_range_m=0.0)
    env = SortieEnv(s)
    env.reset(seed=1)
    before = env.state.tasks.copy()
    env.step(int(np.argmax(env.action_values())))
    arrivals = np.delete(env.state.tasks - before, env.state.served.argmax())
    assert arrivals.mean() == pytest.approx(2.0, abs=0.15) and arrivals.var() == pytest.approx(2.0, abs=0.3)


def test_backlog_task_table_gives_the_arrivals():
    s = paper().replace(task_model="backlog", user_move_range_m=0.0)
    table = np.vstack([np.arange(1, 11), np.full(10, 2), np.full(10, 3)])
    env = SortieEnv(s)
    env.reset(seed=0, options={"task_table": table})
    *_, info = env.step(int(np.argmax(env.action_values())))
    expected = np.arange(1, 11) + 2
    expected[info["user"]] = 2  # served: emptied, then the interval's arrivals
    assert env.state.tasks.tolist() == expected.tolist()


def test_unknown_task_model_is_refused():
    with pytest.raises(ScenarioError) as err:
        paper().replace(task_model="queue")
    assert err.value.field == "task_model"
