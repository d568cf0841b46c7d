"""The parameters of a LuGre identification (``fricli.fitting.identify``): which static parameters
are free and how the solver's vector maps onto them (``_Layout``), parameters held at a bound, the
linear solves of the start grid and the bounded solver that fails with FitError."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fricli.core import lazy
from fricli.core.errors import FitError

optimize = lazy.module("scipy.optimize")


_DELTAS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0)   # Stribeck exponents of the start grid


# the default a bounded static parameter is held at when the fit runs it to a bound (the log does not
# determine it): no viscous or load term, Fs = Fc (the excess Fs - Fc is 0), an exponential Stribeck decay
# (delta: held at the bound it reached, the steepest or flattest Stribeck drop the model has, or at 1
# where Fs = Fc and ks = kc leave it no effect; vs: no
# Stribeck effect, Fs = Fc; fc: held at its lower bound)
HELD = {"fv": 0.0, "kc": 0.0, "ks": 0.0, "fs": 0.0}
HELD_TEXT = {"fc": "Coulomb friction Fc", "fv": "viscous friction Fv", "kc": "load slope kc", "ks": "load slope ks",
             "fs": "Stribeck rise Fs - Fc", "delta": "Stribeck exponent delta",
             "vs": "Stribeck velocity vs (no breakaway the log's speeds show)"}


@dataclasses.dataclass
class _Layout:
    """Which static parameters are free, and how the parameter vector maps onto them."""

    stribeck: bool          # Fs, vs, delta identifiable (slow steady samples exist)
    load: bool              # kc, ks identifiable (tau_g present and varying)
    held: tuple = ()        # parameters held at their defaults (``HELD``): the log does not determine them
    vs_max: float = math.inf  # bounds of the Stribeck velocity from the speeds of the static-curve rows
    vs_min: float = 0.0
    fc_min: float = 0.0       # lower bound of the Coulomb level

    @property
    def names(self) -> list[str]:
        out = ["fc"]
        if self.stribeck:
            out += ["fs", "vs", "delta"]
        out.append("fv")
        if self.load:
            out.append("kc")
            if self.stribeck:
                out.append("ks")
        return [k for k in out if k not in self.held]

    _LOG = ("fc", "vs", "delta")

    def encode(self, p: dict) -> np.ndarray:
        """fs is carried as the excess fs - fc >= 0, so that Fs >= Fc >= 0 holds by construction."""
        q = dict(p, fs=max(p["fs"] - p["fc"], 0.0))
        return np.array([math.log(q[k]) if k in self._LOG else q[k] for k in self.names])

    def decode(self, x: np.ndarray, fixed: dict) -> dict:
        p = dict(fixed)
        for k, xi in zip(self.names, x):
            # a trial step of the solver can go far up or down in log-space: 1e304 gives residuals it
            # rejects (non-finite ones shrink its trust region), where exp(710) would raise, and 1e-304
            # keeps the parameter positive, where exp(-750) would be 0, which no LuGre model takes
            p[k] = math.exp(min(max(xi, -700.0), 700.0)) if k in self._LOG else float(xi)
        for k in self.held:
            if k in HELD:        # the others (delta, vs, fc) are held at their values in ``fixed``
                p[k] = HELD[k]   # fs: the excess Fs - Fc
        if self.stribeck:
            p["fs"] = p["fc"] + p["fs"]
        if not self.stribeck:
            p["fs"] = p["fc"]
            p["ks"] = p.get("kc", 0.0)
        if not self.load:
            p["kc"] = p["ks"] = 0.0
        return p

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = {"fc": math.log(self.fc_min) if self.fc_min > 0 else -np.inf, "delta": math.log(0.2), "vs": math.log(self.vs_min) if self.vs_min > 0 else -np.inf, "fs": 0.0, "fv": 0.0, "kc": 0.0, "ks": 0.0}
        hi = {"delta": math.log(5.0), "vs": math.log(self.vs_max)}
        return (np.array([lo.get(k, -np.inf) for k in self.names]),
                np.array([hi.get(k, np.inf) for k in self.names]))


def _powers(root: np.ndarray):
    """(delta, x^delta) for delta in _DELTAS from root = x^(1/4) (n,), by multiplication: one
    exp for the whole grid of exponents instead of one each."""
    p = {1: root}
    for k in (2, 3, 4, 5, 6, 8, 12):
        p[k] = p[k // 2] * p[k - k // 2] if k % 2 == 0 else p[k - 1] * root
    return [(delta, p[int(round(4 * delta))]) for delta in _DELTAS]


def _linear_fit(rows: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares coefficients (k,) for regressors stored as rows (k, n) and y (n,), and the
    sum of squared residuals. Normal equations on unit-norm rows (k is small); the sum from them
    too, y.y - 2 c.(rows y) + c.G.c, without forming the residuals (it ranks start points)."""
    gram = rows @ rows.T
    ry = rows @ y
    scale = np.sqrt(np.diag(gram)).copy()
    scale[scale == 0] = 1.0
    try:
        coef = np.linalg.solve(gram / np.outer(scale, scale), ry / scale)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(gram / np.outer(scale, scale), ry / scale, rcond=None)[0]
    coef = coef / scale
    sse = _sumsq(y) - 2.0 * float(coef @ ry) + float(coef @ gram @ coef)
    return coef, max(sse, 0.0)


