"""Identify the Generalized Maxwell-Slip model (``fricli identify --kind gms``).

With the element deflection limits d_i fixed on a grid, every element's deflection z_i follows
from the position alone (``fricli.models.gms.element_states``), so the model is linear in the
element forces F_i and its other coefficients (the Coulomb level and its levels along the travel,
Stribeck, viscous, load, the robot-model error's position terms): one bounded linear least-squares
fit (``scipy.optimize.lsq_linear``; every friction coefficient >= 0, so the model is passive) per
candidate, solved on the k x k
normal equations (k < 40), so a candidate costs the same on any length of log.

The grid is log-spaced from ``D_LO`` times the mean travel between velocity reversals (or 20
samples' travel, whichever is larger) up to ``D_HI`` times it. The number of elements N
(``ELEMENTS``, 0 included: no hysteresis at all), the intervals of the Coulomb level along the
travel (``COULOMB_K``, 0: one level) and the harmonics of the robot-model error (``ERROR_K``, -1: none, 0: an offset) are
chosen on held-out time blocks: the log is cut into ``BLOCKS`` contiguous blocks, each candidate
is fitted on all blocks but one and scored on that one, and the candidate of least held-out
error wins; a candidate with fewer coefficients within ``TOLERANCE`` of it is preferred. The
element states run over the whole log (they are causal and read only the position), so a block
is scored with the memory its past gives it, as in use. The Stribeck velocity is
chosen first the same way, among the ``VS_QUANTILES`` percentiles of the speeds in motion, on the
largest candidate with one Coulomb level. Holds (``metrics.at_hold``: over a second not in motion,
where the torque is what the controller left) are left out of the fit and of the held-out scores;
the element states run through them.

A log may join several recordings (``recordings``: a pause of more than ``GAP`` sample periods
starts one). Each recording's elements start afresh at its first row (the joint moved unseen during
the pause), and each has an offset of its own in the robot-model error: a torque sensor's or the
rigid-body model's bias changes from one recording to the next, and with one offset for all the
difference would be taken up by the position terms, the elements and the sliding curve, which then
mispredict other motion. The model keeps the mean of the recordings' offsets (a new log is a
recording of its own); the fit record lists them.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.core import lazy, logs, metrics
from fricli.core.errors import DataError, FitError
from fricli.models.gms import GMSModel, columns

optimize = lazy.module("scipy.optimize")

ELEMENTS = (0, 4, 8)
COULOMB_K = (0, 2, 4, 8, 16)
ERROR_K = (-1, 0, 1, 2, 3)
VS_QUANTILES = (2, 5, 10, 25, 50)
BLOCKS = 5
TOLERANCE = 0.01       # a smaller model within 1 % of the best held-out error is preferred
D_LO = 1e-3            # the smallest element deflection, share of the mean travel between reversals
D_HI = 0.5             # the largest, share of the same travel
GAP = 10               # a step in time above GAP median sample periods starts a new recording


def recordings(t: np.ndarray) -> np.ndarray:
    """Start rows (r,) of the recordings a log joins: row 0 and every row after a step in time
    longer than ``GAP`` median sample periods (the joint moved unseen there)."""
    t = np.asarray(t, dtype=np.float64)
    if len(t) < 3:
        return np.zeros(1, dtype=int)
    dt = np.diff(t)
    return np.concatenate([[0], np.flatnonzero(dt > GAP * float(np.median(dt))) + 1]).astype(int)


def _regressor(signals, d, vs, load, q_range, ks, ke_max, starts) -> np.ndarray:
    """``columns`` of each recording (its elements starting afresh at its first row), stacked; with
    more than one recording and ``ke_max`` >= 0, the offset column replaced by one per recording."""
    if len(starts) == 1:
        return columns(signals, d, vs, load, q_range, ks, ke_max)[0]
    n = len(signals["qd"])
    ends = np.append(starts[1:], n)
    x = np.vstack([columns({k: v[a:b] for k, v in signals.items() if np.ndim(v) and len(v) == n},
                           d, vs, load, q_range, ks, ke_max)[0] for a, b in zip(starts, ends)])
    if ke_max < 0:
        return x
    off = x.shape[1] - 1 - 2 * ke_max
    own = np.zeros((n, len(starts)))
    for j, (a, b) in enumerate(zip(starts, ends)):
        own[a:b, j] = 1.0
    return np.hstack([x[:, :off], own, x[:, off + 1:]])


def travel_between_reversals(q: np.ndarray, qd: np.ndarray) -> float:
    """Mean distance [rad or m] the joint travels between two velocity reversals (its whole
    travel when it never reverses): the total travel over the number of runs in one direction."""
    moving = metrics.in_motion(qd)
    s = np.sign(qd[moving])
    qm = q[moving]
    if len(qm) < 2:
        return 0.0
    cut = np.flatnonzero(np.diff(s) != 0) + 1
    edges = np.concatenate([[0], cut, [len(qm)]])
    spans = [abs(qm[b - 1] - qm[a]) for a, b in zip(edges[:-1], edges[1:]) if b - a > 1]
    return float(np.sum(spans) / len(spans)) if spans else float(np.ptp(qm))


def grid(n: int, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Deflection limits (n,) [rad or m], log-spaced (module doc)."""
    if n == 0:
        return np.zeros(0)
    travel = travel_between_reversals(q, qd)
    step = float(np.median(np.abs(np.diff(q)))) if len(q) > 1 else 0.0
    lo = max(D_LO * travel, step, 1e-12)
    hi = max(D_HI * travel, 2 * lo)
    return np.geomspace(lo, hi, n)


