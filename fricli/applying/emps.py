"""The EMPS benchmark (electro-mechanical positioning system), processed the benchmark's way.

The benchmark (Janot, Gautier, Brunot: "Data set and reference models of EMPS") identifies
the inverse dynamic model ``tau = M*qdd + Fv*qd + Fc*sign(qd) + offset`` by IDIM-LS:

1. ``q`` [m] low-passed by a 4th-order Butterworth filter at 100 Hz, forwards and backwards;
2. velocity and acceleration by central differences of the filtered position
   ((x[k+1] - x[k-1]) / (2 dt), zero at both ends, as the reference scripts leave them);
3. the first 49 samples dropped (filter edge effects);
4. every regressor column and the force decimated by 10 (``scipy.signal.decimate``:
   an order-8 Chebyshev anti-alias filter applied forwards and backwards, then every 10th sample);
5. ordinary least squares; relative error ``100 * ||y - yhat|| / ||y||`` on the decimated force.

Re-run with scipy this gives M = 95.09 kg, Fv = 203.13 N s/m, Fc = 20.44 N, offset = -3.19 N
and 4.37 % (symmetric model), 3.54 % (asymmetric model); the published MATLAB figures are
4.08 % and 3.11 %.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import signal as sps

from fricli.core import logs
from fricli.core.errors import DataError

CUTOFF_HZ = 100.0       # Butterworth cut-off used by the benchmark
ORDER = 4
DROP = 49               # samples dropped at the start
DECIMATE = 10

PUBLISHED = {
    "symmetric": {"M": 95.1089, "Fv": 203.5034, "Fc": 20.3935, "offset": -3.1648, "rel_error": 4.0834},
    "asymmetric": {"M": 95.1540, "Fv+": 166.7061, "Fc+": 20.1440, "Fv-": 240.4236, "Fc-": 20.6277,
                   "rel_error": 3.1117},
}
SCIPY_RERUN = {"symmetric": {"M": 95.09, "Fv": 203.12, "Fc": 20.44, "offset": -3.19, "rel_error": 4.37},
               "asymmetric": {"rel_error": 3.54}}


def central_difference(x: np.ndarray, dt: float) -> np.ndarray:
    """(x[k+1] - x[k-1]) / (2 dt), shape (n,), zero at the first and last sample."""
    out = np.zeros_like(x, dtype=np.float64)
    out[1:-1] = (x[2:] - x[:-2]) / (2.0 * dt)
    return out


def motion(t: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Benchmark velocity and acceleration (n,) from position q (n,) sampled at times t [s]."""
    if len(q) < 64:
        raise DataError("too few samples for the EMPS processing (need at least 64)")
    dt = float(np.median(np.diff(t)))
    b, a = sps.butter(ORDER, CUTOFF_HZ, fs=1.0 / dt)
    qf = sps.filtfilt(b, a, q)
    qd = central_difference(qf, dt)
    return qd, central_difference(qd, dt)


def decimated(x: np.ndarray) -> np.ndarray:
    """Drop the first 49 samples, then ``scipy.signal.decimate`` by 10. Shape (~(n-49)/10,)."""
    return sps.decimate(np.asarray(x, dtype=np.float64)[DROP:], DECIMATE)


def relative_error(y: np.ndarray, y_pred: np.ndarray) -> float:
    """100 * ||y - yhat|| / ||y|| [%] on full-rate signals (n,), no filtering."""
    return float(100.0 * np.linalg.norm(y - y_pred) / np.linalg.norm(y))


def benchmark_error(y: np.ndarray, y_pred: np.ndarray) -> float:
    """The benchmark's relative error [%]: both signals (n,) dropped and decimated first."""
    yd = decimated(y)
    return relative_error(yd, decimated(y_pred))


def signals(log: logs.Log) -> dict[str, np.ndarray]:
    """A copy of ``log.signals`` with qd and qdd computed the benchmark's way from q."""
    sig = dict(log.signals)
    if "q" not in sig:
        raise DataError("the EMPS processing needs the position column 'q'")
    sig["qd"], sig["qdd"] = motion(sig["t"], sig["q"])
    return sig


@dataclasses.dataclass
class IdimResult:
    """The benchmark's IDIM-LS fit: parameters [kg, N s/m, N] and relative error [%]."""

    params: dict[str, float]
    rel_error: float
    cond: float


def idim_ls(t: np.ndarray, q: np.ndarray, force: np.ndarray, asymmetric: bool = False) -> IdimResult:
    """The benchmark's reference identification on raw t [s], q [m], force [N] (n,)."""
    qd, qdd = motion(t, q)
    y = decimated(force)
    if asymmetric:
        pos, neg = (qd > 0).astype(float), (qd < 0).astype(float)
        names = ["M", "Fv+", "Fc+", "Fv-", "Fc-"]
        cols = [qdd, qd * pos, pos, qd * neg, -neg]
    else:
        names = ["M", "Fv", "Fc", "offset"]
        cols = [qdd, qd, np.sign(qd), np.ones_like(qd)]
    X = np.column_stack([decimated(c) for c in cols])
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    err = relative_error(y, X @ theta)
    return IdimResult(dict(zip(names, map(float, theta))), err, float(np.linalg.cond(X)))


def model_errors(model, log: logs.Log) -> dict[str, float]:
    """Relative error [%] of a friction model's force prediction, raw and the benchmark's way.

    The EMPS log has no gravity and no robot model, so the predicted motor force is the
    model's output (any inertia term is part of it once diagnosed). ``raw`` uses fricli's
    own derived signals (``log.signals``) at the full rate; ``benchmark`` feeds the model the
    benchmark's velocity and acceleration and compares after dropping and decimating.
    """
    y = log.signals["tau_m"]
    raw = relative_error(y, model.predict(log.signals)[0])
    bench = benchmark_error(y, model.predict(signals(log))[0])
    return {"raw": raw, "benchmark": bench}
