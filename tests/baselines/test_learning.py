"""TD target, schedule, masked choice and replay, against numbers worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.baselines.learning import linear_schedule, masked_argmax, td_target
from planner_service.baselines.replay import ReplayBuffer


def test_td_target_by_hand():
    rewards = np.array([0.5, -0.2, 0.1, 0.3])
    next_values = np.array([[1.0, 3.0, 2.0], [4.0, 0.0, -1.0], [7.0, 8.0, 9.0], [5.0, 6.0, 7.0]])
    masks = np.array([[1, 0, 1], [0, 1, 1], [1, 1, 1], [0, 0, 0]], dtype=bool)
    dones = np.array([False, False, True, False])
    y = td_target(rewards, next_values, masks, dones, gamma=0.9)
    # row 0: the 3.0 is masked -> 0.5 + 0.9 * 2 = 2.3
    # row 1: the 4.0 is masked -> -0.2 + 0.9 * 0 = -0.2
    # row 2: done -> no bootstrap -> 0.1
    # row 3: nothing allowed next -> no bootstrap -> 0.3
    np.testing.assert_allclose(y, [2.3, -0.2, 0.1, 0.3])


def test_td_target_single_transition():
    y = td_target(0.25, np.array([-1.0, -0.5, 2.0]), np.array([True, True, False]), False, gamma=1.0)
    assert float(y) == pytest.approx(0.25 - 0.5)


def test_linear_schedule():
    assert linear_schedule(1.0, 0.05, 50, 0) == pytest.approx(1.0)
    assert linear_schedule(1.0, 0.05, 50, 25) == pytest.approx(0.525)
    assert linear_schedule(1.0, 0.05, 50, 50) == pytest.approx(0.05)
    assert linear_schedule(1.0, 0.05, 50, 80) == pytest.approx(0.05)
    assert linear_schedule(1.0, 0.05, 0, 0) == pytest.approx(0.05)


def test_masked_argmax_ignores_disallowed_and_breaks_ties_with_the_rng():
    values = np.array([9.0, 1.0, 3.0, 3.0])
    mask = np.array([False, True, True, True])
    assert masked_argmax(values, mask) == 2
    rng = np.random.default_rng(0)
    picks = {masked_argmax(values, mask, rng) for _ in range(50)}
    assert picks == {2, 3}
    with pytest.raises(ValueError):
        masked_argmax(values, np.zeros(4, dtype=bool))


def test_replay_buffer_keeps_the_latest_transitions():
    rb = ReplayBuffer(capacity=3, obs_dim=2, num_actions=2)
    for i in range(5):
        rb.add(np.full(2, i), i, float(i), np.full(2, i + 1), np.array([True, i % 2 == 0]), i == 4)
    assert rb.size == 3
    assert sorted(rb.actions.tolist()) == [2, 3, 4]
    batch = rb.sample(100, np.random.default_rng(0))
    assert set(batch.actions.tolist()) == {2, 3, 4}
    # every field of a sampled row belongs to the same transition
    np.testing.assert_array_equal(batch.obs[:, 0], batch.actions)
    np.testing.assert_array_equal(batch.next_obs[:, 0], batch.actions + 1)
    np.testing.assert_array_equal(batch.rewards, batch.actions)
    np.testing.assert_array_equal(batch.dones, batch.actions == 4)
    np.testing.assert_array_equal(batch.next_masks[:, 1], batch.actions % 2 == 0)
