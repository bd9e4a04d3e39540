"""Adam with bias correction and decoupled weight decay, and a step learning-rate schedule.

Adam: Kingma & Ba 2015, Algorithm 1 (m, v moments with bias correction 1 - beta^t); weight decay decoupled
from the gradient (Loshchilov & Hutter 2019, AdamW), applied to weight matrices only (names ending in
``.W``: the paper regularises "all the weights", sec. 5.2).  The step schedule follows sec. 5.2: the rate
is multiplied by ``gamma`` = 0.2 at given fractions of the run (the paper's epochs 6 and 9 of 10).
"""

from __future__ import annotations

import numpy as np


class Adam:
    """Updates ``params`` (name -> array, in place) from gradients with the same names."""

    def __init__(self, params: dict[str, np.ndarray], lr: float = 3e-3, betas=(0.9, 0.999), eps: float = 1e-8,
                 weight_decay: float = 1e-5):
        self.params = params
        self.lr, self.betas, self.eps, self.weight_decay = float(lr), betas, float(eps), float(weight_decay)
        self.m = {k: np.zeros_like(v) for k, v in params.items()}
        self.v = {k: np.zeros_like(v) for k, v in params.items()}
        self.t = 0

    def step(self, grads: dict[str, np.ndarray], lr: float | None = None) -> None:
        lr = self.lr if lr is None else float(lr)
        b1, b2 = self.betas
        self.t += 1
        c1, c2 = 1.0 - b1 ** self.t, 1.0 - b2 ** self.t
        for name, p in self.params.items():
            g = grads[name]
            m, v = self.m[name], self.v[name]
            m *= b1
            m += (1.0 - b1) * g
            v *= b2
            v += (1.0 - b2) * np.square(g)
            update = (m / c1) / (np.sqrt(v / c2) + self.eps)
            if self.weight_decay and name.endswith(".W"):
                update = update + self.weight_decay * p
            p -= (lr * update).astype(p.dtype)

    def state(self) -> dict[str, np.ndarray]:
        """The moments and step count as arrays (for a checkpoint)."""
        out = {f"m/{k}": v for k, v in self.m.items()} | {f"v/{k}": v for k, v in self.v.items()}
        out["t"] = np.array(self.t)
        return out

    def load_state(self, state: dict[str, np.ndarray]) -> None:
        for k in self.m:
            self.m[k][...] = state[f"m/{k}"]
            self.v[k][...] = state[f"v/{k}"]
        self.t = int(state["t"])


def step_schedule(lr: float, fraction: float, milestones=(0.6, 0.9), gamma: float = 0.2) -> float:
    """The learning rate at ``fraction`` (0..1) of the run: lr x gamma^(milestones passed)."""
    return float(lr) * float(gamma) ** sum(fraction >= m for m in milestones)
