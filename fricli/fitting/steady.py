"""The rows of a log that lie on the static friction curve: steady-state rows, where the velocity
has been held (``steady_state_mask``), and settled rows, far enough past a velocity reversal
(``settled_mask``); and the number of distinct speed levels a log holds (``speed_levels``). The
LuGre identification (``fricli.fitting.identify``) fits its static curve on them; train-base
finds a log's plateaus with them."""

from __future__ import annotations

import math

import numpy as np


NOISE_FLOOR = 1e-3        # velocity tolerance of the static-curve selection: at least this share of the top speed


def steady_state_mask(t: np.ndarray, qd: np.ndarray, *, hold: float = 0.2, travel: float = 0.002,
                      rel_tol: float = 0.05, abs_tol: float | None = None) -> np.ndarray:
    """Rows (n,) bool where the velocity qd (n,) [rad/s] has been held constant.

    A row is steady when, over a window from H seconds before to H/4 after it, qd keeps its
    sign and its range stays within rel_tol*|qd| + abs_tol. The hold H is ``hold`` [s] or the
    time to cover ``travel`` [rad or m] at that speed, whichever is longer (so the bristles have
    settled at slow speeds too), rounded up to hold*2^k and capped at 16*hold. ``abs_tol``
    defaults to 1e-3 of the top speed or four times the sample-to-sample velocity noise,
    whichever is larger. The window is counted in samples at the median sample rate.
    """
    n = len(qd)
    if n < 3:
        return np.zeros(n, dtype=bool)
    dt = float(np.median(np.diff(t)))
    speed = np.abs(qd)
    top = float(np.percentile(speed, 99))
    if abs_tol is None:
        abs_tol = _noise_tol(qd, top)
    with np.errstate(divide="ignore"):
        need = np.maximum(hold, travel / speed)            # hold required at each row [s]
    level = np.clip(np.ceil(np.log2(need / hold) - 1e-9), 0, 4).astype(int)
    mask = np.zeros(n, dtype=bool)
    for k in range(5):
        rows = level == k
        if not rows.any():
            continue
        h = hold * 2 ** k
        before = max(1, int(min(n, round(h / dt))))  # min: a window longer than the log is no window
        after = max(1, int(min(n, round(h / 4 / dt))))
        vmax = window_extreme(qd, before, after, np.maximum)
        vmin = window_extreme(qd, before, after, np.minimum)
        ok = ((vmin > 0) | (vmax < 0)) & ((vmax - vmin) <= rel_tol * speed + abs_tol)
        ok[:before] = False                                # the window must not run off the log
        ok[n - after:] = False
        mask |= rows & ok
    return mask & (speed > max(abs_tol, NOISE_FLOOR * top))


def settled_mask(t: np.ndarray, qd: np.ndarray, *, settle: float = 0.01,
                 abs_tol: float | None = None) -> np.ndarray:
    """Rows (n,) bool where the joint has moved at least ``settle`` [rad or m] since the last
    velocity reversal (the bristles have reached their steady deflection, so the friction is
    on the static curve whatever the acceleration) and |qd| exceeds the noise level ``abs_tol``
    (default as ``steady_state_mask``). For continuous excitation without plateaus."""
    n = len(qd)
    if n < 3:
        return np.zeros(n, dtype=bool)
    speed = np.abs(qd)
    top = float(np.percentile(speed, 99))
    if abs_tol is None:
        abs_tol = _noise_tol(qd, top)
    moving = speed > abs_tol
    sign = np.where(moving, np.sign(qd), 0.0)
    # sign of the last moving row at or before each row: a reversal is a change of it
    idx = np.where(moving, np.arange(n), 0)
    np.maximum.accumulate(idx, out=idx)
    held = sign[idx]
    start = np.r_[True, held[1:] != held[:-1]]
    dist = np.r_[0.0, np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))]
    seg_start = np.where(start, np.arange(n), 0)
    np.maximum.accumulate(seg_start, out=seg_start)
    return moving & (held != 0) & (dist - dist[seg_start] >= settle)


def _noise_tol(qd: np.ndarray, top: float) -> float:
    """Velocity tolerance: NOISE_FLOOR of the top speed or four times the sample-to-sample noise."""
    jitter = float(np.median(np.abs(np.diff(qd)))) / 0.6745 / math.sqrt(2)
    return max(NOISE_FLOOR * top, 4 * jitter)


def window_extreme(x: np.ndarray, before: int, after: int, op=np.maximum) -> np.ndarray:
    """op-extreme (np.maximum or np.minimum) of x (n,) over rows i - before .. i + after for
    every row i, the ends extended with the first and last value; O(n) whatever the window
    (van Herk / Gil-Werman: extremes of whole blocks from the left and from the right)."""
    n, size = len(x), before + after + 1
    padded = np.concatenate([np.full(before, x[0]), x, np.full(after, x[-1])])
    blocks = -(-len(padded) // size)
    fill = -np.inf if op is np.maximum else np.inf
    grid = np.full(blocks * size, fill)
    grid[:len(padded)] = padded
    grid = grid.reshape(blocks, size)
    left = op.accumulate(grid, axis=1).reshape(-1)
    right = op.accumulate(grid[:, ::-1], axis=1)[:, ::-1].reshape(-1)
    return op(right[:n], left[size - 1:size - 1 + n])


def speed_levels(speed: np.ndarray, width: float = 1.1) -> int:
    """Number of distinct speeds in ``speed`` (n,) > 0: occupied bins of log-width ``width``
    holding at least 10 samples (and 0.5 % of them)."""
    if len(speed) == 0:
        return 0
    bins = np.floor(np.log(speed) / math.log(width)).astype(np.int64)
    _, counts = np.unique(bins, return_counts=True)
    return int((counts >= max(10, 0.005 * len(speed))).sum())