_BOUND_TEXT = {"fc": {"lower": "Fc = 0.1 % of the median friction"}, "fs": {"lower": "Fs = Fc"}, "vs": {"upper": "vs = 1/6 of the top speed", "lower": "vs = 5 % of the slowest speed"}, "delta": {"lower": "delta = 0.2", "upper": "delta = 5"},
               "fv": {"lower": "Fv = 0"}, "kc": {"lower": "kc = 0"}, "ks": {"lower": "ks = 0"}}


def _at_bounds(names: list[str], res, lb=None, ub=None) -> dict[str, str]:
    """{name: "lower" or "upper"} of the bounded static parameters ``names`` that a fit ``res``
    (scipy's result) left at a bound, from its active_mask or, given the bounds (lb, ub), a value
    within 1e-6 (relative to the bound, absolute at 0) of one (the bristle parameters, listed
    after them, have notes of their own)."""
    out = {}
    for i, (name, a) in enumerate(zip(names, res.active_mask)):
        if name not in _BOUND_TEXT:
            continue
        if a:
            out[name] = "lower" if a < 0 else "upper"
        elif lb is not None:
            x = float(res.x[i])
            for bound, side in ((lb[i], "lower"), (ub[i], "upper")):
                if np.isfinite(bound) and abs(x - bound) <= 1e-6 * max(abs(bound), 1.0):
                    out[name] = side
    return out


def _hold(layout: _Layout, bound: dict) -> _Layout:
    """The layout with the parameters ``bound`` held (no Stribeck effect once Fs - Fc or vs is)."""
    return dataclasses.replace(layout, held=layout.held + tuple(k for k in bound if k not in layout.held),
                               stribeck=layout.stribeck and not {"fs", "vs"} & set(bound))


def _held_values(layout: _Layout, p: dict, bound: dict) -> dict:
    """Parameters ``p`` with those in ``bound`` set to the value they are held at."""
    q = dict(p)
    q.update({k: HELD[k] for k in bound if k in HELD and k != "fs"})
    if "delta" in bound:
        q["delta"] = 5.0 if bound["delta"] == "upper" else 0.2
    if "fc" in bound:
        q["fc"] = layout.fc_min
    if not layout.stribeck:   # no Stribeck effect: Fs = Fc, ks = kc
        q["fs"], q["ks"] = q["fc"], q["kc"]
    return q


def _coulomb_in_load(layout: _Layout, p: dict, load: float) -> dict[str, str]:
    """{"kc": "lower"(, "ks": "lower")} when the fit put the whole Coulomb level into the load slope
    (Fc under 1e-6 of Fc + kc |tau_g| at the typical load ``load`` [Nm]): the log does not separate
    the two, and the load slopes are held at 0; else {}."""
    if not layout.load or "kc" not in layout.names or not p["fc"] < 1e-6 * (p["fc"] + p["kc"] * load):
        return {}
    return {k: "lower" for k in ("kc", "ks") if k in layout.names}


def _typical(signals: dict, name: str, rows: np.ndarray) -> float:
    """Median |signals[name]| over ``rows``; 0 without the column."""
    col = signals.get(name)
    return float(np.median(np.abs(col[rows]))) if col is not None else 0.0


def _sumsq(r: np.ndarray) -> float:
    """Sum of squares of r (n,)."""
    # einsum, not r @ r: a threaded BLAS dot is erratic on a busy 2-core machine
    return float(np.einsum("i,i->", r, r))


def _bristles(x) -> tuple[float, float]:
    """(sigma0 [Nm/rad], sigma1 [Nm s/rad]) from x = (log sigma0, log tau1), tau1 = sigma1/sigma0 [s]."""
    s0 = math.exp(x[0])
    return s0, s0 * math.exp(x[1])


def _inside(x0: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """A start point strictly inside the bounds (least squares starts from an interior point)."""
    return np.clip(x0, lb + 1e-9, ub - 1e-9)


def _least_squares(fun, x0, bounds, max_nfev: int, what: str):
    """``scipy.optimize.least_squares`` (trf, x_scale='jac') of fun from x0 within bounds;
    failures become FitError. A fit stopped at ``max_nfev`` (status 0) returns its last iterate:
    trf accepts only steps that lower the cost, so that is the best one."""
    x0 = _inside(x0, *bounds)
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            res = optimize.least_squares(fun, x0, bounds=bounds, method="trf", x_scale="jac", max_nfev=max_nfev)
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise FitError(f"fitting the {what} failed: {exc}") from None
    if res.status < 0 or not np.isfinite(res.x).all():
        raise FitError(f"fitting the {what} failed: {res.message}")
    return res
