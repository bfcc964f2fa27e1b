"""The fleet model (``model/fleet``): a fleet of one is today's environment draw for draw;
the joint rules are enforced (an illegal joint state raises) and hold in every sortie; the
event order; the UAVs' own parameters."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.model import AT_BASE, NO_USER, ScenarioError, SortieEnv, preset
from planner_service.model.channel import channel_gain
from planner_service.model.fleet import Fleet, FleetEnv, FleetError, check_joint
from planner_service.model.fleet.audit import Hold, overlaps
from planner_service.model.interval import served_user


def _random_fleet_sortie(env: FleetEnv, seed: int) -> list[dict]:
    """Fly ``env`` (reset) to the end with uniform allowed choices; every step's record."""
    rng = np.random.default_rng(seed)
    records = []
    while not env.done:
        j = env.due
        st = env.state
        live = np.flatnonzero(st.active)
        assert st.clock_s[j] == st.clock_s[live].min(), "the due UAV is not the one whose interval ends first"
        allowed = np.flatnonzero(env.action_mask(j))
        assert len(allowed), "a due UAV always has an allowed action"
        action = int(rng.choice(allowed))
        intent = int(rng.choice(allowed))
        _, _, _, _, info = env.step(action, intent)
        assert info["uav"] == j and info["end_s"] > info["start_s"]
        records.append(info)
    return records


@pytest.mark.parametrize("name", ["paper", "field", "paper-3d"])
def test_a_fleet_of_one_is_the_single_uav_environment(name: str) -> None:
    for seed in range(3):
        single, fleet = SortieEnv(preset(name)), FleetEnv(preset(name), Fleet(uavs=1))
        single.reset(seed=seed)
        fleet.reset(seed=seed)
        rng = np.random.default_rng(100 + seed)
        steps = 0
        while not single.done:
            mask = single.action_mask()
            assert np.array_equal(mask, fleet.action_mask(0))
            assert np.array_equal(single.action_values(), fleet.action_values(0))
            action = int(rng.choice(np.flatnonzero(mask)))
            _, r1, _, _, a = single.step(action)
            _, r2, _, _, b = fleet.step(action)
            assert r1 == r2
            assert {k: v for k, v in a.items() if k != "action_mask"} == {k: b[k] for k in a if k != "action_mask"}
            steps += 1
        assert fleet.done and steps > 3
        assert np.array_equal(single.state.users, fleet.state.users)
        assert np.array_equal(single.state.tasks, fleet.state.tasks)


def test_a_fleet_of_one_keeps_a_known_task_table_and_arrivals_in_time() -> None:
    scenario = preset("field").replace(task_model="backlog", task_arrival_period_s=55.0)
    table = np.random.default_rng(3).integers(0, 20, size=(12, scenario.num_users))
    single, fleet = SortieEnv(scenario), FleetEnv(scenario, Fleet(uavs=1))
    single.reset(seed=4)
    fleet.reset(seed=4)
    while not single.done:
        action = int(np.argmax(single.action_values()))
        single.step(action)
        fleet.step(action)
        assert np.array_equal(single.state.tasks, fleet.state.tasks)
    assert fleet.done
    s2 = preset("paper")
    single, fleet = SortieEnv(s2), FleetEnv(s2, Fleet(uavs=1))
    single.reset(seed=1, options={"task_table": table})
    fleet.reset(seed=1, options={"task_table": table})
    while not single.done:
        action = int(np.argmax(single.action_values()))
        assert single.step(action)[1] == fleet.step(action)[1]


def test_an_illegal_joint_state_raises() -> None:
    env = FleetEnv(preset("field"), Fleet(uavs=3))
    env.reset(seed=0)
    check_joint(env.state)  # the start is legal: everyone at base
    for _ in range(3):
        env.step(int(np.argmax(env.action_values(env.due))))
    st = env.state
    a, b = 0, 1
    same_point = st.copy()
    same_point.hover[b] = same_point.hover[a]
    with pytest.raises(FleetError, match=f"both hold hovering point {st.hover[a]}") as err:
        check_joint(same_point)
    assert err.value.field == "hover"
    same_user = st.copy()
    same_user.bound[b] = same_user.bound[a]
    assert same_user.bound[a] != NO_USER
    with pytest.raises(FleetError, match="served by UAVs") as err:
        check_joint(same_user)
    assert err.value.field == "user"
    retired = same_point.copy()  # a UAV that stopped holds nothing
    retired.active[b] = False
    check_joint(retired)


