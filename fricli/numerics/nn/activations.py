"""Activation functions as (value, derivative) pairs, and fused in-place forms for the network.

Each plain pair ``f(x)``, ``f_grad(x)`` allocates and is easy to read and test. The network uses
the ``Activation`` objects: ``forward(h, a, d)`` writes f(h) into ``a`` and f'(h) into ``d`` with
no temporaries, where h, a, d have the shape (units, samples).

    ELU          f(x) = x for x > 0, e^x - 1 otherwise. Computed as max(x, E - 1) with
                 E = exp(min(x, 0)): one exp per element, never of a large positive number, and
                 E is also the derivative (E = 1 for x >= 0). Without the derivative (``value``,
                 prediction) the same arithmetic, as the exported C code's: numpy's expm1 agrees
                 with it to 1 ulp, but in float32 it is vectorised only with AVX-512 (without,
                 measured 9.6 ns an element against 1.3 for exp and a subtraction).
    sigmoid      f(x) = 1 / (1 + e^-x), f' = f (1 - f).
    jump k       phi_k(x) = (1 - e^-x)^k for x >= 0, 0 otherwise (Selmic & Lewis 2002);
                 phi_k' = k (1 - e^-x)^(k-1) e^-x for x >= 0 (right derivative at 0), 0 otherwise.
"""

from __future__ import annotations

import numpy as np

_SIGMOID_CLIP = 60.0  # exp(60) is finite in float32; sigmoid(+-60) is 1 or 0 to float32 precision


# ---------------------------------------------------------------------------- plain pairs


def elu(x: np.ndarray) -> np.ndarray:
    e = np.exp(np.minimum(x, 0))
    return np.maximum(x, e - 1)


def elu_grad(x: np.ndarray) -> np.ndarray:
    return np.exp(np.minimum(x, 0))


def sigmoid(x: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(-np.clip(x, -_SIGMOID_CLIP, _SIGMOID_CLIP)))


def sigmoid_grad(x: np.ndarray) -> np.ndarray:
    s = sigmoid(x)
    return s * (1.0 - s)


def jump(x: np.ndarray, k) -> np.ndarray:
    """phi_k(x); ``k`` a positive integer or an array broadcasting against x."""
    s = -np.expm1(-np.maximum(x, 0))
    return np.where(x >= 0, s ** k, 0.0).astype(np.result_type(x, np.float32), copy=False)


def jump_grad(x: np.ndarray, k) -> np.ndarray:
    xp = np.maximum(x, 0)
    s = -np.expm1(-xp)
    k = np.asarray(k, dtype=np.result_type(x, np.float32))
    return np.where(x >= 0, k * s ** (k - 1) * np.exp(-xp), 0.0).astype(np.result_type(x, np.float32), copy=False)


def identity(x: np.ndarray) -> np.ndarray:
    return x.copy()


def identity_grad(x: np.ndarray) -> np.ndarray:
    return np.ones_like(x)


# ---------------------------------------------------------------------------- fused in-place forms


class Activation:
    """An activation for a whole layer. ``name`` is how it is written into model files."""

    name = ""

    def forward(self, h: np.ndarray, a: np.ndarray, d: np.ndarray) -> None:
        """a[:] = f(h), d[:] = f'(h); all (units, samples), three distinct buffers."""
        raise NotImplementedError

    def value(self, h: np.ndarray, a: np.ndarray, scratch: np.ndarray) -> None:
        """a[:] = f(h) alone (prediction); ``scratch``, of h's shape, may be overwritten."""
        self.forward(h, a, scratch)

    def spec(self):
        return self.name


def _zeros_like(cache: dict, h: np.ndarray) -> np.ndarray:
    """A zero array of h's shape and type, kept in ``cache``: numpy's minimum against an array
    is several times faster than against the scalar 0."""
    key = (h.shape, h.dtype)
    zeros = cache.get(key)
    if zeros is None:
        zeros = cache[key] = np.zeros(h.shape, dtype=h.dtype)
    return zeros