def _solve(gram: np.ndarray, xy: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """Bounded least squares (coefficients >= lower) from the normal equations: the columns scaled
    to unit norm, the Gram matrix factored (Cholesky, a tiny ridge for rank), lsq_linear on the
    k x k system."""
    scale = np.sqrt(np.diag(gram)).copy()
    scale[scale == 0] = 1.0
    g = gram / np.outer(scale, scale) + 1e-10 * np.eye(len(scale))
    r = np.linalg.cholesky(g).T                       # g = r' r
    rhs = np.linalg.solve(r.T, xy / scale)
    res = optimize.lsq_linear(r, rhs, bounds=(lower * scale, np.full(len(scale), np.inf)), method="bvls")
    return res.x / scale


def _layout(n_el: int, load: bool, kc_: int, ke: int, coulomb_ks, ke_max: int,
            offsets: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Columns (indices into the full regressor of ``columns`` with ``coulomb_ks``, ke_max) of a
    candidate (``offsets`` offset columns: one per recording), and their lower bounds."""
    base = n_el + 3 + int(load)
    idx = [i for i in range(base) if not (kc_ and i == n_el)]     # the hats replace the constant level
    at = base
    for k in coulomb_ks:
        if k == kc_ and k:
            idx += list(range(at, at + k + 1))
        at += k + 1
    n_friction = len(idx)
    if ke >= 0:
        idx += list(range(at, at + offsets + 2 * ke))
    lower = np.full(len(idx), -np.inf)
    lower[:n_friction] = 0.0                          # every friction coefficient >= 0: passive
    return np.array(idx), lower


def fit(signals: dict[str, np.ndarray], *, axis: str = "rotary", elements=ELEMENTS, coulomb_k=COULOMB_K,
        error_k=ERROR_K, blocks: int = BLOCKS) -> tuple[GMSModel, dict]:
    """Fit the GMS model to a log's signals (canonical units); (model, fit record): errors over all
    rows and the rows in motion, every candidate's held-out error and the choice."""
    if "q" not in signals:
        raise DataError("the GMS model needs the position q (its elements deflect with it)")
    q = np.asarray(signals["q"], dtype=np.float64)
    qd = np.asarray(signals["qd"], dtype=np.float64)
    moving = metrics.moving_both_ways(qd, "the GMS model")
    y = logs.friction_target(signals)
    tau_g = signals.get("tau_g")
    load = tau_g is not None and bool(metrics.load_can_show(np.abs(tau_g[moving]), y[moving]))
    notes = [] if load else ["no load slope can show in the log (|tau_g| absent or nearly constant): kc = 0"]
    q_range = (float(q.min()), float(q.max()))
    if not q_range[1] > q_range[0]:
        raise DataError("the joint's position does not change over the log")
    n = len(y)
    blocks = max(2, min(blocks, n // 50))
    edges = np.linspace(0, n, blocks + 1).astype(int)
    ks = tuple(k for k in coulomb_k if k)
    starts = recordings(signals["t"]) if "t" in signals else np.zeros(1, dtype=int)
    ke_max = max(error_k)

    held = metrics.at_hold(signals["t"], qd) if "t" in signals else np.zeros(n, dtype=bool)
    if held.any():
        notes.append(f"{int(held.sum())} rows of holds (over {metrics.HOLD_S:g} s not in motion) left out of the fit: "
                     "the torque there is what the controller left; the elements run through them")
    fitted = np.flatnonzero(~held)
    cuts = np.searchsorted(fitted, edges)
    rows = fitted if held.any() else slice(None)

    def normal(n_el, vs_):
        d = grid(n_el, q, qd)
        x = _regressor(signals, d, vs_, load, q_range, ks, ke_max, starts)[rows]
        yf = y[rows]
        parts = [(x[a:b].T @ x[a:b], x[a:b].T @ yf[a:b], float(yf[a:b] @ yf[a:b])) for a, b in zip(cuts[:-1], cuts[1:])]
        return d, parts, sum(p[0] for p in parts), sum(p[1] for p in parts)

    def heldout(parts, gram, xy, idx, lower):
        sse = 0.0
        for gb, xb, yb in parts:
            coef = _solve((gram - gb)[np.ix_(idx, idx)], (xy - xb)[idx], lower)
            sse += max(float(coef @ gb[np.ix_(idx, idx)] @ coef - 2 * coef @ xb[idx] + yb), 0.0)
        return math.sqrt(sse / len(fitted))

    # the Stribeck velocity first, on the largest candidate with one Coulomb level
    speeds = np.abs(qd[moving])
    vs_scores = []
    for quantile in VS_QUANTILES:
        vs_ = max(float(np.percentile(speeds, quantile)), 1e-9)
        _, parts, gram, xy = normal(max(elements), vs_)
        vs_scores.append((heldout(parts, gram, xy, *_layout(max(elements), load, 0, ke_max, ks, ke_max, len(starts))), vs_))
    vs = min(vs_scores)[1]
    candidates = []
    for n_el in elements:
        d, parts, gram, xy = normal(n_el, vs)
        for kc_ in coulomb_k:
            for ke in error_k:
                idx, lower = _layout(n_el, load, kc_, ke, ks, ke_max, len(starts))
                candidates.append({"elements": int(n_el), "coulomb_k": kc_, "error_k": ke, "size": len(idx),
                                   "heldout_rmse": heldout(parts, gram, xy, idx, lower), "_d": d, "_idx": idx,
                                   "_lower": lower, "_g": gram, "_xy": xy})
    best = min(c["heldout_rmse"] for c in candidates)
    chosen = min((c for c in candidates if c["heldout_rmse"] <= (1 + TOLERANCE) * best),
                 key=lambda c: (c["size"], c["heldout_rmse"]))
    idx = chosen["_idx"]
    coef = _solve(chosen["_g"][np.ix_(idx, idx)], chosen["_xy"][idx], chosen["_lower"])
    n_el, kc_, ke = chosen["elements"], chosen["coulomb_k"], chosen["error_k"]
    coef = np.concatenate([coef[:n_el], [0.0] if kc_ else [], coef[n_el:]])   # fc = 0 where the hats are
    at = n_el + 3
    kc = float(coef[at]) if load else 0.0
    at += int(load)
    levels = coef[at:at + kc_ + 1] if kc_ else np.zeros(0)
    at += kc_ + 1 if kc_ else 0
    pos = np.maximum   # bvls keeps the bounds; rounding may leave -0.0
    # a new log is a recording of its own: its offset is the mean of the recordings' offsets
    error = np.concatenate([[coef[at:at + len(starts)].mean()], coef[at + len(starts):]]) if ke >= 0 else coef[at:]
    try:
        model = GMSModel(chosen["_d"], pos(coef[:n_el], 0.0), fc=max(coef[n_el], 0.0), fst=max(coef[n_el + 1], 0.0),
                         vs=vs, fv=max(coef[n_el + 2], 0.0), kc=max(kc, 0.0), q_lo=q_range[0], q_hi=q_range[1],
                         coulomb_pos=pos(levels, 0.0), error=error, axis=axis)
    except ValueError as exc:
        raise FitError(f"the GMS fit gave unusable parameters ({exc})") from None
    pred = model.predict(signals)[0]
    if not np.isfinite(pred).all():
        raise FitError("the GMS fit gave a model with non-finite predictions")
    if len(starts) > 1 and ke >= 0:
        notes.append(f"the log joins {len(starts)} recordings (a pause of over {GAP} sample periods before each): "
                     "offsets " + ", ".join(f"{c:.4g}" for c in coef[at:at + len(starts)])
                     + " (robot-model error, one per recording); the model keeps their mean")
    record = metrics.errors(y, pred)
    record.update(moving=metrics.errors(y[moving], pred[moving]), moving_rows=int(moving.sum()),
                  held_rows=int(held.sum()), elements=n_el, coulomb_k=kc_, error_k=ke, blocks=blocks, recordings=len(starts),
                  recording_offsets=[float(c) for c in coef[at:at + len(starts)]] if ke >= 0 else [], heldout_best=best,
                  vs_candidates=[{"vs": v, "heldout_rmse": e} for e, v in vs_scores], notes=notes,
                  candidates=[{k: v for k, v in c.items() if not k.startswith("_")} for c in candidates])
    return model, record