def test_a_point_another_uav_holds_is_refused() -> None:
    env = FleetEnv(preset("field"), Fleet(uavs=2))
    env.reset(seed=0)
    first = env.due
    taken = int(np.argmax(env.action_values(first)))
    env.step(taken)
    second = env.due
    assert second != first
    assert not env.action_mask(second)[taken]
    assert env.action_values(second)[taken] == -np.inf
    with pytest.raises(FleetError, match="held by another UAV"):
        env.step(taken)
    with pytest.raises(FleetError, match="hovering-point index"):
        env.step(10_000)
    with pytest.raises(FleetError, match="intent"):
        env.step(int(np.argmax(env.action_values(second))), intent=10_000)


def test_the_user_another_uav_serves_goes_to_the_next_nearest() -> None:
    """Two UAVs asking for the same user: the first in event order binds it, the second
    serves its next nearest eligible user (docs/MODEL.md, "A fleet")."""
    # a second service needs no more than one task, so the first UAV's user stays eligible
    scenario = preset("field").replace(fairness_threshold_tasks=0, max_services_per_user=5)
    env = FleetEnv(scenario, Fleet(uavs=2, layer_m=0.0))
    env.reset(seed=2)
    first = env.due
    q = env.action_values(first)
    action = int(np.argmax(q))
    _, _, _, _, a = env.step(action)
    second = env.due
    near = [k for k in range(env.num_actions) if k != action and np.isfinite(env.action_values(second)[k])]
    # a point whose nearest eligible user, blind to the first UAV, is the first's user
    blind = env.view(second)
    same = [k for k in near if served_user(env.params[second], env.hover_points[second][k], blind.state.users,
                                           blind.state.tasks, blind.state.served) == a["user"]]
    assert same, "no point near the first UAV's user: the test needs another seed"
    _, _, _, _, b = env.step(same[0])
    assert b["user"] not in (a["user"], NO_USER)


@pytest.mark.parametrize("uavs", [2, 3, 5])
def test_the_joint_rules_hold_in_every_sortie(uavs: int) -> None:
    scenario = preset("field").replace(num_users=30, num_hover_points=30)
    for seed in range(4):
        env = FleetEnv(scenario, Fleet(uavs=uavs))
        env.reset(seed=seed)
        records = _random_fleet_sortie(env, seed)
        holds = [Hold(r["uav"], r["hover_point"], r["user"], r["start_s"], r["end_s"]) for r in records]
        assert overlaps(holds) == (0, 0)
        assert {r["uav"] for r in records} == set(range(uavs)), "some UAV never flew"
        served = np.zeros(scenario.num_users, dtype=int)
        for r in records:
            served[r["user"]] += 1
        assert np.array_equal(served, env.state.served), "the service counts are the fleet's"
        assert served.max() <= scenario.max_services_per_user


def test_the_audit_counts_overlaps_of_two_uavs_only() -> None:
    holds = [Hold(0, 1, 2, 0.0, 10.0), Hold(1, 1, 2, 5.0, 12.0),  # same point and user, overlapping
             Hold(1, 3, 4, 12.0, 20.0), Hold(0, 3, 4, 20.0, 21.0),  # back to back: no overlap
             Hold(0, 5, 6, 30.0, 40.0), Hold(0, 5, 6, 35.0, 41.0)]  # one UAV: not a double
    assert overlaps(holds) == (1, 1)
    assert overlaps([Hold(0, AT_BASE, NO_USER, 0, 5), Hold(1, AT_BASE, NO_USER, 0, 5)]) == (0, 0)


