"""A small multilayer perceptron and Adam, on numpy, for the DQN baseline.

torch from the registry pulls gigabytes of CUDA packages the flight side should not carry, so
the Q-network is written out by hand:
ReLU hidden layers, a linear output of one value per action, the squared TD error on the
taken action, and its gradient by backpropagation. Shapes: inputs (B, D), outputs (B, A).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


class MLP:
    """ReLU network; ``params`` is ``[W1, b1, W2, b2, ...]`` with ``W`` (fan_in, fan_out)."""

    def __init__(self, sizes: Sequence[int], rng: np.random.Generator) -> None:
        if len(sizes) < 2 or any(int(n) < 1 for n in sizes):
            raise ValueError(f"an MLP needs at least an input and an output size, all positive; got {sizes}")
        self.sizes = tuple(int(n) for n in sizes)
        self.params: list[np.ndarray] = []
        for fan_in, fan_out in zip(self.sizes[:-1], self.sizes[1:]):
            # He initialisation keeps ReLU activations at a stable scale through the layers.
            self.params.append(rng.normal(0.0, np.sqrt(2.0 / fan_in), size=(fan_in, fan_out)))
            self.params.append(np.zeros(fan_out))

    def forward(self, x: np.ndarray) -> np.ndarray:
        """Q-values (B, A) of inputs ``x`` (B, D)."""
        return self._forward(x)[-1]

    def _forward(self, x: np.ndarray) -> list[np.ndarray]:
        # Keep every layer's output: the backward pass needs the activations.
        acts = [x]
        n_layers = len(self.params) // 2
        for layer in range(n_layers):
            w, b = self.params[2 * layer], self.params[2 * layer + 1]
            z = acts[-1] @ w + b
            acts.append(np.maximum(z, 0.0) if layer < n_layers - 1 else z)
        return acts

    def loss_and_grad(
        self, x: np.ndarray, actions: np.ndarray, targets: np.ndarray
    ) -> tuple[float, list[np.ndarray]]:
        """Mean squared error between Q(x)[actions] and ``targets`` (both (B,)), and its
        gradient with respect to every parameter (same shapes as ``params``)."""
        acts = self._forward(x)
        rows = np.arange(len(actions))
        error = acts[-1][rows, actions] - targets
        loss = float(np.mean(error**2))
        # Only the taken action's output enters the loss: its gradient is 2 e / B, others 0.
        delta = np.zeros_like(acts[-1])
        delta[rows, actions] = 2.0 * error / len(actions)
        grads: list[np.ndarray] = [np.empty(0)] * len(self.params)
        for layer in range(len(self.params) // 2 - 1, -1, -1):
            grads[2 * layer] = acts[layer].T @ delta
            grads[2 * layer + 1] = delta.sum(axis=0)
            if layer > 0:
                # ReLU passes the gradient where its output was positive.
                delta = (delta @ self.params[2 * layer].T) * (acts[layer] > 0.0)
        return loss, grads

    def copy_from(self, other: "MLP") -> None:
        """Take ``other``'s weights (the target network's hard update)."""
        if other.sizes != self.sizes:
            raise ValueError(f"cannot copy a {other.sizes} network into a {self.sizes} one")
        for mine, theirs in zip(self.params, other.params):
            mine[...] = theirs


class Adam:
    """Adam (Kingma and Ba, 2015) updating a list of arrays in place."""

    def __init__(
        self,
        params: list[np.ndarray],
        learning_rate: float,
        beta1: float = 0.9,
        beta2: float = 0.999,
        eps: float = 1e-8,
    ) -> None:
        if not learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {learning_rate}")
        self.params = params
        self.learning_rate = learning_rate
        self.beta1, self.beta2, self.eps = beta1, beta2, eps
        self.m = [np.zeros_like(p) for p in params]
        self.v = [np.zeros_like(p) for p in params]
        self.t = 0

    def step(self, grads: list[np.ndarray]) -> None:
        """One update of every parameter against its gradient."""
        self.t += 1
        # Bias corrections folded into the step size: Kingma and Ba's efficient form (end of their Sec. 2).
        scale = self.learning_rate * np.sqrt(1.0 - self.beta2**self.t) / (1.0 - self.beta1**self.t)
        for p, g, m, v in zip(self.params, grads, self.m, self.v):
            m *= self.beta1
            m += (1.0 - self.beta1) * g
            v *= self.beta2
            v += (1.0 - self.beta2) * g * g
            p -= scale * m / (np.sqrt(v) + self.eps)
