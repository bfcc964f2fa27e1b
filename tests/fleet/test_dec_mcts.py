"""``dec-mcts`` (planner_service/fleet/dec_mcts.py, messages.py): its messages round-trip and
stay small, its distribution is the documented softmax, the others' sampled plans reach a
UAV's futures, and lost or late messages degrade it without a double service or hold."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner_service.fleet import DecMctsConfig, MessageError, PlanMessage, decode, make_fleet_policy, run_fleet_sortie
from planner_service.fleet.dec_mcts import LinkModel, distribution
from planner_service.mcts.tree import ROOT_INDEX, Tree
from planner_service.model import preset
from planner_service.model.fleet import Fleet
from planner_service.policy import PolicySpec


def test_a_message_round_trips_and_its_size_is_the_formula() -> None:
    seqs = np.array([[3, 17, -1], [199, 0, 5]])
    message = PlanMessage(2, 7, 12, 999, seqs, np.array([0.75, 0.25]))
    data = message.encode()
    assert len(data) == 10 + 2 * (2 * 3 + 2) == 26
    back = decode(data)
    assert (back.sender, back.interval, back.point, back.user) == (2, 7, 12, 999)
    assert np.array_equal(back.sequences, seqs)
    assert back.probs == pytest.approx([0.75, 0.25], abs=1e-4)
    # the default k = 4, d = 3 at any K and I: 42 bytes, far under the 2 KB
    assert len(PlanMessage(0, 0, -1, -1, np.zeros((4, 3), int), np.full(4, 0.25)).encode()) == 42


def test_bad_messages_name_what_is_wrong() -> None:
    good = PlanMessage(1, 0, 2, 3, np.array([[1, 2, 3]]), np.array([1.0])).encode()
    with pytest.raises(MessageError, match="^length"):
        decode(good[:-1])
    with pytest.raises(MessageError, match="^header"):
        decode(good[:4])
    with pytest.raises(MessageError, match="^version"):
        decode(good[:9] + b"\x09" + good[10:])
    with pytest.raises(MessageError, match="^probs"):
        PlanMessage(1, 0, 2, 3, np.array([[1, 2, 3]]), np.array([0.5])).encode()
    with pytest.raises(MessageError, match="^user"):
        PlanMessage(1, 0, 2, 40000, np.array([[1, 2, 3]]), np.array([1.0])).encode()


def test_the_distribution_is_a_softmax_over_mean_returns_with_a_cooling_temperature() -> None:
    tree = Tree.empty(5, 16)
    # root -> action 2 (node 1, 10 visits) -> actions 0, 4 (nodes 2, 3), node 3 -> action 1 (node 4)
    for node, parent, action, visits, value in ((1, 0, 2, 10, 4.0), (2, 1, 0, 6, 2.4), (3, 1, 4, 4, 2.0),
                                                (4, 3, 1, 4, 2.0)):
        tree.parent[node], tree.action[node] = parent, action
        tree.children[parent, action] = node
        tree.visits[node], tree.value_sum[node] = visits, value
    tree.num_nodes = 5
    keep = np.array([10, 11, 12, 13, 14])  # the view's point a is the fleet's 10 + a
    seqs, probs = distribution(tree, 2, keep, DecMctsConfig(top_k=4, depth=2, temperature=0.1))
    assert seqs.tolist() == [[10, -1], [14, 11]]  # most visited first, lines padded with AT_BASE
    tau = 0.1 / math.sqrt(1 + 10 / 2)  # two children: k = 2
    w = np.exp(np.array([0.0, (0.5 - 0.4)]) / tau)  # means 0.4 and 0.5
    assert probs == pytest.approx(w / w.sum())
    assert distribution(tree, 3, keep, DecMctsConfig())[0].shape == (0, 3)  # never tried: nothing to say
    assert tree.children[ROOT_INDEX, 2] == 1


def test_the_link_drops_and_delays_as_told() -> None:
    link = LinkModel(3, 0.0, 2, np.random.default_rng(0))
    for t in range(3):
        link.send(0, PlanMessage(0, t, t, -1, np.zeros((0, 3), int), np.zeros(0)).encode())
    assert link.inbox(1)[0].interval == 0  # two intervals late: the first of three
    assert 0 not in link.inbox(0)
    lossy = LinkModel(2, 1.0, 0, np.random.default_rng(0))
    lossy.send(0, PlanMessage(0, 0, 1, -1, np.zeros((0, 3), int), np.zeros(0)).encode())
    assert lossy.inbox(1) == {}


def test_the_others_plans_reach_a_uavs_futures() -> None:
    """UAV 1 deciding after UAV 0: its futures have no tasks for the users UAV 0's
    published sequences take, in the rows of the intervals that take them."""
    from planner_service.fleet import fleet_streams
    from planner_service.model.fleet import FleetEnv
    scenario = preset("field").replace(num_users=30, num_hover_points=20)
    env = FleetEnv(scenario, Fleet(uavs=2))
    world, rngs = fleet_streams(3, 2)
    env.rng = world
    env.reset()
    policy = make_fleet_policy("dec-mcts", "mcts", PolicySpec(300), rngs)
    policy.begin(env)
    first = policy.decide(env)
    env.step(first.action, first.line[1] if len(first.line) > 1 else -1)
    message = policy.link.inbox(1)[0]
    assert message.point == first.action and len(message.probs) > 0
    users = policy._sequence_users(env, 0, message, env.state.tasks.copy())
    shaper = policy._shaper(env, 1, {0: message}, env.state.tasks.copy())
    news = np.ones((64, 5, scenario.num_users), dtype=np.int64)
    shaper(np.zeros((64, 5, scenario.num_users, 3)), news)
    for m in range(min(3, 5)):
        zeroed = {u for u in range(scenario.num_users) if (news[:, m, u] == 0).any()}
        assert zeroed == {row[m] for row in users if row[m] >= 0}, m
    assert (news[:, 3:] == 1).all()  # d = 3: nothing said beyond


@pytest.mark.parametrize("drop,age", [(0.5, 0), (1.0, 0), (0.2, 3)])
def test_lost_and_late_messages_degrade_without_a_double_service(drop: float, age: int) -> None:
    scenario = preset("field").replace(num_users=30, num_hover_points=24)
    for seed in range(2):
        out = run_fleet_sortie(scenario, Fleet(uavs=4), "dec-mcts", seed, PolicySpec(200),
                               settings={"drop": drop, "age": age})
        f = out["fleet"]
        assert f["double_services"] == f["double_holds"] == 0 and f["fairness_violations"] == 0
        assert 0 < f["message_bytes_max"] <= 42


def test_every_message_lost_is_independent_but_for_what_it_held_in_common() -> None:
    """With drop = 1 no UAV hears another: each plans its blind view, as ``independent``
    does, with the same generators: the same sortie."""
    scenario = preset("field").replace(num_users=30, num_hover_points=24)
    for seed in range(2):
        blind = run_fleet_sortie(scenario, Fleet(uavs=3), "dec-mcts", seed, PolicySpec(300), settings={"drop": 1.0})
        independent = run_fleet_sortie(scenario, Fleet(uavs=3), "independent", seed, PolicySpec(300))
        assert blind["events"] == independent["events"]


def test_dec_mcts_settings_are_checked() -> None:
    from planner_service.fleet import fleet_streams
    rngs = fleet_streams(0, 2)[1]
    with pytest.raises(ValueError, match="drop must lie"):
        make_fleet_policy("dec-mcts", "mcts", PolicySpec(), rngs, drop=1.5)
    with pytest.raises(ValueError, match="fleet planner 'dec-mcts'"):
        make_fleet_policy("dec-mcts", "mcts", PolicySpec(), rngs, loss=0.5)
    with pytest.raises(ValueError, match="with mcts"):
        make_fleet_policy("dec-mcts", "greedy", PolicySpec(), rngs)
    with pytest.raises(ValueError, match="takes no settings"):
        make_fleet_policy("independent", "mcts", PolicySpec(), rngs, drop=0.5)