def test_same_seed_same_fleet_sortie() -> None:
    scenario = preset("field").replace(num_users=30)
    runs = []
    for _ in range(2):
        env = FleetEnv(scenario, Fleet(uavs=3))
        env.reset(seed=7)
        runs.append(_random_fleet_sortie(env, 7))
    assert runs[0] == runs[1]
    env = FleetEnv(scenario, Fleet(uavs=3))
    env.reset(seed=7)
    snap = env.snapshot()
    first = _random_fleet_sortie(env, 1)
    env.restore(snap)
    assert _random_fleet_sortie(env, 1) == first


def test_each_uav_flies_its_own_layer_base_speed_and_battery() -> None:
    scenario = preset("field")
    fleet = Fleet(uavs=3, layer_m=20.0, base_step_m=50.0, speeds_mps=(10.0, 15.0, 20.0),
                  batteries_j=(90e3, 100e3, 110e3))
    env = FleetEnv(scenario, fleet)
    obs, _ = env.reset(seed=0)
    assert obs["uav_xyz"].tolist() == [[0.0, 0.0, 100.0], [50.0, 0.0, 120.0], [100.0, 0.0, 140.0]]
    assert obs["battery_j"].tolist() == [90e3, 100e3, 110e3]
    for j in range(3):
        assert np.all(env.hover_points[j][:, 2] == 100.0 + 20.0 * j)
        assert np.array_equal(env.hover_points[j][:, :2], env.hover_points[0][:, :2])
    assert [s.speed_mps for s in env.scenarios] == [10.0, 15.0, 20.0]
    user = np.array([20.0, 20.0, 0.0])  # below hovering point 0
    gains = [channel_gain(env.params[j], env.hover_points[j][0], user) for j in range(3)]
    assert gains[0] > gains[1] > gains[2]  # (5): rho_0 / d^2, d grows with the layer
    assert gains[0] / gains[2] == pytest.approx(140.0**2 / 100.0**2)


def test_bad_fleet_parameters_name_the_field() -> None:
    with pytest.raises(ScenarioError, match="speeds_mps") as err:
        Fleet(uavs=2, speeds_mps=(10.0,))
    assert err.value.field == "speeds_mps"
    with pytest.raises(ScenarioError, match="uavs") as err:
        Fleet(uavs=0)
    assert err.value.field == "uavs"
    with pytest.raises(ScenarioError, match="base_step_m"):
        FleetEnv(preset("field"), Fleet(uavs=3, base_step_m=400.0))
    env = FleetEnv(preset("field"), Fleet(uavs=2))
    with pytest.raises(FleetError, match="reset"):
        env.due
    with pytest.raises(FleetError, match="arrivals_every_s"):
        env.reset(options={"arrivals_every_s": 55})


def test_the_fleet_preset_is_field_with_users_ample_for_five() -> None:
    fleet, field = preset("fleet"), preset("field")
    assert (fleet.num_users, fleet.num_hover_points, fleet.name) == (60, 40, "fleet")
    assert fleet.replace(name="field", num_users=10, num_hover_points=20) == field
    env = FleetEnv(fleet, Fleet(uavs=5))
    env.reset(seed=0)
    assert len(env.hover_points[0]) == 40 and env.state.users.shape == (60, 3)


def test_a_fleets_arrivals_in_time_follow_one_clock() -> None:
    """With arrivals in time, the users' new tasks are drawn up to the fleet's time (the clock
    of the UAV whose turn it is), each span once: three UAVs meet the arrivals of one clock,
    not three."""
    scenario = preset("field").replace(task_model="backlog", task_arrival_period_s=55.0, num_users=10)
    env = FleetEnv(scenario, Fleet(uavs=3, layer_m=20.0))
    env.rng = np.random.default_rng(4)
    env.reset()
    drawn, steps = [], 0
    while not env.done and steps < 40:
        j = env.due
        st = env.state
        assert st is not None and env._arrivals_until_s == pytest.approx(float(st.clock_s[j]))
        drawn.append(env._arrivals_until_s)
        env.step(int(np.flatnonzero(env.action_mask(j))[0]))
        steps += 1
    assert steps > 3 and drawn == sorted(drawn)  # the fleet's time only goes on
    # the fleet's time is the slowest active clock, never the sum of the UAVs' intervals
    assert drawn[-1] <= max(float(c) for c in env.state.clock_s) + 1e-9
