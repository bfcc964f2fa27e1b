"""The numpy Q-network: backpropagation against finite differences, Adam by hand."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.baselines.mlp import MLP, Adam


def test_gradient_matches_central_differences():
    rng = np.random.default_rng(7)
    net = MLP((5, 7, 6, 3), rng)
    for p in net.params[1::2]:
        p[...] = rng.normal(0.0, 0.1, size=p.shape)  # non-zero biases, so their gradient is tested too
    x = rng.normal(size=(4, 5))
    actions = np.array([0, 2, 1, 2])
    targets = rng.normal(size=4)
    _, grads = net.loss_and_grad(x, actions, targets)
    h = 1e-6
    for p, g in zip(net.params, grads):
        numeric = np.zeros_like(p)
        for idx in np.ndindex(p.shape):
            keep = p[idx]
            p[idx] = keep + h
            up, _ = net.loss_and_grad(x, actions, targets)
            p[idx] = keep - h
            down, _ = net.loss_and_grad(x, actions, targets)
            p[idx] = keep
            numeric[idx] = (up - down) / (2 * h)
        np.testing.assert_allclose(g, numeric, rtol=1e-5, atol=1e-8)


def test_loss_is_mean_squared_error_on_the_taken_action():
    net = MLP((2, 3), np.random.default_rng(0))  # one linear layer: Q = x W + b
    net.params[0][...] = [[1.0, 2.0, 3.0], [0.0, -1.0, 1.0]]
    net.params[1][...] = [0.5, 0.0, 0.0]
    x = np.array([[1.0, 1.0], [2.0, 0.0]])
    # Q rows: [1.5, 1, 4] and [2.5, 4, 6]; taken actions 2 and 0 -> 4 and 2.5.
    loss, grads = net.loss_and_grad(x, np.array([2, 0]), np.array([3.0, 3.5]))
    assert loss == pytest.approx(((4 - 3) ** 2 + (2.5 - 3.5) ** 2) / 2)
    # dL/dQ = 2 e / B: +1 at (0, 2), -1 at (1, 0); dL/dW = x^T dL/dQ.
    np.testing.assert_allclose(grads[0], [[-2.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(grads[1], [-1.0, 0.0, 1.0])


def test_adam_first_step_moves_by_the_learning_rate():
    p = np.array([1.0, -1.0])
    opt = Adam([p], learning_rate=0.1)
    # After bias correction m_hat = g and v_hat = g^2, so the first step is lr * sign(g).
    opt.step([np.array([2.0, -0.5])])
    np.testing.assert_allclose(p, [0.9, -0.9], rtol=1e-6)


def test_adam_fits_a_linear_map():
    rng = np.random.default_rng(3)
    net = MLP((3, 16, 2), rng)
    opt = Adam(net.params, learning_rate=1e-2)
    w_true = np.array([[1.0, -2.0], [0.5, 0.0], [-1.0, 1.5]])
    x = rng.normal(size=(64, 3))
    actions = rng.integers(0, 2, size=64)
    y = (x @ w_true)[np.arange(64), actions]
    first, _ = net.loss_and_grad(x, actions, y)
    for _ in range(500):
        loss, grads = net.loss_and_grad(x, actions, y)
        opt.step(grads)
    assert loss < 0.01 * first


def test_copy_from_is_a_copy_not_an_alias():
    a = MLP((3, 4, 2), np.random.default_rng(1))
    b = MLP((3, 4, 2), np.random.default_rng(2))
    b.copy_from(a)
    x = np.ones((1, 3))
    np.testing.assert_array_equal(a.forward(x), b.forward(x))
    a.params[0] += 1.0
    assert not np.array_equal(a.forward(x), b.forward(x))


def test_bad_shapes_raise():
    with pytest.raises(ValueError):
        MLP((3,), np.random.default_rng(0))
    with pytest.raises(ValueError):
        MLP((3, 4, 2), np.random.default_rng(0)).copy_from(MLP((3, 5, 2), np.random.default_rng(0)))
