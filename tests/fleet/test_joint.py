"""``joint`` (planner_service/fleet/joint.py): one search over the fleet's plan; it refuses
fleets whose joint action space is too large, never touches the world's generator, and
flies without a double service or hold."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.fleet import MAX_JOINT_ACTIONS, fleet_streams, make_fleet_policy, run_fleet_sortie
from planner_service.model import preset
from planner_service.model.fleet import Fleet, FleetEnv
from planner_service.policy import PolicySpec


def test_joint_refuses_a_joint_action_space_beyond_its_size() -> None:
    env = FleetEnv(preset("fleet"), Fleet(uavs=3))  # 40^3 = 64000
    env.reset(seed=0)
    policy = make_fleet_policy("joint", "mcts", PolicySpec(10), fleet_streams(0, 3)[1])
    with pytest.raises(ValueError, match=f"40\\^3 = 64000 joint actions, more than {MAX_JOINT_ACTIONS}"):
        policy.begin(env)
    with pytest.raises(ValueError, match="base 'greedy'"):
        make_fleet_policy("joint", "greedy", PolicySpec(10), fleet_streams(0, 3)[1])


def test_joint_plans_from_the_real_state_without_the_worlds_generator() -> None:
    """A decision leaves the environment and its generator as they were, and repeats with
    the same planner generator."""
    scenario = preset("field")
    env = FleetEnv(scenario, Fleet(uavs=2))
    env.rng = np.random.default_rng(5)
    env.reset()
    before = env.rng.bit_generator.state
    decisions = []
    for _ in range(2):
        policy = make_fleet_policy("joint", "mcts", PolicySpec(200), [np.random.default_rng(1), np.random.default_rng(2)])
        policy.begin(env)
        decisions.append(policy.decide(env))
    assert env.rng.bit_generator.state == before and env.state.intervals.sum() == 0
    assert (decisions[0].action, decisions[0].line) == (decisions[1].action, decisions[1].line)
    assert env.action_mask(env.due)[decisions[0].action] and decisions[0].line[0] == decisions[0].action


def test_joint_flies_without_a_double_service_or_hold() -> None:
    scenario = preset("field").replace(num_users=16, num_hover_points=12)
    for seed in range(2):
        f = run_fleet_sortie(scenario, Fleet(uavs=3), "joint", seed, PolicySpec(100))["fleet"]
        assert f["double_services"] == f["double_holds"] == f["fairness_violations"] == 0
        assert f["blocked_choices"] == 0 and f["services"] > 10
