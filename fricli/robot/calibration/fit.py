"""The calibration's fits: the maximum a posteriori estimate with reweighted rows (``_map_fit``), the
prior strength chosen by blocked cross-validation (``choose_prior``), the fit over physically
consistent parameters (``consistent_fit``) and how well the run excites the parameters
(``_excitation``)."""

from __future__ import annotations

import math

import numpy as np

from fricli.core.errors import FitError
from fricli.robot.calibration.parameters import _from_pseudo, _from_pseudos, _random_regressor, pseudo_inertia


PRIOR_GRID = (0.01, 0.03, 0.1, 0.2, 0.5, 1.0, 3.0, 10.0)   # the prior strengths "auto" chooses from
PRIOR_FOLDS = 10           # contiguous blocks of time of the cross-validation that chooses the prior (as diagnose)
PRIOR_START = 0.5          # the fixed strength whose fit gives the cross-validation's row weights
UNDETERMINED = 1.0         # a direction whose data information is below the prior's stays at CAD
NUMERIC_ZERO = 1e-10       # ... or below this share of the best-determined direction's
MAX_ITERATIONS = 30


def _with_prior(s1: np.ndarray, nj: int, prior) -> np.ndarray:
    """Prior std (as ``prior_scales``) for strength ``prior`` (a float, or one per inertial parameter
    and armature, (11 * joints,)) from those for strength 1: friction's loose prior does not scale."""
    return np.concatenate([np.asarray(prior, dtype=float) * s1[:11 * nj], s1[11 * nj:]])


