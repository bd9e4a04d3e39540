"""Dense layers, leaky ReLU and residual blocks with a forward cache and hand-written backward passes.

Chen, Wang & Wang 2024, sec. 4.2 and Fig. 3: fully connected layers with leaky ReLU activations; a residual
block is two FC layers "with a skip connection before the last leaky ReLU":

    y = lrelu(x + W2 lrelu(W1 x + b1) + b2)

Every layer keeps what its backward pass needs from the last ``forward(x, train=True)`` call and writes the
gradients of its parameters into ``grads`` (same names as ``params``).  Arrays keep the dtype of the
parameters (float32 for training and inference, float64 for the gradient check).
"""

from __future__ import annotations

import numpy as np

LEAK = 0.01
"""Negative-side slope of the leaky ReLU (PyTorch's default; the paper does not state its value)."""


def leaky_relu(x: np.ndarray) -> np.ndarray:
    """max(x, LEAK x) elementwise."""
    return np.where(x > 0, x, x * x.dtype.type(LEAK))


def leaky_relu_backward(x: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """d lrelu(x) / dx times dy (x: the pre-activation)."""
    return np.where(x > 0, dy, dy * dy.dtype.type(LEAK))


class Dense:
    """y = x W + b, W (n_in, n_out), b (n_out,); He-initialised (fan-in) for leaky-ReLU inputs."""

    def __init__(self, n_in: int, n_out: int, rng: np.random.Generator, dtype=np.float32):
        self.params = {"W": (rng.standard_normal((n_in, n_out)) * np.sqrt(2.0 / n_in)).astype(dtype),
                       "b": np.zeros(n_out, dtype=dtype)}
        self.grads = {k: np.zeros_like(v) for k, v in self.params.items()}
        self._x = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.params["W"].shape

    def forward(self, x: np.ndarray, train: bool = False) -> np.ndarray:
        if train:
            self._x = x
        return x @ self.params["W"] + self.params["b"]

    def backward(self, dy: np.ndarray) -> np.ndarray:
        self.grads["W"][...] = self._x.T @ dy
        self.grads["b"][...] = dy.sum(axis=0)
        return dy @ self.params["W"].T


class DenseAct:
    """lrelu(x W + b): a dense layer followed by the leaky ReLU."""

    def __init__(self, n_in: int, n_out: int, rng: np.random.Generator, dtype=np.float32):
        self.dense = Dense(n_in, n_out, rng, dtype)
        self.params, self.grads = self.dense.params, self.dense.grads
        self._pre = None

    def forward(self, x: np.ndarray, train: bool = False) -> np.ndarray:
        pre = self.dense.forward(x, train)
        if train:
            self._pre = pre
        return leaky_relu(pre)

    def backward(self, dy: np.ndarray) -> np.ndarray:
        return self.dense.backward(leaky_relu_backward(self._pre, dy))


class Residual:
    """Residual block of two FC layers of ``width``: y = lrelu(x + D2(lrelu(D1(x)))) (sec. 4.2)."""

    def __init__(self, width: int, rng: np.random.Generator, dtype=np.float32):
        self.first = DenseAct(width, width, rng, dtype)
        self.second = Dense(width, width, rng, dtype)
        self.second.params["W"] *= 0.5  # the block starts close to the identity
        self.params = {**{f"1.{k}": v for k, v in self.first.params.items()},
                       **{f"2.{k}": v for k, v in self.second.params.items()}}
        self.grads = {**{f"1.{k}": v for k, v in self.first.grads.items()},
                      **{f"2.{k}": v for k, v in self.second.grads.items()}}
        self._pre = None

    def forward(self, x: np.ndarray, train: bool = False) -> np.ndarray:
        pre = x + self.second.forward(self.first.forward(x, train), train)
        if train:
            self._pre = pre
        return leaky_relu(pre)

    def backward(self, dy: np.ndarray) -> np.ndarray:
        d_pre = leaky_relu_backward(self._pre, dy)
        return d_pre + self.first.backward(self.second.backward(d_pre))
