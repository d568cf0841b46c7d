"""The calibration's fits: the maximum a posteriori estimate with reweighted rows (``_map_fit``), the
prior strength chosen by blocked cross-validation (``choose_prior``), the fit over physically
consistent parameters (``consistent_fit``) and how well the run excites the parameters
(``_excitation``)."""

from __future__ import annotations

import math

import numpy as np

from fricli.core.errors import FitError
from fricli.robot.calibration.parameters import _from_pseudo, _random_regressor, pseudo_inertia


PRIOR_GRID = (0.01, 0.03, 0.1, 0.2, 0.5, 1.0, 3.0, 10.0)   # the prior strengths "auto" chooses from
PRIOR_FOLDS = 10           # contiguous blocks of time of the cross-validation that chooses the prior (as diagnose)
PRIOR_START = 0.5          # the fixed strength whose fit gives the cross-validation's row weights
UNDETERMINED = 1.0         # a direction whose data information is below the prior's stays at CAD
NUMERIC_ZERO = 1e-10       # ... or below this share of the best-determined direction's
MAX_ITERATIONS = 30
STRIBECK_ALTERNATIONS = 4  # rounds of the fit and the Stribeck velocities' search
STRIBECK_GRID = np.geomspace(0.005, 0.5, 25)   # Stribeck velocities searched, x the joint's top speed


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

    prior_rows = np.hstack([np.eye(p), np.zeros((p, 1))])

    def score(strengths):
        s = _with_prior(s1, nj, strengths)
        scaled = np.append(s, 1.0)
        total = 0.0
        for Rk, Ro in zip(blocks, others):    # the fit without block k (ridge in z = d / s), scored on block k
            r = np.linalg.qr(np.vstack([Ro * scaled, prior_rows]), mode="r")    # [R | Q^T rhs]: Q not formed
            d = s * solve_triangular(r[:p, :p], r[:p, p])
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
                if g == per[b]:
                    continue             # the current strength: its score is ``best``
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


def stribeck_velocity(qd: np.ndarray, target: np.ndarray, top: float) -> float:
    """The Stribeck velocity vs on the grid ``top`` x STRIBECK_GRID whose bump sign(qd) exp(-(qd / vs)^2),
    fitted with qd, sign(qd) and an offset to ``target`` (n,) at the velocities ``qd`` (n,) of the rows
    in motion, leaves the least squared error. A vs below the slowest of them has no rows to be
    fitted on: left out (the largest kept when every one is)."""
    grid = top * STRIBECK_GRID
    slowest = np.abs(qd).min()
    return float(min(grid[grid >= slowest] if grid[-1] >= slowest else grid[-1:],
                     key=lambda vs: _stribeck_rss(qd, target, vs)))


def _stribeck_rss(qd: np.ndarray, target: np.ndarray, vs: float) -> float:
    cols = np.column_stack([qd, np.sign(qd), np.sign(qd) * np.exp(-np.square(qd / vs)), np.ones_like(qd)])
    coef = np.linalg.lstsq(cols, target, rcond=None)[0]
    return float(np.sum(np.square(target - cols @ coef)))


_BASIS = np.array([pseudo_inertia(e) for e in np.eye(10)])   # (10, 4, 4): pseudo_inertia(pi) = sum_i pi_i E_i
GAP = 1e-9           # the consistent fit ends within this share of its cost (at least 1) above the optimum
GROWTH = 100.0       # the barrier's weight t grows by this factor once its centre is reached ...
CENTRED = 1e-2       # ... i.e. once Newton's decrement^2 is below this
MAX_NEWTON = 400


