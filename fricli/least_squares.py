"""Bounded nonlinear least squares for a handful of parameters (identification's solver).

``solve`` minimises 0.5*||fun(x)||^2 over lb <= x <= ub by Levenberg-Marquardt:

- the Jacobian by forward differences, steps sqrt(eps)*max(1, |x_i|) taken towards the
  inside of the box;
- Marquardt's scaling: the damping is lam*diag(J'J), with each diagonal entry the largest seen
  so far (as MINPACK does), so that the result does not depend on the units of the parameters;
- the bounds by projection: a parameter at a bound whose gradient points out of the box is held
  there for the step, every trial point is clipped into the box;
- the damping by the gain ratio (Nielsen 1999): the ratio of the actual to the predicted
  reduction shrinks lam after a good step and doubles its growth after each refused one.

Every accepted step lowers the cost, so the last iterate is also the best one. It stops when a
step lowers the cost by less than ftol of it, moves x by less than xtol*(xtol + ||x||), when the
gradient is orthogonal to the residual to within gtol (MINPACK's test, scale-free), or after
max_nfev evaluations of ``fun`` (those for the Jacobian not counted, as in scipy).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

_EPS_STEP = math.sqrt(np.finfo(float).eps)


@dataclasses.dataclass
class Result:
    """x (n,): the best point; cost: 0.5*||fun(x)||^2; nfev, njev: evaluations of fun for steps
    and Jacobians made; status: 0 when max_nfev stopped it, 1 gradient, 2 ftol, 3 xtol."""

    x: np.ndarray
    cost: float
    nfev: int
    njev: int
    status: int
    message: str


def solve(fun, x0: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], *, max_nfev: int = 400,
          ftol: float = 1e-8, xtol: float = 1e-8, gtol: float = 1e-8) -> Result:
    """Minimise 0.5*||fun(x)||^2 for x (n,) within bounds (lb (n,), ub (n,), +-inf allowed),
    from x0 (n,). fun returns the residuals (m,). Raises ValueError when the residuals are not
    finite at x0 or the Jacobian is not finite."""
    lb, ub = (np.broadcast_to(np.asarray(b, dtype=float), np.shape(x0)) for b in bounds)
    if (lb > ub).any():
        raise ValueError("a lower bound is above its upper bound")
    x = np.clip(np.asarray(x0, dtype=float), lb, ub)
    r = np.asarray(fun(x), dtype=float)
    nfev, njev = 1, 0
    cost = 0.5 * sumsq(r)
    if not math.isfinite(cost):
        raise ValueError("the residuals are not finite at the start point")
    diag = np.zeros(len(x))
    lam, growth = 1e-3, 2.0

    def result(status: int, message: str) -> Result:
        return Result(x, cost, nfev, njev, status, message)

    while True:
        jac = _jacobian(fun, x, r, lb, ub)
        njev += 1
        if not np.isfinite(jac).all():
            raise ValueError("the Jacobian is not finite")
        grad = jac.T @ r
        jtj = jac.T @ jac
        diag = np.maximum(diag, np.diag(jtj))
        free = ~(((x <= lb) & (grad > 0)) | ((x >= ub) & (grad < 0)))
        norms = np.sqrt(np.diag(jtj))
        cosine = np.abs(grad[free]) / np.where(norms[free] > 0, norms[free], np.inf)
        if cost == 0 or not free.any() or cosine.max() <= gtol * math.sqrt(2 * cost):
            return result(1, "the gradient is orthogonal to the residuals")
        sub = jtj[np.ix_(free, free)]
        damp = np.where(diag[free] > 0, diag[free], 1.0)
        while True:
            if nfev >= max_nfev:
                return result(0, f"stopped after {max_nfev} evaluations")
            step = np.zeros(len(x))
            try:
                step[free] = np.linalg.solve(sub + lam * np.diag(damp), -grad[free])
            except np.linalg.LinAlgError:
                lam, growth = lam * growth, growth * 2
                continue
            x_new = np.clip(x + step, lb, ub)
            step = x_new - x
            r_new = np.asarray(fun(x_new), dtype=float)
            nfev += 1
            cost_new = 0.5 * sumsq(r_new)
            predicted = -(grad @ step + 0.5 * step @ jtj @ step)
            ratio = (cost - cost_new) / predicted if predicted > 0 and math.isfinite(cost_new) else -1.0
            small_step = np.linalg.norm(step) <= xtol * (xtol + np.linalg.norm(x))
            if ratio > 0:
                small_change = cost - cost_new <= ftol * cost and ratio > 0.25
                x, r, cost = x_new, r_new, cost_new
                lam *= max(1 / 3, 1 - (2 * ratio - 1) ** 3)
                growth = 2.0
                if small_change:
                    return result(2, "the cost changed by less than ftol")
                if small_step:
                    return result(3, "the step was smaller than xtol")
                break
            if small_step:
                return result(3, "the step was smaller than xtol")
            lam, growth = lam * growth, growth * 2


def _jacobian(fun, x: np.ndarray, r: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """Forward-difference Jacobian (m, n) of fun at x with residuals r (m,)."""
    jac = np.empty((len(r), len(x)))
    for i in range(len(x)):
        h = _EPS_STEP * max(1.0, abs(x[i]))
        if x[i] + h > ub[i]:
            h = -h
        xi = x.copy()
        xi[i] += h
        jac[:, i] = (np.asarray(fun(xi), dtype=float) - r) / (xi[i] - x[i])
    return jac


def sumsq(r: np.ndarray) -> float:
    """Sum of squares of r (n,)."""
    # einsum, not r @ r: a threaded BLAS dot is erratic on a busy 2-core machine
    return float(np.einsum("i,i->", r, r))
