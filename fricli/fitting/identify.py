"""Identify the extended LuGre model from a log (``fricli identify``).

Two stages, both bounded nonlinear least-squares fits (``scipy.optimize.least_squares``, trust
region reflective, x_scale='jac'):

1. Static parameters (Fc, Fs, vs, delta, Fv, kc, ks) on the steady-state samples, where the
   friction is the static curve sign(v)*g(v, tau_g) + Fv*v. The start comes from the data: for a
   grid of (vs, delta) the curve is linear in (Fc, Fs, kc, ks, Fv), so each grid point is one
   linear least-squares solve; the best point in the physical order starts a bounded nonlinear
   fit (log-parameters for Fc, vs, delta; Fs - Fc, Fv, kc, ks >= 0). Parameters the data
   cannot determine are fixed and reported in ``notes_``: kc = ks = 0 when no load slope can show
   (``metrics.load_can_show``), Fs = Fc with fewer than
   ``MIN_STRIBECK_LEVELS`` steady speed levels.
2. Bristle parameters sigma0, sigma1 by simulating the bristle state over the whole log: a
   coarse grid, then a bounded fit in x = (log sigma0, log sigma1/sigma0) with the micro-damping
   time constant sigma1/sigma0 at most ``TAU1_MAX``. With ``refine`` all parameters are then
   fitted jointly on the whole log; a refinement that does not converge keeps its best iterate
   (or the two-stage estimate) with a note.

Steady-state samples (``steady_state_mask``, in ``fricli.fitting.steady``): the velocity has kept
its sign and stayed within ``rel_tol``*|v| (plus a small absolute tolerance from the velocity
noise) from a hold time before the sample to a quarter of it after; the hold is ``hold`` seconds or the time to travel ``travel``
at that speed, whichever is longer. This keeps samples away from reversals and accelerations,
where bristle dynamics and inertia errors would bias the static curve. Logs of continuous
excitation have few such holds; when the log has tau_dyn (the inertia is out of the target),
every row far enough past a velocity reversal samples the static curve (``settled_mask``).
The fit keeps Fs >= Fc > 0 and Fv >= 0 (Fs is carried as the excess Fs - Fc >= 0).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fricli.core import lazy, logs, metrics
from fricli.core.errors import DataError, FitError
from fricli.models.lugre import LuGreModel
from fricli.numerics.threads import single_threaded
# the parameter layout, held parameters and solver, importable from here as before
from fricli.fitting.lugre_parameters import (_BOUND_TEXT, _DELTAS, HELD, HELD_TEXT, _at_bounds, _bristles,  # noqa: F401
                                            _coulomb_in_load, _held_values, _hold, _inside, _Layout,
                                            _least_squares, _linear_fit, _powers, _sumsq, _typical)
# the static-curve rows, importable from here as before
from fricli.fitting.steady import (NOISE_FLOOR, _noise_tol, settled_mask, speed_levels,  # noqa: F401
                                   steady_state_mask, window_extreme)

optimize = lazy.module("scipy.optimize")


MIN_STEADY_PER_DIRECTION = 20
MIN_STRIBECK_LEVELS = 6
TAU1_MAX = 0.01           # upper bound on sigma1/sigma0 [s]
TAU1_MIN = 1e-7           # lower bound on sigma1/sigma0 [s], the micro-damping's default
DEFLECTION = (1e-8, 1.0)  # bounds of the bristle deflection g/sigma0 at the breakaway level g [rad or m]
_GRID_ROWS = 10_000       # rows that rank the start grid (more fall out of cache for no better start)
MINOR = 0.05              # plausibility: a friction term under this share of its reference counts as absent
TAIL = 2.0                # plausibility: a max error over TAIL * sqrt(2 ln n) * RMS is a local misfit
VS_MAX_SHARE = 0.5 / 3.0  # upper bound of the Stribeck velocity, share of the top speed: exp(-3) < MINOR at half of it
VS_WIDE_SHARE = 1.0 / 3.0  # the bound tried when the fit runs vs to the first: exp(-3) < MINOR at the top speed
_BRISTLE_NOTES = ("bristle deflection g/sigma0", "micro-damping time constant sigma1/sigma0")
FC_MIN_SHARE = 1e-3       # lower bound of Fc, share of the median |friction| on the static-curve rows


class LuGreIdentifier:
    """Fit an extended LuGre model to a log's friction target.

    hold [s], travel [rad or m], rel_tol [-]: the steady-state sample selection
    (``steady_state_mask``);
    samples: which rows sample the static curve: "steady" (constant-velocity holds), "settled"
    (every row at least ``settle`` [rad or m] of travel past the last reversal,
    ``settled_mask``: for continuous excitation) or "auto" ("settled" when the holds cover
    less than ``min_steady_share`` of the moving rows and the log has ``tau_dyn``, so that the
    target away from holds is friction only; else "steady");
    refine: after the two stages, fit all parameters jointly on the whole log;
    max_nfev: evaluations allowed per least-squares stage.

    Fitted attributes: ``model_`` (LuGreModel), ``steady_`` (bool mask of the rows used for the
    static curve), ``samples_`` ("steady" or "settled"),
    ``fit_`` (error figures and stage details), ``notes_`` (what could not be identified).
    """

    def __init__(self, *, hold: float = 0.2, travel: float = 0.002, rel_tol: float = 0.05,
                 refine: bool = False, max_nfev: int = 2000, samples: str = "auto",
                 settle: float = 0.01, min_steady_share: float = 0.5):
        self.hold = hold
        self.samples = samples
        self.settle = settle
        self.min_steady_share = min_steady_share
        self.travel = travel
        self.rel_tol = rel_tol
        self.refine = refine
        self.max_nfev = max_nfev

    # ------------------------------------------------------------------ checks

    def _require_motion(self, v: np.ndarray) -> np.ndarray:
        """The rows in motion (n,) bool; DataError unless the joint moves both ways."""
        if not float(np.max(np.abs(v))) > 0:
            raise DataError("the joint does not move (qd is zero everywhere)")
        moving = metrics.in_motion(v)
        if not (v[moving] < 0).any():
            raise DataError("no samples with negative velocity: identify needs motion in both directions")
        if not (v[moving] > 0).any():
            raise DataError("no samples with positive velocity: identify needs motion in both directions")
        return moving

    def _static_rows(self, sig: dict, units: dict, moving: np.ndarray) -> np.ndarray:
        """The rows that sample the static curve (n,) bool: constant-velocity holds or settled
        rows (``samples``); DataError when they cannot separate the friction terms."""
        v = sig["qd"]
        vu = units["qd"]
        if self.samples not in ("auto", "steady", "settled"):
            raise ValueError(f"samples must be 'auto', 'steady' or 'settled', not {self.samples!r}")
        steady = steady_state_mask(sig["t"], v, hold=self.hold, travel=self.travel, rel_tol=self.rel_tol)
        self.samples_ = self.samples
        if self.samples == "auto":
            share = steady.sum() / max(int(moving.sum()), 1)
            # away from holds the target is static friction only if the inertia has been removed
            continuous = share < self.min_steady_share and "tau_dyn" in sig and bool(np.any(sig["tau_dyn"]))
            self.samples_ = "settled" if continuous else "steady"
            if self.samples_ == "settled":
                self.notes_.append(f"constant-velocity holds cover {100 * share:.0f} % of the moving rows: the "
                                   f"static curve is fitted on every row {self.settle:g} {units.get('q', '')} past a reversal")
        if self.samples_ == "settled":
            if "q" in sig and float(np.ptp(sig["q"])) < self.settle:
                raise DataError(f"the joint's position spans less than --settle {self.settle:g} {units.get('q', '')} "
                                "over the whole log: it moves too little to sample the static curve (a joint held "
                                "still while others move?)")
            steady = settled_mask(sig["t"], v, settle=self.settle)
        held_both_ways = self._both_ways(steady, v)
        holds_fit = held_both_ways and self._several_speeds(steady, v)
        if self.samples == "auto" and self.samples_ == "steady" and not holds_fit:
            # no constant-velocity holds to speak of, or holds at one speed only: the continuous-motion
            # fit (settled rows for the static curve, then every parameter on the simulated model
            # output over the whole log)
            settled = settled_mask(sig["t"], v, settle=self.settle)
            if self._both_ways(settled, v) and (not held_both_ways or self._several_speeds(settled, v)):
                why = (f"no constant-velocity holds (fewer than {MIN_STEADY_PER_DIRECTION} steady-state rows in a "
                       "direction)" if not held_both_ways else
                       f"the constant-velocity holds are at one speed (about {np.median(np.abs(v[steady])):.3g} {vu})")
                self.samples_ = "settled"
                self.continuous_ = True
                steady = settled
                self.notes_.append(f"{why}: continuous-motion fit, the static curve on every row "
                                   f"{self.settle:g} {units.get('q', '')} past a reversal, then all parameters on "
                                   "the simulated model output over the whole log")
        for name, side in (("positive", v > 0), ("negative", v < 0)):
            count = int((steady & side).sum())
            if count < MIN_STEADY_PER_DIRECTION:
                raise DataError(
                    f"too few steady-state samples with {name} velocity ({count}, need at least "
                    f"{MIN_STEADY_PER_DIRECTION}): the log needs constant-velocity motion held for at "
                    f"least {self.hold:g} s (--hold) or motion past reversals")
        if not self._several_speeds(steady, v):
            speeds = np.abs(v[steady])
            raise DataError(f"the steady-state samples cover only one speed (about {np.median(speeds):.3g} {vu}): "
                            "several velocity levels are needed to separate Coulomb and viscous friction")
        return steady

    @staticmethod
    def _several_speeds(rows: np.ndarray, v: np.ndarray) -> bool:
        """Whether the speeds of ``rows`` span enough (95th percentile at least 1.5 times the 5th) to
        separate Coulomb and viscous friction."""
        lo, hi = np.percentile(np.abs(v[rows]), [5, 95])
        return bool(hi >= 1.5 * lo)

    @staticmethod
    def _both_ways(rows: np.ndarray, v: np.ndarray) -> bool:
        return all(int((rows & side).sum()) >= MIN_STEADY_PER_DIRECTION for side in (v > 0, v < 0))

    # ----------------------------------------------------------------- stage 1

    def _start(self, v: np.ndarray, y: np.ndarray, load: np.ndarray | None) -> tuple[dict, float, float]:
        """Grid over (vs, delta) with a linear solve per point. Returns (params, e_max, sse_gain)."""
        speed = np.abs(v)
        s = np.sign(v)
        ya = y * s                                    # friction magnitude along the motion
        step = max(1, len(v) // _GRID_ROWS)
        speed, ya = speed[::step], ya[::step]
        load = None if load is None else load[::step]
        logv = np.log(speed)
        base_cols = [np.ones_like(speed), speed] + ([load] if load is not None else [])
        coef0, sse0 = _linear_fit(np.array(base_cols), ya)
        best = None
        vlo, vhi = float(speed.min()), float(speed.max())
        rows = np.empty((3 if load is None else 5, len(speed)))
        rows[2] = speed
        for vs in np.geomspace(vlo / 3, vhi, 25):
            root = np.exp(0.25 * (logv - math.log(vs)))             # |v/vs|^(1/4)
            for delta, power in _powers(root):                      # |v/vs|^delta
                e = np.exp(np.negative(power, out=rows[1]), out=rows[1])   # E = exp(-|v/vs|^delta)
                np.subtract(1.0, e, out=rows[0])
                if load is not None:
                    np.multiply(load, rows[0], out=rows[3])
                    np.multiply(load, e, out=rows[4])
                coef, sse = _linear_fit(rows, ya)
                if coef[0] <= 0 or coef[1] < coef[0] or coef[2] < 0:   # physical order only
                    continue
                if best is None or sse < best[0]:
                    best = (sse, vs, delta, coef, float(e.max()))
        if best is None:
            fc = max(float(coef0[0]), 1e-3 * float(np.abs(ya).mean()) + 1e-12)
            p = {"fc": fc, "fs": fc, "vs": vlo, "delta": 1.0, "fv": max(float(coef0[1]), 0.0),
                 "kc": max(float(coef0[2]), 0.0) if load is not None else 0.0}
            p["ks"] = p["kc"]
            return p, 0.0, 0.0
        sse, vs, delta, coef, e_max = best
        p = {"fc": float(coef[0]), "fs": float(coef[1]), "vs": float(vs), "delta": float(delta),
             "fv": max(float(coef[2]), 0.0)}
        if load is not None:
            p["kc"], p["ks"] = max(float(coef[3]), 0.0), max(float(coef[4]), 0.0)
        else:
            p["kc"] = p["ks"] = 0.0
        gain = 1.0 - sse / sse0 if sse0 > 0 else 0.0
        return p, e_max, gain

    def fit_static(self, v: np.ndarray, y: np.ndarray, tau_g: np.ndarray | None = None,
                   qd_unit: str = "rad/s") -> dict:
        """The static stage alone: the LuGre model's steady-state curve (Stribeck, viscous, load)
        fitted by least squares to friction ``y`` (n,) at velocities ``v`` (n,) [qd_unit], with the
        gravity torque ``tau_g`` (n,) or None; its parameters. Fitted attribute: ``notes_``.
        Raises FitError when the fit fails."""
        self.notes_ = []
        return self._fit_static(v, y, tau_g, {"qd": qd_unit})[0]

    def _fit_static(self, v, y, tau_g, units) -> tuple[dict, dict]:
        load = None if tau_g is None else np.abs(tau_g)
        if load is not None and not metrics.load_can_show(load, y):
            spread, level = metrics.load_range(load, y)
            load, tau = None, units.get("tau", "")
            self.notes_.append(f"|tau_g| varies by only {spread:.3g} {tau} over the steady-state samples "
                               f"(5th to 95th percentile), under {100 * metrics.LOAD_SHARE:.0f} % of the friction there "
                               f"({level:.3g} {tau}): no load slope can show, kc = ks = 0")
        elif tau_g is None:
            self.notes_.append("no tau_g in the log: load slopes kc = ks = 0")
        start, e_max, gain = self._start(v, y, load)
        # Fs, vs, delta need several speed levels and a visible rise of the curve at the slow ones.
        levels = speed_levels(np.abs(v))
        stribeck = levels >= MIN_STRIBECK_LEVELS and e_max > 0.1 and gain > 1e-3
        if not stribeck:
            why = (f"only {levels} steady speed levels (need {MIN_STRIBECK_LEVELS})" if levels < MIN_STRIBECK_LEVELS
                   else f"no visible rise at the slowest steady speed ({np.abs(v).min():.3g} {units['qd']})")
            self.notes_.append(f"Stribeck effect not identifiable ({why}): Fs = Fc")
            start["fs"], start["ks"] = start["fc"], start["kc"]
            start["vs"], start["delta"] = float(np.abs(v).min()), 1.0
        # a Stribeck velocity near the fastest rows would make the curve a decay across all of them (with a
        # vanishing Coulomb level, a viscous slope traded against it): no breakaway the log shows. Bounds:
        # at half the top speed 95 % of the drop Fs - Fc is done (delta = 1; more with a larger delta),
        # and vs not far below the slowest row
        top = float(np.abs(v).max())
        vs_wide = VS_WIDE_SHARE * top
        layout = _Layout(stribeck=stribeck, load=load is not None, vs_max=VS_MAX_SHARE * top,
                         vs_min=MINOR * float(np.abs(v).min()))
        if stribeck:
            start["vs"] = min(max(start["vs"], 2 * layout.vs_min), 0.5 * layout.vs_max)
        fixed = {k: start[k] for k in ("fc", "fs", "vs", "delta", "fv", "kc", "ks")}
        fixed.update(sigma0=1.0, sigma1=0.0)
        tg = None if load is None else tau_g

        def residual(x):
            m = LuGreModel(**layout.decode(x, fixed))
            return m.steady_state(v, tg) - y

        nfev = 0
        level = float(np.median(np.abs(y)))
        layout = dataclasses.replace(layout, fc_min=FC_MIN_SHARE * level)
        start["fc"] = max(start["fc"], 2 * layout.fc_min)
        hit: dict[str, str] = {}   # every bound the fits reached
        for _ in range(len(HELD) + 1):
            res = _least_squares(residual, layout.encode(start), layout.bounds(), self.max_nfev, "static parameters")
            nfev += int(res.nfev)
            params = layout.decode(res.x, fixed)
            bound = _at_bounds(layout.names, res, *layout.bounds())
            bound.update(_coulomb_in_load(layout, params, _typical({"l": load}, "l", slice(None))))
            if layout.stribeck and math.exp(-(layout.vs_min / MINOR / params["vs"]) ** params["delta"]) < MINOR:
                bound["vs"] = "lower"   # the rise Fs - Fc is gone by the slowest row: no row shows Fs

            if bound.get("vs") == "upper" and layout.stribeck and vs_wide > layout.vs_max:
                # slow sweeps (a top speed of 3 to 6 Stribeck velocities): the drop is done by the top
                # speed, not by half of it. The wider bound is kept when no parameter reaches a bound
                # there; else (a decay across all the speeds, traded against Fc and Fv) as before
                wide = dataclasses.replace(layout, vs_max=vs_wide)
                layout, narrow = wide, layout
                res_w = _least_squares(residual, wide.encode(params), wide.bounds(), self.max_nfev, "static parameters")
                nfev += int(res_w.nfev)
                params_w = wide.decode(res_w.x, fixed)
                bound_w = _at_bounds(wide.names, res_w, *wide.bounds())
                bound_w.update(_coulomb_in_load(wide, params_w, _typical({"l": load}, "l", slice(None))))
                if bound_w or math.exp(-(wide.vs_min / MINOR / params_w["vs"]) ** params_w["delta"]) < MINOR:
                    layout = narrow
                else:
                    res, params, bound = res_w, params_w, {}
            hit.update(bound)
            if not bound:
                break
            if layout.stribeck and {"fs", "vs"} & set(bound):
                # Fc or Fv at a bound beside it may be traded against a decay across all the speeds:
                # the Stribeck effect is held alone first, and they are fitted again without it
                bound = {k: side for k, side in bound.items() if k in ("fs", "vs", "delta")}
            # a parameter the fit runs to its bound is not determined by the log: held at its default, refit
            layout = _hold(layout, bound)
            start = _held_values(layout, params, bound)
            fixed.update(start)
        idle = (("delta" in layout.held or not layout.stribeck) and params["fs"] == params["fc"]
                and params["ks"] == params["kc"])
        if idle:   # no Stribeck rise at any load: the exponent has no effect, shown at its neutral 1
            params["delta"] = 1.0
        self._note_held(layout.held, delta_idle=idle, params=params)
        return params, {"nfev": nfev, "cost": float(res.cost), "stribeck": stribeck,
                        "load": layout.load, "held": list(layout.held), "vs_max": layout.vs_max, "vs_min": layout.vs_min,
                        "fc_min": layout.fc_min, "at_bounds": hit,
                        "converged": bool(res.status != 0)}

    def _note_held(self, held, delta_idle: bool = False, params: dict | None = None, vu: str = "") -> None:
        """A note per parameter ``held``, saying the value it is held at in ``params`` (the model of
        the latest stage); a later stage's note replaces an earlier one of the same parameter (the
        joint refinement fits the rise Fs - Fc again beside a Stribeck velocity held at its bound)."""
        for k in held:
            if k in ("fs", "vs"):
                value = ("its default Fs = Fc" if params is None or k == "fs" or params["fs"] == params["fc"]
                         else f"the bound it reached, vs = {params['vs']:.3g}{' ' + vu if vu else ''}, with the rise "
                              "Fs - Fc fitted beside it on the whole log")
            else:
                value = ("its lower bound, 0.1 % of the median friction" if k == "fc"
                         else "its default delta = 1 (with Fs = Fc it has no effect)" if k == "delta" and delta_idle
                         else "its default the bound it reached (the steepest or flattest drop the model has)"
                         if k == "delta" else f"its default {k} = {HELD[k]:g}")
            note = (f"{HELD_TEXT[k]}: the log does not determine it (the fit ran it to a bound, or traded it against "
                    f"another term), held at {value}")
            same = [i for i, n in enumerate(self.notes_) if n.startswith(f"{HELD_TEXT[k]}:")]
            if same:
                self.notes_[same[0]] = note
            else:
                self.notes_.append(note)

    # ----------------------------------------------------------------- stage 2

    def _fit_dynamic(self, sig: dict, y: np.ndarray, static: dict) -> tuple[dict, dict]:
        """sigma0, sigma1 on the whole log, as x = (log sigma0, log tau1), tau1 = sigma1/sigma0 [s]."""
        # the bristles deflect most at breakaway, where the static curve is at Fs (Fc when the log shows
        # no Stribeck effect): that level scales the stiffness, so a vanishing Fc cannot shrink it
        g_typ = _breakaway(static, sig)
        if not g_typ > 0:
            raise FitError(f"the static fit gave no breakaway friction (Fs {g_typ:.3g}): the bristle stiffness "
                           "cannot be scaled; check the sign of tau_m (--kt, the mapping)")
        response = LuGreModel(**dict(static, sigma0=1.0, sigma1=0.0)).bristle_response(sig)

        def residual(x):
            return response(*_bristles(x)) - y

        grid = [(math.log(g_typ / zd), math.log(tau1)) for zd in np.geomspace(1e-7, 1e-1, 13)
                for tau1 in (1e-6, 1e-4, TAU1_MAX)]
        costs = [_sumsq(residual(x)) for x in grid]
        x0 = np.array(grid[int(np.nanargmin(costs))])
        # bristle deflection g/sigma0 within DEFLECTION, time constant sigma1/sigma0 within [TAU1_MIN, TAU1_MAX]
        lb = np.array([math.log(g_typ / DEFLECTION[1]), math.log(TAU1_MIN)])
        ub = np.array([math.log(g_typ / DEFLECTION[0]), math.log(TAU1_MAX)])
        res = _least_squares(residual, x0, (lb, ub), self.max_nfev, "bristle parameters")
        sigma0, sigma1 = _bristles(res.x)
        self._note_bristles(sigma0, sigma1, g_typ)
        return dict(static, sigma0=sigma0, sigma1=sigma1), {"nfev": int(res.nfev) + len(grid),
                                                                "cost": float(res.cost),
                                                                "converged": bool(res.status != 0)}

    def _note_bristles(self, sigma0: float, sigma1: float, g_typ: float) -> None:
        """Notes on the bristle parameters at a bound of the dynamic stage (deflection g/sigma0 within
        DEFLECTION of the breakaway level ``g_typ``, sigma1/sigma0 within [TAU1_MIN, TAU1_MAX]), replacing
        those of an earlier stage: the joint refinement moves them."""
        self.notes_ = [n for n in self.notes_ if not n.startswith(_BRISTLE_NOTES)]
        for what, x, bounds in zip(_BRISTLE_NOTES, (g_typ / sigma0, sigma1 / sigma0), (DEFLECTION, (TAU1_MIN, TAU1_MAX))):
            for bound, side in zip(bounds, ("lower", "upper")):
                if abs(math.log(x) - math.log(bound)) < 1e-3:
                    self.notes_.append(f"{what} at its {side} bound: the log does not determine it, held there "
                                       "(its default)")

    def _damping_determined(self, sig: dict, y: np.ndarray, params: dict) -> dict:
        """``params``, or with sigma1/sigma0 at its default TAU1_MIN when the log does not tell the
        fitted micro-damping from it: held there, the squared error over the log grows by less than
        one row's noise variance (its mean over the log after the fit), a change of chi-square
        under 1. A fitted value that no row distinguishes from its default is not reported as one."""
        tau1 = params["sigma1"] / params["sigma0"]
        if tau1 <= TAU1_MIN * (1.0 + 1e-3):
            return params
        held = dict(params, sigma1=TAU1_MIN * params["sigma0"])
        sse = _sumsq(LuGreModel(**params).predict(sig)[0] - y)
        sse_held = _sumsq(LuGreModel(**held).predict(sig)[0] - y)
        if not sse_held - sse < sse / max(len(y) - 9, 1):
            return params
        self.notes_ = [n for n in self.notes_ if not n.startswith(_BRISTLE_NOTES[1])]
        self.notes_.append(f"{_BRISTLE_NOTES[1]}: the log does not determine it (the fitted {tau1:.3g} s and the "
                           f"default {TAU1_MIN:g} s differ in squared error by less than one row's noise variance), "
                           "held at its default")
        return held

    def _fit_joint(self, sig: dict, y: np.ndarray, params: dict, layout: _Layout, vu: str = "") -> tuple[dict, dict]:
        nfev, start_cost, p, res, hit = 0, None, dict(params), None, {}
        for _ in range(len(HELD) + 1):
            fixed = dict(p)
            n_static = len(layout.names)

            def decode(x, layout=layout, fixed=fixed, n_static=n_static):
                q = layout.decode(x[:n_static], fixed)
                q["sigma0"], q["sigma1"] = _bristles(x[n_static:])
                return q

            def residual(x, decode=decode):
                return LuGreModel(**decode(x)).predict(sig)[0] - y

            lb, ub = layout.bounds()
            s0 = math.log(p["sigma0"])
            tau1 = math.log(max(p["sigma1"] / p["sigma0"], TAU1_MIN))
            x0 = np.concatenate([layout.encode(p), [s0, tau1]])
            lb = np.concatenate([lb, [s0 - 5, math.log(TAU1_MIN)]])
            ub = np.concatenate([ub, [s0 + 5, math.log(TAU1_MAX)]])
            if start_cost is None:
                start_cost = 0.5 * _sumsq(residual(_inside(x0, lb, ub)))
            try:
                res = _least_squares(residual, x0, (lb, ub), self.max_nfev, "joint refinement")
            except FitError as exc:
                self.notes_.append(f"{exc}: kept the two-stage estimate")
                return params, {"nfev": self.max_nfev, "cost": start_cost, "kept": "two-stage"}
            nfev += int(res.nfev)
            p = decode(res.x)
            bound = _at_bounds(layout.names, res, lb, ub)
            bound.update(_coulomb_in_load(layout, p, _typical(sig, "tau_g", slice(None))))
            hit.update(bound)
            if not bound:
                break
            # a parameter run to its bound: held at its default, the others fitted again
            layout = _hold(layout, bound)
            p = _held_values(layout, p, bound)
        if res.status == 0:
            self.notes_.append(f"joint refinement stopped at {self.max_nfev} evaluations: kept its best iterate")
        if not res.cost < start_cost:
            self.notes_.append("joint refinement did not lower the error: kept the two-stage estimate")
            return params, {"nfev": nfev, "cost": start_cost, "kept": "two-stage"}
        self._note_held(layout.held, params=p, vu=vu)
        self._note_bristles(p["sigma0"], p["sigma1"], _breakaway(p, sig))
        return p, {"nfev": nfev, "cost": float(res.cost), "held": list(layout.held), "at_bounds": hit}

    # ----------------------------------------------------------- plausibility

    def _plausibility(self, signals: dict, steady: np.ndarray, model: LuGreModel, fit: dict,
                      units: dict) -> list[str]:
        """Warnings (str) about a fit that converged but looks implausible, each with what to try.
        ``steady``: the static-curve rows (n,) bool; ``fit``: the error figures and stages of ``_fit``."""
        out = []
        p, tau, vu = model.parameters(), units.get("tau", ""), units["qd"]
        stages = fit["stages"]
        joint = stages.get("joint", {})
        bounds = joint["at_bounds"] if "at_bounds" in joint else stages["static"]["at_bounds"]
        # on the static-curve rows: at reversals the jump of the friction sign leaves errors of 2 Fc in any fit
        curve = fit["steady"]
        tail = TAIL * math.sqrt(2 * math.log(max(curve["n"], 2))) * curve["rmse"]
        if bounds and curve["max"] > tail:
            shown = {k: v for k, v in bounds.items() if not (k == "delta" and "fs" in bounds)}  # no effect then
            which = " and ".join(_BOUND_TEXT[name][side] for name, side in shown.items())
            out.append(f"{which} (at the bound of the fit, held there) with a max error of {curve['max']:.3g} {tau} on the "
                       f"static-curve rows, {curve['max'] / curve['rmse']:.0f} times their RMS error: the static curve cannot follow some "
                       "rows. Look at where the error is largest (fricli diagnose); try --samples steady or "
                       "settled, --drop-invalid for bad rows, or a model kind with the missing effect")
        along, offset = _along_the_motion(signals["qd"][steady], logs.friction_target(signals)[steady], tau)
        if along is not None:
            out.append(along)
        speed = np.abs(signals["qd"][steady])
        load = _typical(signals, "tau_g", steady)                     # typical |tau_g| [Nm]
        fc, fs = p["fc"] + p["kc"] * load, p["fs"] + p["ks"] * load   # the levels at that load
        top = float(speed.max())
        left = math.exp(-(0.5 * top / p["vs"]) ** p["delta"])       # share of Fs - Fc still to come at top/2
        spans = stages["static"]["stribeck"] and fs - fc > MINOR * fs and left > MINOR
        if spans:
            out.append(f"the Stribeck velocity vs = {p['vs']:.3g} {vu} spans the speeds of the log (top steady "
                       f"speed {top:.3g} {vu}): at half that speed {100 * left:.0f} % of the Stribeck drop Fs - Fc "
                       "is still to come, so the curve shapes the velocity dependence instead of the breakaway "
                       "at low speed. Log constant-velocity levels well below vs, or try a neural model with a "
                       "free velocity law (fricli train-base)")
        slowest = float(speed.min())
        if stages["static"]["stribeck"] and fs - fc > MINOR * fs and p["vs"] < MINOR * slowest:
            out.append(f"the Stribeck velocity vs = {p['vs']:.3g} {vu} lies far below the slowest speed of the "
                       f"static-curve rows ({slowest:.3g} {vu}): no row determines the breakaway Fs = {fs:.3g} {tau}, "
                       "which the model nonetheless applies near rest. Log slow constant-velocity motion, or look "
                       "for what else changes the friction along the log (fricli diagnose: drift, ripple)")
        slow = float(np.percentile(speed, 5))
        scale = max(fs, float(model.steady_state(np.array([slow]), np.array([load]))[0]))
        if fc < MINOR * scale:
            level = (f"Fc + kc |tau_g| at the median |tau_g| ({load:.3g} {tau})" if stages["static"]["load"]
                     else "Fc")
            what = (f"the Coulomb level vanishes: {level} = {fc:.3g} {tau} is {100 * fc / scale:.1f} % of "
                    f"{'Fs' if scale == fs else 'the friction at the slowest steady speeds'} ({scale:.3g} {tau})")
            if spans:   # the friction is there; the curve has not decayed to Fc within the log's speeds
                out.append(f"{what}: with vs spanning the log's speeds, Fc is the friction beyond its fastest rows, "
                           "which the log does not determine; do not use the model beyond them")
            elif offset:
                out.append(f"{what}: the offset above hides it (in the direction it cancels, little friction is left "
                           "to fit; fricli diagnose --fix)")
            else:
                out.append(f"{what}. Check the sign and scale of tau_m (--kt) and that tau_g and tau_dyn are not "
                           "counted twice; log slow constant-velocity motion in both directions")
        steep = [k for k in ("kc", "ks") if abs(p[k]) > 1.0]
        if steep:
            which = " and ".join(f"{k} = {p[k]:.3g} {tau}/{tau}" for k in steep)
            out.append(f"load slope {which}: above 1, the friction would grow faster than the gravity load on "
                       "the gear, which no gear does; the shape more likely comes from tau_g (a gravity or payload "
                       "error of the robot model: fricli calibrate, fricli diagnose) than from friction")
        return out

    # --------------------------------------------------------------------- fit

    def fit(self, signals: dict[str, np.ndarray], units: dict | None = None, axis: str = "rotary") -> "LuGreIdentifier":
        """Fit on a log's signals (canonical units, see ``fricli.core.logs``).

        The BLAS libraries (numpy's and scipy's) run on one thread meanwhile: threaded
        reductions (over the log's rows) round differently for each thread count, and the fit
        would not give the same bytes under OMP_NUM_THREADS=1 and 2. It costs nothing
        measurable here. scipy is imported first: its own BLAS must be loaded to be pinned."""
        optimize.least_squares  # noqa: B018  (the import)
        with single_threaded():
            return self._fit(signals, units, axis)

    def _fit(self, signals: dict[str, np.ndarray], units: dict | None, axis: str) -> "LuGreIdentifier":
        units = units or logs.CANONICAL[axis]
        self.notes_: list[str] = []
        self.continuous_ = False
        sig = {k: signals[k] for k in ("t", "qd", "tau_g") if k in signals}
        y = logs.friction_target(signals)
        steady = self._static_rows(signals, units, self._require_motion(signals["qd"]))
        v = signals["qd"]
        tau_g = sig.get("tau_g")
        static, info1 = self._fit_static(v[steady], y[steady], None if tau_g is None else tau_g[steady], units)
        params, info2 = self._fit_dynamic(sig, y, static)
        stages = {"static": info1, "dynamic": info2}
        if self.refine or self.continuous_:
            layout = _Layout(stribeck=info1["stribeck"], load=info1["load"], held=tuple(info1["held"]),
                             vs_max=info1["vs_max"], vs_min=info1["vs_min"], fc_min=info1["fc_min"])
            params, stages["joint"] = self._fit_joint(sig, y, params, layout, units["qd"])
        params = self._damping_determined(sig, y, params)
        try:
            model = LuGreModel(**params, axis=axis)
        except ValueError as exc:
            raise FitError(f"identification gave unusable parameters ({exc})") from None
        pred = model.predict(sig)[0]
        if not np.isfinite(pred).all():
            raise FitError("identification gave a model with non-finite predictions")
        self.model_ = model
        self.steady_ = steady
        fit = metrics.errors(y, pred)
        fit["steady"] = metrics.errors(y[steady], pred[steady])
        fit["steady_rows"] = int(steady.sum())
        fit["stages"] = stages
        fit["notes"] = list(self.notes_)
        self.warnings_ = self._plausibility(signals, steady, model, fit, units)
        stopped = [name for name, info in (("static", info1), ("bristle", info2)) if not info["converged"]]
        if stopped:
            self.warnings_.insert(0, f"the {' and '.join(stopped)} fit stopped at {self.max_nfev} evaluations "
                                     "before it converged: the model holds its best iterate. Look at the fit (fricli "
                                     "evaluate, fricli diagnose); a log with constant-velocity holds determines the "
                                     "static curve better")
        fit["warnings"] = list(self.warnings_)
        self.fit_ = fit
        return self


def _breakaway(params: dict, sig: dict) -> float:
    """The breakaway friction Fs + ks |tau_g| at the log's median |tau_g| [Nm]: the level the bristle
    deflection is measured against."""
    return params["fs"] + params["ks"] * float(np.median(np.abs(logs.column(sig, "tau_g"))))


def _along_the_motion(v: np.ndarray, y: np.ndarray, tau: str = "Nm") -> tuple[str | None, bool]:
    """(warning, offset): the warning when the friction target ``y`` (n,) of the static-curve rows,
    averaged over the rows of one direction of motion (velocities ``v`` (n,)), pushes along the
    motion (None when both means oppose it). No friction does that on average: in one direction
    the target carries an offset (half the sum of the two directions' means; ``offset`` True) that a
    model odd in the velocity cannot hold; in both, tau_m's sign is wrong."""
    up, down = float(np.mean(y[v > 0])), float(np.mean(y[v < 0]))
    if up >= 0 >= down:
        return None, False
    if up < 0 < down:
        return (f"in both directions of motion the friction target averages along the motion ({up:+.3g} {tau} moving "
                f"forward, {down:+.3g} {tau} backward): no friction does that. Check the sign of tau_m (--kt, the "
                "mapping) and that tau_g and tau_dyn are not counted twice"), False
    which, mean = ("forward", up) if up < 0 else ("backward", down)
    return (f"moving {which} the friction target averages {mean:+.3g} {tau} on the static-curve rows, along the "
            f"motion in one direction: no friction does that. The target carries an offset of about "
            f"{0.5 * (up + down):+.3g} {tau} (half the sum of the two directions' means: a bias of the torque "
            "measurement or of the robot model's tau_g), which this model, odd in the velocity, cannot hold: it "
            "stays in the error, and where the two directions move at different speeds the fit trades friction "
            "terms against it. 'fricli diagnose MODEL LOG --fix' adds it as a robot-model error; "
            "'fricli identify --kind gms' fits one beside the friction"), True


def identify(log: logs.Log, **kwargs) -> LuGreIdentifier:
    """Fit an extended LuGre model to ``log``; keyword arguments as ``LuGreIdentifier``."""
    return LuGreIdentifier(**kwargs).fit(log.signals, units=log.units, axis=log.axis)
