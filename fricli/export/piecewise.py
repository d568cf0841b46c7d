"""A function of one input as polynomial pieces, for the exported step: a network of one
continuous input at the cost of a few multiply-adds.

The dissipative network's magnitude reads one continuous input, its speed feature u (the other,
the sign of qd, takes one of three values), over a bounded range (the speed is clamped to the
training's). Each hidden unit's activation is analytic on either side of 0 (ELU: e^v - 1 and v),
so the network is analytic between the inputs where a unit's pre-activation crosses 0
(``crossings``: sign changes on a grid of GRID points, refined by bisection to the last bit).
Between those, ``fit`` interpolates the function by a polynomial of degree DEGREE at Chebyshev
points and halves a piece whose largest difference from the function at CHECKS points exceeds
TOL (relative to max(1, |f|)); no more than MAX_PIECES pieces. In C (``c_code``) a piece is found
by bisection of the edges and evaluated by Horner's rule in t = (u - mid) / half.
"""

from __future__ import annotations

import dataclasses
from typing import Callable

import numpy as np
from numpy.polynomial import chebyshev

from fricli.export.c import array, num

DEGREE = 8          # of each piece's polynomial
TOL = 1e-12         # largest difference from the function allowed, relative to max(1, |f|)
CHECKS = 97         # points a piece is checked at (its ends and 95 between, evenly)
MAX_PIECES = 1024   # more: the function is not exported this way
GRID = 4097         # points over the range where the units' pre-activations are looked at
WIDTH = DEGREE + 3  # numbers per piece in the C table: mid, 1 / half, a0 .. a_DEGREE


@dataclasses.dataclass
class Pieces:
    """Polynomial pieces over [edges[0], edges[-1]]: piece k on [edges[k], edges[k + 1]] is
    sum_i table[k, 2 + i] t^i with t = (u - table[k, 0]) * table[k, 1]; ``error``: the largest
    difference from the function found at the check points."""

    edges: np.ndarray   # (n + 1,)
    table: np.ndarray   # (n, WIDTH)
    error: float

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """The pieces at u (m,), as the C code evaluates them (Horner's rule)."""
        u = np.asarray(u, dtype=np.float64)
        row = self.table[np.searchsorted(self.edges[1:-1], u, side="right")]
        t = (u - row[:, 0]) * row[:, 1]
        y = row[:, -1].copy()
        for i in range(WIDTH - 2, 1, -1):
            y *= t
            y += row[:, i]
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


def fit(fn: Callable[[np.ndarray], np.ndarray], lo: float, hi: float, breaks: np.ndarray = ()) -> Pieces | None:
    """Pieces of ``fn`` (vectorised, (m,) -> (m,)) over [lo, hi], with edges at ``breaks`` (the
    inputs where fn may not be smooth); None when MAX_PIECES do not reach TOL."""
    if not hi > lo:
        return Pieces(np.array([lo, lo]), np.array([[lo, 0.0, float(fn(np.array([lo]))[0])] + [0.0] * DEGREE]), 0.0)
    edges = [lo, *[float(b) for b in breaks if lo < b < hi], hi]
    todo = list(zip(edges[:-1], edges[1:]))[::-1]
    done, worst = [], 0.0
    t_check = np.linspace(-1.0, 1.0, CHECKS)
    while todo:
        a, b = todo.pop()
        mid, half = 0.5 * (a + b), 0.5 * (b - a)
        if len(done) + len(todo) >= MAX_PIECES:
            return None
        coef = chebyshev.cheb2poly(chebyshev.chebinterpolate(lambda t: fn(mid + half * t), DEGREE))
        coef = np.pad(coef, (0, DEGREE + 1 - coef.size))
        piece = Pieces(np.array([a, b]), np.array([[mid, 1.0 / half, *coef]]), 0.0)
        u = np.clip(mid + half * t_check, a, b)
        want = fn(u)
        err = float(np.max(np.abs(piece(u) - want) / np.maximum(1.0, np.abs(want))))
        if err > TOL and mid > a and mid < b:
            todo += [(mid, b), (a, mid)]
            continue
        if err > TOL:
            return None
        done.append((a, b, piece.table[0]))
        worst = max(worst, err)
    done.sort(key=lambda p: p[0])
    return Pieces(np.array([p[0] for p in done] + [done[-1][1]]), np.array([p[2] for p in done]), worst)


def c_function(name: str) -> str:
    """C definition of ``double <name>(const double *edges, const double *table, int n, double u)``:
    the piece of the n whose edges hold u (edges[0..n]), by Horner's rule."""
    horner = "p[{}]".format(WIDTH - 1)
    for i in range(WIDTH - 2, 1, -1):
        horner = f"{horner} * t + p[{i}]" if i == WIDTH - 2 else f"({horner}) * t + p[{i}]"
    return "\n".join([
        f"static inline double {name}(const double *edges, const double *table, int n, double u) {{",
        "    int lo = 0, hi = n;",
        "    const double *p;",
        "    double t;",
        "    while (hi - lo > 1) { const int mid = (lo + hi) / 2; if (u < edges[mid]) hi = mid; else lo = mid; }",
        f"    p = table + lo * {WIDTH};",
        "    t = (u - p[0]) * p[1];",
        f"    return {horner};",
        "}", ""])


def c_tables(name: str, pieces: Pieces) -> str:
    """The file-scope tables ``<name>_edges`` and ``<name>`` (WIDTH numbers a piece) of ``pieces``."""
    n = len(pieces.table)
    return "\n".join([f"static const double {name}_edges[{n + 1}] = {array(pieces.edges, 4)};",
                      f"static const double {name}[{n * WIDTH}] = {array(pieces.table, 4)};"])


def c_call(function: str, name: str, pieces: Pieces, u: str) -> str:
    """The C expression of ``pieces`` at ``u``, through ``c_function``'s function and ``c_tables``' tables."""
    if len(pieces.table) == 1 and pieces.table[0, 1] == 0.0:
        return num(pieces.table[0, 2])
    return f"{function}({name}_edges, {name}, {len(pieces.table)}, {u})"
