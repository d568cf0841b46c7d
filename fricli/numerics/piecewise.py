"""A function of one input as polynomial pieces: a network of one continuous input at the cost
of a few multiply-adds, for prediction and for the exported step.

The dissipative network's magnitude reads one continuous input, its speed feature u (the other,
the sign of qd, takes one of three values), over a bounded range (the speed is clamped to the
training's). Each hidden unit's activation is analytic on either side of 0 (ELU: e^v - 1 and v),
so the network is analytic between the inputs where a unit's pre-activation crosses 0
(``crossings``: sign changes on a grid of GRID points, refined by bisection to the last bit).
Between those, ``fit`` interpolates the function by a polynomial of degree DEGREE at Chebyshev
points and halves a piece whose largest difference from the function at CHECKS points exceeds
TOL (relative to max(1, |f|)); no more than MAX_PIECES pieces. A piece is evaluated by Horner's
rule in t = (u - mid) / half (``Pieces.__call__``, and the C code of ``fricli.export.piecewise``).
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
from numpy.polynomial import chebyshev

from fricli.numerics.nn.activations import softplus

DEGREE = 8          # of each piece's polynomial
TOL = 1e-12         # largest difference from the function allowed, relative to max(1, |f|)
CHECKS = 97         # points a piece is checked at (its ends and 95 between, evenly)
MAX_PIECES = 1024   # more: None (the function is evaluated otherwise)
GRID = 4097         # points over the range where the units' pre-activations are looked at
WIDTH = DEGREE + 3  # numbers per piece: mid, 1 / half, a0 .. a_DEGREE

_NODES = np.cos(np.pi * (np.arange(DEGREE + 1) + 0.5) / (DEGREE + 1))   # Chebyshev points (first kind)
# values at _NODES -> coefficients of t^0 .. t^DEGREE: the Chebyshev interpolant, then its power series
_TO_POWERS = np.array([chebyshev.cheb2poly(chebyshev.chebfit(_NODES, np.eye(DEGREE + 1)[j], DEGREE))
                       for j in range(DEGREE + 1)]).T
_CHECK_T = np.linspace(-1.0, 1.0, CHECKS)


@dataclasses.dataclass
class Pieces:
    """Polynomial pieces over [edges[0], edges[-1]]: piece k on [edges[k], edges[k + 1]] is
    sum_i table[k, 2 + i] t^i with t = (u - table[k, 0]) * table[k, 1]; ``error``: the largest
    difference from the function found at the check points."""

    edges: np.ndarray   # (n + 1,)
    table: np.ndarray   # (n, WIDTH)
    error: float

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """The pieces at u (m,), by Horner's rule."""
        return horner(self.table, np.searchsorted(self.edges[1:-1], u, side="right"), np.asarray(u, dtype=np.float64))


