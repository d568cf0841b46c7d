"""Friction physics shared by the simulator and the LuGre model.

Extended LuGre model (Canudas de Wit et al. 1995, with load dependence):

    g(v, tau_l) = Fc(tau_l) + (Fs(tau_l) - Fc(tau_l)) * exp(-|v/vs|^delta)    [Nm], > 0
    dz/dt       = v - sigma0 * |v| / g * z                                    [rad/s]
    tau_f       = sigma0 * z + sigma1 * dz/dt + Fv * v                        [Nm]

The bristle state uses the exact solution of dz/dt for v and g held over each sample
interval (zero-order hold), which is stable at any stiffness:

    z[k] = z_ss[k] + (z[k-1] - z_ss[k]) * exp(-sigma0 * |v[k]| / g[k] * (t[k] - t[k-1])),
    z_ss = sign(v) * g / sigma0.

That is a linear recurrence z[k] = a[k] z[k-1] + b[k], solved in one call as a unit lower
bidiagonal system (BLAS ``dtbsv`` through ``scipy.linalg.blas``, ``recurrence``), with no
Python loop over samples. These functions are the one implementation of the equations: the LuGre model, the
simulator and identification call them.

Maxwell-slip elements (the ``gms`` kind, the ``slip`` term factor): the stop operator, ``stop``,
z[k] = clip(z[k-1] + q[k] - q[k-1], -d, d) for each element of deflection limit d, where a step
q[k] - q[k-1] beyond half a turn (pi) is a position that wrapped at a turn (a continuous joint
recorded within one turn), less that turn (``position_steps``): no joint moves half a turn in one
sample.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.core import lazy
from fricli.core.logs_motion import HALF_TURN

scipy_blas = lazy.module("scipy.linalg.blas")

_RATE_DT_MAX = 700.0   # exp(-700) is the smallest decay used: the state has reached z_ss


def stribeck_shape_log(log_ratio: np.ndarray, delta: float, out: np.ndarray | None = None) -> np.ndarray:
    """E = exp(-|v/vs|^delta) (n,) from log_ratio = log|v| - log vs (n,); -inf (v = 0) gives E = 1."""
    out = np.multiply(log_ratio, delta, out=out)
    np.exp(out, out=out)
    np.negative(out, out=out)
    return np.exp(out, out=out)


def stribeck_shape(v: np.ndarray, vs: float, delta: float, out: np.ndarray | None = None) -> np.ndarray:
    """E = exp(-|v/vs|^delta) (n,) for velocities v (n,) [rad/s], 1 at v = 0.

    |v/vs|^delta is written exp(delta (log|v| - log vs)): np.power is several times slower."""
    out = np.abs(v, out=out)
    with np.errstate(divide="ignore"):
        np.log(out, out=out)
    out -= math.log(vs)
    return stribeck_shape_log(out, delta, out=out)


def stribeck(v: np.ndarray, fc: np.ndarray | float, fs: np.ndarray | float, vs: float, delta: float) -> np.ndarray:
    """Stribeck curve g(v) [Nm] for velocities v [rad/s]; fc, fs may be arrays (load-dependent)."""
    return fc + (fs - fc) * stribeck_shape(v, vs, delta)


class Buffers:
    """Work arrays for ``lugre_friction`` on up to ``n`` samples, to reuse across blocks."""

    def __init__(self, n: int):
        self.work = [np.empty(n) for _ in range(3)]
        self.band = np.empty((2, n), order="F")   # dtbsv band storage; row 0 unused (unit diagonal)
        self.band[0] = 1.0


def lugre_friction(v: np.ndarray, g: np.ndarray, fv: np.ndarray | float, sigma0: float, sigma1: float,
                   dt: np.ndarray, z0: float | None = None, *, out: np.ndarray | None = None,
                   buffers: Buffers | None = None) -> tuple[np.ndarray, float]:
    """Friction torque (n,) [Nm] and the bristle state z [rad] after the last sample.

    v: velocity (n,) [rad/s]; g: Stribeck curve (n,) [Nm], > 0; fv: viscous coefficient, scalar
    or (n,); sigma0 [Nm/rad], sigma1 [Nm s/rad]; dt: interval ending at each sample (n,) [s];
    z0: state before the first sample (None: the steady state of the first sample). ``out``
    (n,) receives the torque and may be ``g`` itself; ``buffers`` (at least n long) avoid allocating.
    """
    n = len(v)
    out = np.empty(n) if out is None else out
    if n == 0:
        return out, (z0 or 0.0)
    buffers = buffers if buffers is not None else Buffers(n)
    rate, a, zss = (w[:n] for w in buffers.work)
    band = buffers.band[:, :n]
    np.abs(v, out=rate)
    rate *= sigma0
    rate /= g                                     # sigma0 |v| / g  [1/s]
    np.multiply(rate, dt, out=a)
    np.minimum(a, _RATE_DT_MAX, out=a)
    np.negative(a, out=a)
    np.exp(a, out=a)                              # decay over the interval
    np.sign(v, out=zss)
    zss *= g
    zss /= sigma0                                 # steady-state deflection
    b = np.subtract(1.0, a, out=out)
    b *= zss
    if z0 is None:
        z0 = float(zss[0])
    b[0] += a[0] * z0
    # z[k] = a[k] z[k-1] + b[k]: a unit lower bidiagonal system
    np.negative(a[1:], out=band[1, :-1])
    band[1, -1] = 0.0
    recurrence(band, b)
    z_last = float(out[-1])
    # tau = sigma0 z + sigma1 dz/dt + fv v, with dz/dt = v - rate z
    rate *= out
    np.subtract(v, rate, out=rate)
    rate *= sigma1
    np.multiply(out, sigma0, out=a)
    np.add(a, rate, out=out)
    np.multiply(fv, v, out=a)
    out += a
    return out, z_last


def recurrence(band: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve z[k] = a[k] z[k-1] + b[k] (z[-1] = 0) in place in b (n,) float64; returns b.

    band: (2, n) float64, BLAS ``dtbsv``'s band storage of the unit lower bidiagonal matrix:
    band[1, k] = -a[k+1] for k < n-1 (row 0 and band[1, n-1] are not read); Fortran order
    avoids a copy. ValueError for any other shape."""
    n = len(b)
    if np.ndim(b) != 1 or np.shape(band) != (2, n):
        raise ValueError(f"recurrence: band must have shape (2, {n}) for b of shape ({n},), "
                         f"not {np.shape(band)} and {np.shape(b)}")
    if n == 0:
        return b
    z = scipy_blas.dtbsv(1, band, b, lower=1, diag=1, overwrite_x=1)
    if not np.shares_memory(z, b):     # b was copied (not contiguous float64): copy back
        b[:] = z
    return b