class ELU(Activation):
    name = "elu"

    def __init__(self):
        self._zeros: dict = {}

    def forward(self, h, a, d):
        np.minimum(h, _zeros_like(self._zeros, h), out=d)
        np.exp(d, out=d)                 # E, which is also f'(h)
        np.subtract(d, 1, out=a)
        np.maximum(a, h, out=a)

    def value(self, h, a, scratch):
        np.minimum(h, _zeros_like(self._zeros, h), out=scratch)
        np.exp(scratch, out=scratch)
        np.subtract(scratch, 1, out=scratch)
        np.maximum(scratch, h, out=a)


class Sigmoid(Activation):
    name = "sigmoid"

    def forward(self, h, a, d):
        np.clip(h, -_SIGMOID_CLIP, _SIGMOID_CLIP, out=a)
        np.negative(a, out=a)
        np.exp(a, out=a)
        np.add(a, 1, out=a)
        np.reciprocal(a, out=a)          # s
        np.subtract(1, a, out=d)
        np.multiply(d, a, out=d)         # s (1 - s)


class Jump(Activation):
    """phi_k per unit: ``ks`` holds one integer exponent per unit (row)."""

    name = "jump"

    def __init__(self, ks):
        self.ks = np.asarray(ks, dtype=np.float64).reshape(-1)
        if self.ks.size == 0 or (self.ks < 1).any() or (self.ks != np.round(self.ks)).any():
            raise ValueError("jump exponents must be integers >= 1")

    def forward(self, h, a, d):
        k = self.ks.astype(h.dtype)[:, None]
        np.maximum(h, 0, out=d)
        np.negative(d, out=d)
        np.exp(d, out=d)                 # e^-x, 1 for x <= 0
        np.subtract(1, d, out=a)         # s = 1 - e^-x, 0 for x <= 0
        pk1 = np.power(a, k - 1)         # s^(k-1); 0^0 = 1
        np.multiply(a, pk1, out=a)       # phi = s^k, 0 for x < 0
        np.multiply(d, pk1, out=d)
        np.multiply(d, k, out=d)
        np.multiply(d, h >= 0, out=d)    # only k = 1 needs this: its s^0 = 1 at x < 0

    def spec(self):
        return {"name": self.name, "k": [int(k) for k in self.ks]}


class Identity(Activation):
    name = "identity"

    def forward(self, h, a, d):
        if a is not h:
            np.copyto(a, h)
        d.fill(1)


class Mixed(Activation):
    """Different activations on consecutive groups of units: ``parts`` = [(units, activation), ...]."""

    name = "mixed"

    def __init__(self, parts):
        self.parts = [(int(n), act) for n, act in parts]

    @property
    def units(self) -> int:
        return sum(n for n, _ in self.parts)

    def forward(self, h, a, d):
        start = 0
        for n, act in self.parts:
            act.forward(h[start:start + n], a[start:start + n], d[start:start + n])
            start += n

    def value(self, h, a, scratch):
        start = 0
        for n, act in self.parts:
            act.value(h[start:start + n], a[start:start + n], scratch[start:start + n])
            start += n

    def spec(self):
        return {"name": self.name, "parts": [[n, act.spec()] for n, act in self.parts]}


def from_spec(spec) -> Activation:
    """The activation written as ``spec`` in a model file (see ``Activation.spec``)."""
    if isinstance(spec, str):
        spec = {"name": spec}
    name = spec.get("name")
    if name == "elu":
        return ELU()
    if name == "sigmoid":
        return Sigmoid()
    if name == "identity":
        return Identity()
    if name == "jump":
        return Jump(spec["k"])
    if name == "mixed":
        return Mixed([(n, from_spec(s)) for n, s in spec["parts"]])
    raise ValueError(f"unknown activation {name!r}")


def softplus(x: np.ndarray) -> np.ndarray:
    """log(1 + e^x), without overflow: max(x, 0) + log1p(e^-|x|)."""
    return np.maximum(x, 0) + np.log1p(np.exp(-np.abs(x)))


def softplus_grad(x: np.ndarray) -> np.ndarray:
    """d softplus / dx = sigmoid(x)."""
    return sigmoid(x)