def consistent_fit(A: np.ndarray, b: np.ndarray, x_start: np.ndarray, x0: np.ndarray, s: np.ndarray,
                   nj: int, fixed: np.ndarray | None = None, info: dict | None = None) -> np.ndarray:
    """The same weighted least squares with the same prior (``A`` (rows, p) and ``b`` weighted, prior
    centre ``x0`` and std ``s`` (p,)), over physically consistent parameters only: each body's
    pseudo-inertia J (less ``fixed`` (10 nj,), a declared payload) positive semidefinite, each armature
    a not negative. F(x) = |A x - b|^2 + |(x - x0) / s|^2 is convex and the constraints are cones: a
    barrier method, damped Newton steps on t F(x) - sum log det J - sum log a, t grown by ``GROWTH``
    at each centre, from ``x_start`` or ``x0`` (the lower F) with each body's eigenvalues clipped. A
    dual point from each step bounds the optimum F* from below; ends when F(x) - F* <= ``GAP``
    max(F(x), 1), or after ``MAX_NEWTON`` steps. ``info`` (optional) gets ``gap`` (F(x) - F* at most),
    ``newton_steps`` and ``converged`` (the gap within the tolerance). Returns x (p,): each body strictly consistent."""
    from scipy import linalg

    fixed = np.zeros(10 * nj) if fixed is None else fixed
    p = A.shape[1]
    rc = linalg.qr(np.column_stack([A, b]), mode="r")[0][:p]          # |A x - b|^2 = |r x - c|^2 + a constant
    top = linalg.qr(np.block([[rc], [np.diag(1.0 / s), (x0 / s)[:, None]]]), mode="r")[0][:p + 1]
    rh = top[:p, :p]                         # F(xu + d) = F(xu) + |rh d|^2: no round-off of F itself
    xu = linalg.solve_triangular(rh, top[:p, p])                         # the unconstrained minimum
    fu = float(top[p, p]) ** 2                                           # F(xu) less the constant
    arm, m = slice(10 * nj, 11 * nj), 5 * nj                               # m: the barrier's degree

    def excess(d):          # F(xu + d) - F(xu)
        return float(np.sum(np.square(rh @ d)))

    def pseudo(d):          # (nj, 4, 4) at x = xu + d
        return np.einsum("ki,iab->kab", (xu[:10 * nj] + d[:10 * nj] - fixed).reshape(nj, 10), _BASIS)

    def inside(d):          # every J positive definite in floating point, every armature positive
        try:
            np.linalg.cholesky(pseudo(d))
        except np.linalg.LinAlgError:
            return False
        return bool(np.all(xu[arm] + d[arm] > 0))

    def clipped(x):         # d of a strictly consistent point: each body's eigenvalues clipped
        d = np.array(x, dtype=float) - xu
        for k in range(nj):
            w, v = np.linalg.eigh(pseudo(d)[k])
            floor = 1e-3 * max(float(np.abs(w).max()), 1e-12)
            d[10 * k:10 * k + 10] = _from_pseudo((v * np.maximum(w, floor)) @ v.T) + fixed[10 * k:10 * k + 10] \
                - xu[10 * k:10 * k + 10]
        d[arm] = np.maximum(xu[arm] + d[arm], 1e-3 * s[arm]) - xu[arm]
        return d

    d = min((clipped(x) for x in (x_start, x0)), key=excess)
    t = m / max(excess(d), 1e-300)      # the barrier's share m / t about the start's excess
    lower, centred, step = -math.inf, False, 0     # lower: a bound on F* - F(xu)
    while step < MAX_NEWTON and excess(d) - lower > GAP * max(excess(d) + fu, 1.0):
        step += 1
        if centred:
            t, centred = t * GROWTH, False
        low = np.linalg.cholesky(pseudo(d))                                   # J = L L^T
        li = np.linalg.inv(low)
        gi = np.einsum("kab,ibc,kdc->kiad", li, _BASIS, li)     # (nj, 10, 4, 4): L^-1 E_i L^-T
        grad = 2.0 * t * (rh.T @ (rh @ d))
        grad[:10 * nj] -= np.einsum("kiaa->ki", gi).ravel()     # d(-log det J)/d pi_i = -tr(J^-1 E_i)
        grad[arm] -= 1.0 / (xu[arm] + d[arm])
        # Newton's system as least squares, the square roots of its terms stacked: t F's, the barrier's
        # (tr(J^-1 E_i J^-1 E_j) = <L^-1 E_i L^-T, L^-1 E_j L^-T>) and the armatures'
        root = np.zeros((17 * nj, p))
        for k in range(nj):
            root[16 * k:16 * k + 16, 10 * k:10 * k + 10] = gi[k].reshape(10, 16).T
        root[16 * nj + np.arange(nj), np.arange(10 * nj, 11 * nj)] = 1.0 / (xu[arm] + d[arm])
        newton = linalg.qr(np.vstack([math.sqrt(2.0 * t) * rh, root]), mode="r")[0][:p]
        dd = -linalg.solve_triangular(newton, linalg.solve_triangular(newton, grad, trans="T"))
        # mu: the eigenvalues of L^-1 dJ L^-T and da / a along dd
        half = np.linalg.solve(low, np.einsum("ki,iab->kab", dd[:10 * nj].reshape(nj, 10), _BASIS))
        mu = np.concatenate([np.linalg.eigvalsh(np.linalg.solve(low, half.transpose(0, 2, 1))).ravel(),
                             dd[arm] / (xu[arm] + d[arm])])
        if mu.max() <= 1.0:
            # the duals (J^-1 - J^-1 dJ J^-1) / t and (1 - da / a) / (t a) are PSD, and xu + d + dd
            # minimises the Lagrangian with them: F* >= F(xu + d + dd) - (m - |mu|^2) / t
            lower = max(lower, excess(d + dd) - (m - float(mu @ mu)) / t)
        # along dd: t F and the barrier change by t (2 a (rh d).(rh dd) + a^2 |rh dd|^2) - sum log(1 + a mu)
        linear, square = 2.0 * t * float((rh @ d) @ (rh @ dd)), t * excess(dd)
        slope = linear - float(np.sum(mu))            # -(Newton's decrement^2)
        alpha = min(1.0, 0.99 / max(float(-mu.min()), 1e-300))
        while alpha > 1e-12 and not (alpha * linear + alpha ** 2 * square - float(np.sum(np.log1p(alpha * mu)))
                                     <= 0.25 * alpha * slope and inside(d + alpha * dd)):
            alpha *= 0.5
        if alpha <= 1e-12:
            break
        d = d + alpha * dd
        centred = -slope <= CENTRED
    x = xu + d
    if not np.all(np.isfinite(x)):
        raise FitError("the physically consistent fit did not converge")
    if info is not None:
        gap = excess(d) - lower
        info.update(gap=float(gap), newton_steps=step, converged=bool(gap <= GAP * max(excess(d) + fu, 1.0)))
    return x


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