def intervals(t: np.ndarray, t_prev: float | None = None) -> np.ndarray:
    """Sample intervals (n,) [s]: t[k] - t[k-1]; the first uses t_prev or the next interval."""
    dt = np.empty_like(t)
    if len(t) == 0:
        return dt
    dt[1:] = np.diff(t)
    if t_prev is not None:
        dt[0] = t[0] - t_prev
    else:
        dt[0] = dt[1] if len(t) > 1 else 0.0
    return dt


STOP_BLOCK = 64   # rows per block of the stop operator's vector passes
STOP_PASSES = 16  # at most this many passes over the blocks, then block by block


def position_steps(q: np.ndarray, q0: float) -> np.ndarray:
    """q[k] - q[k-1] (n,) from q0 before the first row, a step beyond half a turn taken as a wrap at
    a turn: less 2 pi (the exported C steps alike: a test, then one subtraction)."""
    dq = np.diff(q, prepend=float(q0))
    dq[dq > HALF_TURN] -= 2 * HALF_TURN
    dq[dq < -HALF_TURN] += 2 * HALF_TURN
    return dq


def stop(q: np.ndarray, d, z0, q0: float) -> np.ndarray:
    """Deflections z (n, N) [rad or m] of Maxwell-slip elements of limits d (N,) > 0 over positions
    q (n,) (the stop operator): z[k] = clip(z[k-1] + q[k] - q[k-1], -d, d), the steps by
    ``position_steps``, from z0 (N,) at position q0.

    The same bits as stepping row by row in plain floats, faster: the rows are cut into blocks of
    STOP_BLOCK, every block is stepped at once from a guess of its first state (numpy over the
    blocks), and a block is stepped again from its predecessor's last state until the two agree;
    a clip forgets the guess, so blocks where an element slips agree at once. Stretches where it
    does not slip are summed exactly as the steps go (``np.add.accumulate``), then checked."""
    q = np.asarray(q, dtype=np.float64)
    d = np.atleast_1d(np.asarray(d, dtype=np.float64))
    out = np.empty((len(q), len(d)))
    n = len(q)
    if not n:
        return out
    dq = position_steps(q, q0)
    starts = np.broadcast_to(np.asarray(z0, dtype=np.float64), d.shape).tolist()
    blocks = -(-n // STOP_BLOCK)
    if blocks < 4:
        for i, (limit, z) in enumerate(zip(d.tolist(), starts)):
            out[:, i] = _stop_steps(dq, limit, z)
        return out
    padded = np.zeros(blocks * STOP_BLOCK)   # zero steps after the last row change nothing
    padded[:n] = dq
    steps = np.ascontiguousarray(padded.reshape(blocks, STOP_BLOCK).T)   # (B, blocks): block b in column b
    for i, (limit, z) in enumerate(zip(d.tolist(), starts)):
        out[:, i] = _stop_element(padded, steps, limit, z).T.reshape(-1)[:n]
    return out


def _stop_steps(dq: np.ndarray, limit: float, z: float) -> list[float]:
    """The stop operator stepped row by row in plain floats (the reference order of operations)."""
    column = []
    for step in dq.tolist():
        z = min(max(z + step, -limit), limit)
        column.append(z)
    return column


def _stop_blocks(steps: np.ndarray, z: np.ndarray, limit: float, out: np.ndarray) -> None:
    """out (B, k): each column of ``steps`` (B, k) stepped from its first state z (k,)."""
    for j in range(steps.shape[0]):
        z = np.add(z, steps[j], out=out[j])
        np.maximum(z, -limit, out=z)
        np.minimum(z, limit, out=z)


def _stop_element(padded: np.ndarray, steps: np.ndarray, limit: float, z0: float) -> np.ndarray:
    """States (B, blocks) of one element of ``limit`` over ``steps`` (B, blocks), ``padded`` the
    same steps in row order, from z0."""
    size, blocks = steps.shape
    first = np.zeros(blocks)      # the first state each block was stepped from
    first[0] = z0
    z = np.empty((size, blocks))
    # states compared bit for bit (as integers): 0.0 and -0.0 are equal as floats, not as bits
    first_bits, last_bits = first.view(np.int64), z[-1].view(np.int64)
    _stop_blocks(steps, first, limit, z)
    todo = 2 * blocks
    for done in range(STOP_PASSES):   # step again the blocks whose first state was not their predecessor's last
        wrong = np.flatnonzero(last_bits[:-1] != first_bits[1:]) + 1
        if not wrong.size or (done >= 3 and wrong.size > todo * 9 // 10):   # long stretches without a slip: below
            break
        todo = wrong.size
        first[wrong] = z[-1, wrong - 1]
        part = np.empty((size, wrong.size))
        _stop_blocks(steps[:, wrong], first[wrong], limit, part)
        z[:, wrong] = part
    wrong = np.flatnonzero(last_bits[:-1] != first_bits[1:]) + 1
    b, run = (int(wrong[0]) if wrong.size else blocks), 1
    while b < blocks:
        prev = z[-1, b - 1]
        if first_bits[b] == last_bits[b - 1]:
            b, run = b + 1, 1
            continue
        # sum the steps from prev over ``run`` blocks; the rows before the first clip are exact
        sums = np.add.accumulate(np.concatenate(([prev], padded[b * size:min(blocks, b + run) * size])))[1:]
        over = np.flatnonzero(np.abs(sums) > limit)
        clean = (int(over[0]) if over.size else sums.size) // size
        run = 1 if over.size else 2 * run
        if clean:
            z[:, b:b + clean] = sums[:clean * size].reshape(clean, size).T
            first[b] = prev
            first[b + 1:b + clean] = z[-1, b:b + clean - 1]
            b += clean
        else:
            z[:, b], first[b] = _stop_steps(steps[:, b], limit, float(prev)), prev
            b += 1
    return z