def horner(table: np.ndarray, k: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Piece k[i] of ``table`` (n, WIDTH) at u[i] (m,)."""
    cols = table.T
    t = u - cols[0].take(k)
    t *= cols[1].take(k)
    y = cols[-1].take(k)
    for i in range(WIDTH - 2, 1, -1):
        y *= t
        y += cols[i].take(k)
    return y


def crossings(pre: Callable[[np.ndarray], list[np.ndarray]], lo: float, hi: float) -> np.ndarray:
    """Inputs in (lo, hi) where a row of ``pre(u)`` (the pre-activations, a list of (units, m)
    arrays for u (m,)) changes sign, sorted: bisected between the GRID points that bracket it."""
    grid = np.linspace(lo, hi, GRID)
    h = np.vstack(pre(grid))
    unit, cell = np.nonzero(np.signbit(h[:, :-1]) != np.signbit(h[:, 1:]))
    if not unit.size:
        return np.empty(0)
    a, b = grid[cell], grid[cell + 1]
    neg_a = np.signbit(h[unit, cell])
    while True:
        mid = 0.5 * (a + b)
        inside = (mid > a) & (mid < b)
        if not inside.any():
            break
        same = np.signbit(np.vstack(pre(mid))[unit, np.arange(unit.size)]) == neg_a
        a = np.where(inside & same, mid, a)
        b = np.where(inside & ~same, mid, b)
    return np.unique(a)


def fit(fn: Callable[[np.ndarray], np.ndarray], lo: float, hi: float, breaks=()) -> Pieces | None:
    """Pieces of ``fn`` (vectorised, (m,) -> (m,)) over [lo, hi], with edges at ``breaks`` (the
    inputs where fn may not be smooth); None when MAX_PIECES do not reach TOL. Every pending
    piece of a round is evaluated in one call of fn."""
    if not hi > lo:
        return Pieces(np.array([lo, lo]), np.array([[lo, 0.0, float(fn(np.array([lo]))[0])] + [0.0] * DEGREE]), 0.0)
    edges = np.array([lo, *sorted(float(b) for b in breaks if lo < b < hi), hi])
    todo, done = np.column_stack([edges[:-1], edges[1:]]), []
    while todo.size:
        if len(todo) + sum(len(d[0]) for d in done) > MAX_PIECES:
            return None
        mid, half = 0.5 * (todo[:, 0] + todo[:, 1]), 0.5 * (todo[:, 1] - todo[:, 0])
        n = len(todo)
        at = np.concatenate([(mid[:, None] + half[:, None] * _NODES).ravel(),
                             np.clip(mid[:, None] + half[:, None] * _CHECK_T, todo[:, :1], todo[:, 1:]).ravel()])
        values = fn(at)
        table = np.column_stack([mid, 1.0 / half, values[:n * (DEGREE + 1)].reshape(n, -1) @ _TO_POWERS.T])
        want = values[n * (DEGREE + 1):].reshape(n, CHECKS)
        u = at[n * (DEGREE + 1):]
        got = horner(table, np.repeat(np.arange(n), CHECKS), u).reshape(n, CHECKS)
        err = np.max(np.abs(got - want) / np.maximum(1.0, np.abs(want)), axis=1)
        bad = err > TOL
        if np.any(bad & ~((mid > todo[:, 0]) & (mid < todo[:, 1]))):
            return None                                          # a piece too short to halve
        done.append((todo[~bad], table[~bad], err[~bad]))
        todo = np.concatenate([np.column_stack([todo[bad, 0], mid[bad]]), np.column_stack([mid[bad], todo[bad, 1]])])
    spans = np.concatenate([d[0] for d in done])
    order = np.argsort(spans[:, 0])
    return Pieces(np.append(spans[order, 0], spans[order[-1], 1]), np.concatenate([d[1] for d in done])[order],
                  float(max(float(d[2].max()) for d in done if d[2].size)))


@dataclasses.dataclass
class SignedPieces:
    """A function of (u, sign(qd)) as pieces of u: ``pos`` for sign 1, ``neg`` for sign -1, and
    its value ``at_rest`` at sign 0."""

    pos: Pieces
    neg: Pieces
    at_rest: float

    def __post_init__(self):
        # one table for both signs: the negative side's inputs moved past the positive side's
        self._shift = float(self.pos.edges[-1] - self.neg.edges[0] + 1.0)
        self._inner = np.concatenate([self.pos.edges[1:-1], self.neg.edges[:-1] + self._shift])
        self._table = np.vstack([self.pos.table, self.neg.table])
        self._table[len(self.pos.table):, 0] += self._shift

    @property
    def error(self) -> float:
        return max(self.pos.error, self.neg.error)

    def __call__(self, u: np.ndarray, sign: np.ndarray) -> np.ndarray:
        """The function (n,) at the inputs u (n,) and sign(qd) (n,) (1, -1 or 0)."""
        w = u + np.where(sign < 0, self._shift, 0.0)
        y = horner(self._table, np.searchsorted(self._inner, w, side="right"), w)
        y[sign == 0] = self.at_rest
        return y


def network_pieces(nets: list, ranges: list, rest: float) -> SignedPieces | None:
    """mean_k softplus(output 0 of nets[k](u, s)) (``fricli.numerics.nn`` networks of the inputs u
    and s, no skip inputs) as pieces of u over ranges[0] = (lo, hi) for s = 1 and ranges[1] for
    s = -1, and its value at (rest, 0); None where the pieces miss TOL."""
    if any(net.n_skip for net in nets):
        return None

    def pre(u: np.ndarray, s: float) -> list[np.ndarray]:
        return [h for net in nets for h in net.layer_inputs(np.vstack([u, np.full_like(u, s)]))[0]]

    def value(u: np.ndarray, s: float) -> np.ndarray:
        return np.mean([softplus(net.layer_inputs(np.vstack([u, np.full_like(u, s)]))[1][0]) for net in nets], axis=0)

    sides = [fit(lambda u: value(u, s), lo, hi, crossings(lambda u: pre(u, s), lo, hi))
             for s, (lo, hi) in zip((1.0, -1.0), ranges)]
    if any(side is None for side in sides):
        return None
    return SignedPieces(sides[0], sides[1], float(value(np.array([rest]), 0.0)[0]))
