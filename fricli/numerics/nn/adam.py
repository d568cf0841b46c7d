"""Adam (Kingma & Ba 2015) on a flat float32 parameter vector, with explicit state.

    m <- b1 m + (1 - b1) g
    v <- b2 v + (1 - b2) g^2
    theta <- theta - lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)

(the same update as PyTorch's ``torch.optim.Adam``). The whole state is (t, m, v) plus the
hyperparameters; ``state()`` returns it as plain values and arrays, ``from_state`` restores it.
"""

from __future__ import annotations

import math

import numpy as np


class Adam:
    """Adam for one flat parameter vector of ``n`` entries."""

    def __init__(self, n: int, lr: float = 0.01, beta1: float = 0.9, beta2: float = 0.999,
                 eps: float = 1e-8, dtype=np.float32):
        if not (lr > 0 and 0 <= beta1 < 1 and 0 <= beta2 < 1 and eps > 0):
            raise ValueError("Adam needs lr > 0, 0 <= beta1, beta2 < 1 and eps > 0")
        self.lr, self.beta1, self.beta2, self.eps = float(lr), float(beta1), float(beta2), float(eps)
        self.t = 0
        self.m = np.zeros(n, dtype=dtype)
        self.v = np.zeros(n, dtype=dtype)
        self._tmp = np.empty(n, dtype=dtype)

    def step(self, theta: np.ndarray, grad: np.ndarray) -> None:
        """Update ``theta`` in place from ``grad`` (both flat, length n). ``grad`` is left intact."""
        b1, b2, m, v, tmp = self.beta1, self.beta2, self.m, self.v, self._tmp
        self.t += 1
        m *= b1
        np.multiply(grad, 1.0 - b1, out=tmp)
        m += tmp
        v *= b2
        np.multiply(grad, grad, out=tmp)
        tmp *= 1.0 - b2
        v += tmp
        step_size = self.lr / (1.0 - b1 ** self.t)
        np.sqrt(v, out=tmp)
        tmp *= 1.0 / math.sqrt(1.0 - b2 ** self.t)
        tmp += self.eps
        np.divide(m, tmp, out=tmp)
        tmp *= step_size
        theta -= tmp

    def state(self) -> dict:
        """Hyperparameters, step count and moments: enough to continue exactly where it stopped."""
        return {"lr": self.lr, "beta1": self.beta1, "beta2": self.beta2, "eps": self.eps, "t": self.t,
                "m": self.m.copy(), "v": self.v.copy()}

    @classmethod
    def from_state(cls, state: dict) -> "Adam":
        m = np.asarray(state["m"])
        opt = cls(m.size, lr=state["lr"], beta1=state["beta1"], beta2=state["beta2"], eps=state["eps"],
                  dtype=m.dtype)
        opt.t = int(state["t"])
        opt.m[...] = m
        opt.v[...] = np.asarray(state["v"])
        return opt
