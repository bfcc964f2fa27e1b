"""Q-learning and DQN: the update by hand, learning on a tiny static instance,
determinism, and leaving the real sortie untouched while training."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.baselines import BASELINES, DQNConfig, DQNPolicy, QLearningConfig, QLearningPolicy
from planner_service.baselines.dqn import Features
from planner_service.baselines.qlearning import QTable
from planner_service.model import SortieEnv, paper
from planner_service.policy import PolicySpec
from planner_service.registry import make_policy
from planner_service.sortie import fly, run_sortie

# A static problem: users never move and the task schedule is known for every interval, so
# a route's return is deterministic and both the optimum and random's expectation can be
# computed exactly by enumerating every route.
TINY = paper().replace(
    name="tiny", num_hover_points=6, hover_layout="uniform", num_users=4, user_move_range_m=0.0, max_intervals=5
)
TABLE = np.array([[12, 5, 18, 9], [7, 16, 3, 14], [19, 11, 8, 17], [4, 20, 13, 6], [16, 9, 18, 19]])


def tiny_env() -> SortieEnv:
    env = SortieEnv(TINY)
    env.reset(seed=0, options={"task_table": TABLE})
    return env


def best_and_random_return(env: SortieEnv) -> tuple[float, float]:
    """Exact (max, uniform-random expectation) of the sortie's total reward from here."""
    if env.done:
        return 0.0, 0.0
    snap = env.snapshot()
    best, mean = [], []
    for a in np.flatnonzero(env.action_mask()):
        _, r, *_ = env.step(int(a))
        b, m = best_and_random_return(env)
        best.append(r + b)
        mean.append(r + m)
        env.restore(snap)
    return max(best), float(np.mean(mean))


def sortie_return(policy) -> float:
    env = tiny_env()
    trace, _ = fly(env, policy)
    return sum(r["reward"] for r in trace)


@pytest.fixture(scope="module")
def bound() -> float:
    optimum, random_mean = best_and_random_return(tiny_env())
    assert optimum > random_mean + 0.3  # the instance leaves room to learn
    # "Clearly better than random": at least halfway from random's expectation to the optimum.
    return random_mean + 0.5 * (optimum - random_mean)


def test_q_update_by_hand():
    env = tiny_env()
    table = QTable(env, interval_cap=16)
    cfg = QLearningConfig(learning_rate=0.1, gamma=1.0)
    table.values[0, 0, 2] = 0.2
    table.values[1, 3, :] = [1.0, 5.0, -1.0, 0.5, 0.0, 0.0]
    mask = np.array([True, False, True, True, False, False])
    table.update((0, 0), 2, 0.5, (1, 3), mask, False, cfg)
    # 0.2 + 0.1 * (0.5 + max(1.0, -1.0, 0.5) - 0.2) = 0.33; the masked 5.0 is ignored.
    assert table.values[0, 0, 2] == pytest.approx(0.33)
    table.update((0, 0), 2, 0.5, (1, 3), mask, True, cfg)
    # done: 0.33 + 0.1 * (0.5 - 0.33) = 0.347
    assert table.values[0, 0, 2] == pytest.approx(0.347)


def test_q_table_cell_is_interval_and_position():
    env = tiny_env()
    table = QTable(env, interval_cap=16)
    assert table.values.shape == (5, 7, 6)
    assert table.index(env) == (0, 0)  # at base
    env.step(int(np.flatnonzero(env.action_mask())[-1]))
    assert table.index(env) == (1, env.state.hover_index + 1)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_q_learning_beats_random_on_the_static_instance(bound, seed):
    assert sortie_return(QLearningPolicy(QLearningConfig(), 300, np.random.default_rng(seed))) >= bound


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_dqn_beats_random_on_the_static_instance(bound, seed):
    assert sortie_return(DQNPolicy(DQNConfig(), 300, np.random.default_rng(seed))) >= bound


def test_features_layout():
    env = tiny_env()
    features = Features(env, interval_cap=16)
    x, mask = features(env)
    k, i = 6, 4
    assert x.shape == (features.dim,) == ((k + 1) + 2 + 4 * i + 2 * k,)
    assert x[0] == 1.0 and x[1 : k + 1].sum() == 0.0  # at base
    assert x[k + 1] == pytest.approx(1.0)  # full battery
    assert x[k + 2] == 0.0  # first interval
    users = x[k + 3 : k + 3 + 4 * i].reshape(i, 4)
    np.testing.assert_allclose(users[:, 2], TABLE[0] / TINY.task_max)
    np.testing.assert_allclose(users[0, :2], [125.0 / 500.0, 200.0 / 500.0])
    q = env.action_values()
    np.testing.assert_allclose(x[-2 * k : -k], np.where(mask, q, 0.0))
    np.testing.assert_array_equal(x[-k:], mask)


@pytest.mark.parametrize("algo", ["ql", "dqn"])
def test_same_seed_same_sortie(algo):
    spec = PolicySpec(iterations=30)
    a = run_sortie(paper(), algo, seed=4, spec=spec)
    b = run_sortie(paper(), algo, seed=4, spec=spec)
    assert a["hover_points"] == b["hover_points"]
    assert [r["reward"] for r in a["trace"]] == [r["reward"] for r in b["trace"]]


@pytest.mark.parametrize("algo", ["ql", "dqn"])
def test_training_leaves_the_real_sortie_untouched(algo):
    env = SortieEnv(paper())
    env.reset(seed=11)
    before = env.snapshot()
    policy = make_policy(algo, PolicySpec(iterations=20), np.random.default_rng(0))
    policy.begin(env)
    policy.decide(env)
    after = env.snapshot()
    assert after.rng_state == before.rng_state  # the real future was not drawn from
    np.testing.assert_array_equal(after.state.users, before.state.users)
    np.testing.assert_array_equal(after.state.tasks, before.state.tasks)
    np.testing.assert_array_equal(after.state.served, before.state.served)
    assert after.state.battery_j == before.state.battery_j and after.state.interval == 0
    assert policy.report.episodes == 20 and policy.report.steps > 20


@pytest.mark.parametrize("algo", ["ql", "dqn"])
def test_registered_and_logs_its_hyperparameters(algo):
    assert algo in BASELINES
    env = SortieEnv(paper())
    env.reset(seed=3)
    policy = make_policy(algo, PolicySpec(iterations=5), np.random.default_rng(0))
    policy.begin(env)
    decision = policy.decide(env)
    assert env.action_mask()[decision.action]
    assert decision.iterations == 5
    assert decision.extra["config"]["gamma"] == 1.0
    assert decision.extra["training"]["episodes"] == 5


def test_bad_configs_raise():
    with pytest.raises(ValueError):
        QLearningConfig(learning_rate=0.0)
    with pytest.raises(ValueError):
        DQNConfig(batch_size=0)
    with pytest.raises(ValueError):
        DQNPolicy(DQNConfig(), -1, np.random.default_rng(0))


@pytest.mark.parametrize("algo", ["ql", "dqn"])
def test_a_time_budget_alone_is_refused(algo):
    with pytest.raises(ValueError, match="training episodes"):
        make_policy(algo, PolicySpec(iterations=None, budget_ms=50.0), np.random.default_rng(0))
