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
bidiagonal system (BLAS ``dtbsv``), with no Python loop over samples.
"""

from __future__ import annotations

import numpy as np

from fricli import lazy

blas = lazy.module("scipy.linalg.blas")

_TINY = 1e-300


def stribeck(v: np.ndarray, fc: np.ndarray | float, fs: np.ndarray | float, vs: float, delta: float) -> np.ndarray:
    """Stribeck curve g(v) [Nm] for velocities v [rad/s]; fc, fs may be arrays (load-dependent)."""
    absv = np.abs(v)
    with np.errstate(divide="ignore"):
        expo = np.exp(delta * (np.log(np.maximum(absv, _TINY)) - np.log(vs)))
    return fc + (fs - fc) * np.exp(-expo)


def linear_recurrence(a: np.ndarray, b: np.ndarray, z0: float) -> np.ndarray:
    """Solve z[k] = a[k] * z[k-1] + b[k] for k = 0..n-1 with z[-1] = z0. Shapes (n,)."""
    n = len(a)
    if n == 0:
        return np.empty(0)
    rhs = np.array(b, dtype=np.float64)
    rhs[0] += a[0] * z0
    band = np.empty((2, n))
    band[0] = 1.0
    band[1, :-1] = -a[1:]
    band[1, -1] = 0.0
    return blas.dtbsv(1, band, rhs, lower=1)


def bristle_state(v: np.ndarray, g: np.ndarray, sigma0: float, dt: np.ndarray, z0: float | None = None) -> np.ndarray:
    """Bristle deflection z [rad] at each sample.

    v: velocity (n,) [rad/s]; g: Stribeck curve (n,) [Nm]; sigma0 [Nm/rad];
    dt: interval ending at each sample (n,) [s]; z0: state before the first sample
    (None: start in the steady state of the first sample).
    """
    rate = sigma0 * np.abs(v) / g
    a = np.exp(-np.minimum(rate * dt, 700.0))
    zss = np.sign(v) * g / sigma0
    b = (1.0 - a) * zss
    if z0 is None:
        z0 = float(zss[0]) if len(zss) else 0.0
    return linear_recurrence(a, b, z0)


def lugre_friction(v: np.ndarray, g: np.ndarray, fv: np.ndarray | float, sigma0: float, sigma1: float,
                   dt: np.ndarray, z0: float | None = None) -> tuple[np.ndarray, float]:
    """Friction torque (n,) [Nm] and the final bristle state, for the extended LuGre model."""
    z = bristle_state(v, g, sigma0, dt, z0)
    zdot = v - sigma0 * np.abs(v) / g * z
    tau = sigma0 * z + sigma1 * zdot + fv * v
    return tau, (float(z[-1]) if len(z) else (z0 or 0.0))


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