def choose_prior(Phi, y, x0, s1, sigma, rows_of, tau_rms, counts, *, per_group: bool = True, grid=PRIOR_GRID,
                 folds=PRIOR_FOLDS) -> tuple[np.ndarray, dict]:
    """The prior strengths on ``grid`` whose fits predict held-out data best (ridge selection by
    blocked cross-validation): the log cut into ``folds`` contiguous blocks of time, each predicted
    by the fit on the others; score: the held-out sum of squared residuals, each joint's rows weighted
    by 1 / its residual std in the fit at ``PRIOR_START``. First one strength for every parameter;
    then, with ``per_group``, each group's own in turn (each body's 10 inertial parameters, centred
    on CAD; each joint's armature, centred on the rotor inertia), until no group's change lowers the
    score. The weakest prior wins ties (noise-free data need none). ``Phi`` (n * joints, p),
    ``y`` (n * joints,), zero in the rows not used, ``counts`` (joints,) each joint's rows used,
    ``s1``: prior std at strength 1.
    Returns (strength of every inertial parameter and armature (11 * joints,), report)."""
    from scipy.linalg import solve_triangular

    from fricli.fitting.diagnosis.selection import fold_bounds

    nj = len(sigma)
    _, w, _, _ = _map_fit(Phi, y, x0, _with_prior(s1, nj, PRIOR_START), sigma, rows_of, tau_rms, counts)
    Wr = np.column_stack([Phi, y - Phi @ x0]) / w[rows_of, None]       # weighted regressor | residual at x0
    edges = fold_bounds(len(y) // nj, folds) * nj
    # each block as the R factor of its [W r]: |W_k d - r_k| = |R_k [d; -1]| without forming W^T W,
    # whose round-off swamps a held-out error far below the CAD model's (noise-free data)
    blocks = [np.linalg.qr(Wr[a:b], mode="r") for a, b in zip(edges[:-1], edges[1:])]
    others = [np.linalg.qr(np.vstack(blocks[:k] + blocks[k + 1:]), mode="r") for k in range(len(blocks))]
    p = Phi.shape[1]
    tie = 1e-9 * float(np.sum(np.square(Wr[:, -1])))     # round-off of the scores below

    def score(strengths):
        s = _with_prior(s1, nj, strengths)
        total = 0.0
        for Rk, Ro in zip(blocks, others):    # the fit without block k (ridge in z = d / s), scored on block k
            q, r = np.linalg.qr(np.vstack([Ro[:, :p] * s, np.eye(p)]))
            d = s * solve_triangular(r, q[:len(Ro)].T @ Ro[:, p])
            total += float(np.sum(np.square(Rk[:, :p] @ d - Rk[:, p])))
        return total

    held = lambda v: float(np.sqrt(max(v, 0.0) / counts.sum()))  # noqa: E731
    weak_first = sorted(grid, reverse=True)
    scores = {g: score(np.full(11 * nj, g)) for g in weak_first}
    chosen = max(g for g, v in scores.items() if v <= min(scores.values()) + tie)
    strengths, best = np.full(11 * nj, chosen), scores[chosen]
    per = np.full(2 * nj, chosen)      # each body's inertial parameters, then each joint's armature
    for _ in range(3 * per_group):
        changed = False
        for b in range(2 * nj):
            for g in weak_first:
                trial = per.copy()
                trial[b] = g
                cols = np.concatenate([np.repeat(trial[:nj], 10), trial[nj:]])
                v = score(cols)
                if v < best - tie:
                    per, strengths, best, changed = trial, cols, v, True
        if not changed:
            break
    report = {"grid": sorted(grid), "folds": folds, "chosen": chosen,
              "held_out_rms": {f"{g:g}": held(v) for g, v in sorted(scores.items())}}
    if per_group:
        report.update(per_group=[float(v) for v in per], held_out_rms_per_group=held(best))
    return strengths, report


def _map_fit(Phi, y, x0, s, sigma, rows_of, tau_rms, counts):
    """Maximum a posteriori estimate, rows weighted by each joint's residual std, re-estimated until
    the weights settle: (x, sigma (joints,), residuals (n, joints), iterations). Rows not used are
    zero in ``Phi`` and ``y``; ``counts`` (joints,): each joint's rows used."""
    nj, p = len(sigma), Phi.shape[1]
    # each joint's rows as the R factor of [Phi_j | y_j - Phi_j x0]: the same weighted least squares
    # (an orthogonal transform of each joint's rows) on p + 1 rows a joint
    r0 = y - Phi @ x0
    blocks = [np.linalg.qr(np.column_stack([Phi[rows_of == j], r0[rows_of == j]]), mode="r") for j in range(nj)]
    for iteration in range(1, MAX_ITERATIONS + 1):
        A = np.vstack([blk[:, :p] / sigma[j] for j, blk in enumerate(blocks)]) * s
        b = np.concatenate([blk[:, p] / sigma[j] for j, blk in enumerate(blocks)])
        z = np.linalg.lstsq(np.vstack([A, np.eye(len(s))]), np.concatenate([b, np.zeros(len(s))]), rcond=None)[0]
        x = x0 + s * z
        resid = (y - Phi @ x).reshape(-1, nj)
        new = np.maximum(np.sqrt(np.sum(resid ** 2, axis=0) / counts), 1e-9 * tau_rms + 1e-300)
        settled = np.max(np.abs(np.log(new / sigma))) < 0.01
        sigma = new
        if settled:
            break
    return x, sigma, resid, iteration


def _stribeck_rss(qd: np.ndarray, target: np.ndarray, vs: float) -> float:
    cols = np.column_stack([qd, np.sign(qd), np.sign(qd) * np.exp(-np.square(qd / vs)), np.ones_like(qd)])
    coef = np.linalg.lstsq(cols, target, rcond=None)[0]
    return float(np.sum(np.square(target - cols @ coef)))


_TRIL = np.tril_indices(4)


def consistent_fit(A: np.ndarray, b: np.ndarray, x_start: np.ndarray, x0: np.ndarray, s: np.ndarray,
                   nj: int, fixed: np.ndarray | None = None) -> np.ndarray:
    """The same weighted least squares with the same prior (``A`` (rows, 14 nj) and ``b`` weighted),
    over physically consistent parameters only: each body (less ``fixed`` (10 nj,), a declared
    payload) as a pseudo-inertia L L^T (L lower triangular), each armature as u^2. From ``x_start``
    with eigenvalues clipped and from ``x0``: the better; returns x."""
    from scipy import linalg, optimize

    fixed = np.zeros(10 * nj) if fixed is None else fixed
    q, r = linalg.qr(A, mode="economic")
    c = q.T @ b            # |A x - b|^2 = |r x - c|^2 + a constant
    def start(x):        # theta of x, each pseudo-inertia's eigenvalues clipped to be positive
        theta = []
        for k in range(nj):
            w, v = np.linalg.eigh(pseudo_inertia(x[10 * k:10 * k + 10] - fixed[10 * k:10 * k + 10]))
            w = np.maximum(w, 1e-6 * max(w.max(), 1e-12))
            theta.append(np.linalg.cholesky((v * w) @ v.T)[_TRIL])
        arm = x[10 * nj:11 * nj]
        return np.concatenate(theta + [np.sqrt(np.maximum(arm, 1e-6 * s[10 * nj:11 * nj])), x[11 * nj:]])

    def params(th):
        pis = []
        for k in range(nj):
            low = np.zeros((4, 4))
            low[_TRIL] = th[10 * k:10 * k + 10]
            pis.append(_from_pseudo(low @ low.T))
        return np.concatenate([np.concatenate(pis) + fixed, th[10 * nj:11 * nj] ** 2, th[11 * nj:]])

    def dparams(th):   # d x / d theta: block diagonal
        out = np.zeros((len(th), len(th)))
        rows, cols = np.arange(10), _TRIL
        for k in range(nj):
            low = np.zeros((4, 4))
            low[_TRIL] = th[10 * k:10 * k + 10]
            d = np.zeros((10, 4, 4))
            d[rows, cols[0]] = low[:, cols[1]].T     # E_ab L^T + L E_ba: row a and column a of L's column b
            d = d + d.transpose(0, 2, 1)
            out[10 * k:10 * k + 10, 10 * k:10 * k + 10] = _from_pseudos(d).T
        idx = np.arange(10 * nj, 11 * nj)
        out[idx, idx] = 2 * th[idx]
        idx = np.arange(11 * nj, len(th))
        out[idx, idx] = 1.0
        return out

    stacked = np.vstack([r, np.diag(1.0 / s)])
    # convex in x, not in the factors: from a clipped estimate a body can sit where L is nearly singular
    # and the steps vanish, so the fit also starts from the prior's centre (CAD), and the lower cost wins
    fits = [optimize.least_squares(lambda th: np.concatenate([r @ params(th) - c, (params(th) - x0) / s]), start(x),
                                   jac=lambda th: stacked @ dparams(th), x_scale="jac", method="lm",
                                   xtol=1e-8, ftol=1e-6, max_nfev=2000) for x in (x_start, x0)]
    fits = [f for f in fits if np.all(np.isfinite(f.x))]
    if not fits:
        raise FitError("the physically consistent fit did not converge")
    return params(min(fits, key=lambda f: f.cost).x)


def _excitation(robot, A: np.ndarray, Phi: np.ndarray, s: np.ndarray, names: list[str], seed: int,
                vs: np.ndarray | None = None, ratio: np.ndarray | None = None) -> dict:
    """How well the run determines the parameters.

    Structural: the base parameters (QR with column pivoting of the unscaled regressor at random
    states, as ``base_parameters``: identical for every trajectory and prior). This run: the
    condition number of its base regressor, and the directions of the identifiable parameters whose
    data information (eigenvalue of the prior-whitened information matrix, 1 = as much as the
    prior's) is below ``UNDETERMINED``."""
    from scipy import linalg

    R0 = _random_regressor(robot, seed, vs, ratio)
    R_ = R0 * s
    _, r, piv = linalg.qr(R0, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    rank = int(np.sum(d > 1e-9 * d[0]))
    base = np.sort(piv[:rank])
    # the identifiable subspace (whitened coordinates): right singular vectors of the random regressor
    _, sv, vt = np.linalg.svd(R_, full_matrices=False)
    U = vt[:rank].T
    null = vt[rank:].T          # what no joint torque sees: a mass with a part here is not determined alone
    tied = {}
    for c in range(0, 10 * len(robot.joints), 10):
        v = null @ null[c]
        if abs(v[c]) > 1e-6:
            tied[names[c]] = [names[k] for k in np.argsort(-np.abs(v)) if k != c and abs(v[k]) > 1e-3 * abs(v[c])][:3]
    sv_run = np.linalg.svd(Phi[:, base], compute_uv=False)
    sv_scaled = np.linalg.svd(A[:, base] / np.linalg.norm(A[:, base], axis=0), compute_uv=False)
    g, V = np.linalg.eigh(U.T @ (A.T @ A) @ U)
    cut = max(UNDETERMINED, NUMERIC_ZERO * float(g.max()))
    undetermined = []
    for i in np.flatnonzero(g < cut):
        w = U @ V[:, i]
        w = w / np.abs(w).max()
        order = np.argsort(-np.abs(w))
        parts = [{"parameter": names[c], "weight": round(float(w[c]), 3)} for c in order[:4] if abs(w[c]) >= 0.2]
        undetermined.append({"information": float(max(g[i], 0.0)), "combination": parts})
    return {
        "parameters": len(s), "base_parameters": rank, "structurally_unidentifiable": len(s) - rank,
        "base": [names[c] for c in base],
        "condition_number": float(sv_run[0] / sv_run[-1]) if sv_run[-1] > 0 else math.inf,
        "condition_number_scaled": float(sv_scaled[0] / sv_scaled[-1]) if sv_scaled[-1] > 0 else math.inf,
        "undetermined": undetermined,
        "masses_not_determined_alone": tied,
    }
