"""The library of candidate effects a friction model may be missing.

Each effect is a small group of physically motivated regressor terms (``fricli.models.terms``)
built from the log's signals and the base model's prediction p [Nm], and a rule turning the
fitted coefficients into named physical parameters with units. Terms are shared by name: the
level terms ``p`` (the model scaled as a whole) and ``qd`` (a viscous change) are part of the
effects that describe how the level changes (with direction, temperature, time, velocity or
another column), so those effects nest ``level`` and must beat it on held-out data.

Parameters are reported as ``{name: {"value": float, "unit": str}}``. Coulomb and viscous
levels of a model that is not a plain Coulomb + viscous law are its *equivalent* levels: the
least-squares fit of tau = Fc*sign(qd) + Fv*qd to its prediction on the log's moving samples,
per direction where it matters.

An effect is tested only when the log can identify it (``applicable``): a coefficient that is a
torque ratio [Nm/Nm] (gravity, load, payload, quadrant) is physical up to 1 in magnitude, so
such an effect is tested only when its column, at that coefficient, could remove ``min_gain``
of the residual's mean square; otherwise the log cannot tell it from noise and any coefficient
fitted to it is meaningless. A fitted parameter out of its plausible range (``implausible``)
makes the effect a suspicion, reported but not added (docs/diagnose.md).
"""

from __future__ import annotations

import numpy as np

from fricli.core import effectnames as N
from fricli.core.logs import KNOWN
from fricli.models import terms as T
# the context and base class, and the robot-model effects, importable from here as before
from fricli.fitting.diagnosis.context import (LEVEL_TERMS, Context, Effect, _fmt, _level_coefs, _par,  # noqa: F401
                                              equivalent_levels, presliding_travel)
from fricli.fitting.diagnosis.torque_effects import (RATIO_BOUND, ROBOT_MODEL_TOLERANCE, Acceleration,  # noqa: F401
                                                     Gravity, Load, Payload, Quadrant, _constant, _needs_tau_g,
                                                     _ratio_implausible, _ratio_reach, _ratio_text, load_travel)


class Offset(Effect):
    name = N.OFFSET
    description = "a constant (a bias in the torque measurement)"
    part = "model"

    def terms(self, ctx, residual):
        return [T.term("1", T.ONE)]

    def params(self, coef, ctx):
        return {"offset": _par(coef["1"], ctx.tau_unit)}


class Level(Effect):
    name = N.LEVEL
    description = "the model's Coulomb and viscous level changed as a whole"

    def terms(self, ctx, residual):
        return list(LEVEL_TERMS)

    def params(self, coef, ctx):
        bp, bv = _level_coefs(coef)
        lv = equivalent_levels(ctx.p, ctx.signals["qd"])
        return {"scale": _par(1.0 + bp, ""), "Fc": _par((1.0 + bp) * lv["Fc"], ctx.tau_unit),
                "Fv": _par((1.0 + bp) * lv["Fv"] + bv, ctx.fv_unit)}

    def summary(self, params):
        return (f"Fc {_fmt(params['Fc']['value'])} {params['Fc']['unit']}, Fv {_fmt(params['Fv']['value'])} "
                f"{params['Fv']['unit']} (model x{_fmt(params['scale']['value'])})")


class Direction(Effect):
    name = N.DIRECTION
    rivals = ((N.LEVEL, N.OFFSET),)
    description = "separate Coulomb and viscous levels for positive and negative velocity"

    def applicable(self, ctx):
        qd = ctx.signals["qd"]
        moving = ctx.moving()
        if (moving & (qd > 0)).sum() < 10 or (moving & (qd < 0)).sum() < 10:
            return "needs motion in both directions"
        return None

    def terms(self, ctx, residual):
        d = load_travel(ctx)
        if d:   # p [dir > 0] = (p + p z/d) / 2 with the element z turning over the pre-sliding travel
            return LEVEL_TERMS + [T.term("p*slip", T.P, T.slip_(d)), T.term("qd*pos", T.sig_("qd"), T.POS)]
        return LEVEL_TERMS + [T.term("p*pos", T.P, T.POS), T.term("qd*pos", T.sig_("qd"), T.POS)]

    def params(self, coef, ctx):
        sig = ctx.signals
        y = ctx.p + T.matrix(self.terms(ctx, None), sig, ctx.p) @ np.array(
            [coef.get(t["name"], 0.0) for t in self.terms(ctx, None)])
        lv = equivalent_levels(y, sig["qd"])
        return {"Fc+": _par(lv["Fc+"], ctx.tau_unit), "Fc-": _par(lv["Fc-"], ctx.tau_unit),
                "Fv+": _par(lv["Fv+"], ctx.fv_unit), "Fv-": _par(lv["Fv-"], ctx.fv_unit)}


class _ScaledBy(Effect):
    """Level terms plus the level terms multiplied by a slowly varying signal's deviation."""

    signal = ""
    rivals = ((N.LEVEL,),)
    per = 1.0          # report slopes per this many units of the signal

    def center(self, ctx) -> float:
        return float(np.mean(ctx.signals[self.signal]))

    def factor(self, ctx) -> dict:
        return T.dev(self.signal, self.center(ctx))

    def terms(self, ctx, residual):
        f = self.factor(ctx)
        return LEVEL_TERMS + [T.term(f"p*d{self.signal}", T.P, f), T.term(f"qd*d{self.signal}", T.sig_("qd"), f)]

    def slopes(self, coef, ctx) -> dict:
        bp, bv = _level_coefs(coef)
        bps, bvs = coef.get(f"p*d{self.signal}", 0.0), coef.get(f"qd*d{self.signal}", 0.0)
        lv = equivalent_levels(ctx.p, ctx.signals["qd"])
        fc0, fv0 = (1 + bp) * lv["Fc"], (1 + bp) * lv["Fv"] + bv
        dfc, dfv = bps * lv["Fc"] * self.per, (bps * lv["Fv"] + bvs) * self.per
        return {"fc0": fc0, "fv0": fv0, "dfc": dfc, "dfv": dfv}


class Temperature(_ScaledBy):
    name = N.TEMPERATURE
    signal = "temp"
    description = "Coulomb and viscous levels scaled by the temperature deviation"

    def applicable(self, ctx):
        if "temp" not in ctx.signals:
            return "the log has no 'temp' column"
        if np.ptp(ctx.signals["temp"]) < 1.0:
            return "the temperature varies by less than 1 K"
        return None

    def params(self, coef, ctx):
        s = self.slopes(coef, ctx)
        tc = self.center(ctx)
        u = ctx.tau_unit
        return {"t_ref": _par(tc, "degC"), "Fc": _par(s["fc0"], u), "Fv": _par(s["fv0"], ctx.fv_unit),
                "dFc/dT": _par(s["dfc"], f"{u}/K"), "dFv/dT": _par(s["dfv"], f"{ctx.fv_unit}/K"),
                "alpha_c": _par(-s["dfc"] / s["fc0"] if s["fc0"] else float("nan"), "1/K"),
                "alpha_v": _par(-s["dfv"] / s["fv0"] if s["fv0"] else float("nan"), "1/K")}


class Drift(_ScaledBy):
    name = N.DRIFT
    signal = "t"
    per = 3600.0
    description = "Coulomb and viscous levels growing with time (wear)"

    def factor(self, ctx) -> dict:
        # held at the log's ends: a trend fitted over minutes says nothing of an hour later
        t = ctx.signals["t"]
        return T.dev("t", self.center(ctx), float(np.min(t)), float(np.max(t)))

    def applicable(self, ctx):
        if np.ptp(ctx.signals["t"]) <= 0:
            return "the log covers no time"
        return None

    def params(self, coef, ctx):
        s = self.slopes(coef, ctx)
        u = ctx.tau_unit
        rel = s["dfc"] / s["fc0"] if s["fc0"] else float("nan")
        return {"Fc": _par(s["fc0"], u), "Fv": _par(s["fv0"], ctx.fv_unit),
                "dFc/dt": _par(s["dfc"], f"{u}/h"), "dFv/dt": _par(s["dfv"], f"{ctx.fv_unit}/h"),
                "rate": _par(100.0 * rel, "%/h")}


class Velocity(Effect):
    name = N.VELOCITY
    rivals = ((N.LEVEL,),)
    description = "a smooth correction in qd (a wrong curve shape)"
    fractions = (0.05, 0.2, 0.6)

    def applicable(self, ctx):
        if ctx.v_scale() <= 0:
            return "the joint does not move"
        return None

    def terms(self, ctx, residual):
        vs = ctx.v_scale()
        return LEVEL_TERMS + [T.term(f"sat{i + 1}", {"f": "sat", "scale": vs * f})
                              for i, f in enumerate(self.fractions)]

    def params(self, coef, ctx):
        vs = ctx.v_scale()
        lv = equivalent_levels(ctx.p, ctx.signals["qd"])
        out = {"v_ref": _par(vs, ctx.v_unit)}
        for frac in (0.1, 0.5, 1.0):
            v = frac * vs
            d = coef.get("p", 0.0) * (lv["Fc"] + lv["Fv"] * v) + coef.get("qd", 0.0) * v
            d += sum(coef.get(f"sat{i + 1}", 0.0) * -np.expm1(-v / (vs * f)) for i, f in enumerate(self.fractions))
            out[f"dF_{round(100 * frac)}"] = _par(d, ctx.tau_unit)
        return out


class Position(Effect):
    """Periodic in q (gear ripple): at each of the strongest spatial frequencies w of the residual,
    sin(w q) and cos(w q) and the same times the direction of motion. A harmonic drive's torque
    ripple is fixed to the position of its wave generator and motor; the part of it that is
    friction changes sign with the motion, so each direction of motion has its own phase. The
    frequencies are found one after the other by a periodogram over q (q is unevenly spaced) of
    each direction's rows, each removed before the next is sought: not always harmonics of the
    strongest one (twice the wave generator's turn and its multiples, the motor's cogging)."""

    name = N.POSITION
    description = "periodic in q (gear ripple)"
    peaks = 3
    max_bins = 1 << 20
    oversample = 4

    def applicable(self, ctx):
        q = ctx.signals.get("q")
        if q is None or _constant(q):
            return "the log has no position range"
        step = self.step(ctx)
        need = 2 * 2 * 3 * step      # two periods of a ripple six samples long
        if np.ptp(q) < need:
            return (f"the position range {np.ptp(q):.2g} {ctx.q_unit} is under two periods of the shortest ripple "
                    f"its sampling resolves ({need:.2g} {ctx.q_unit})")
        return None

    def step(self, ctx) -> float:
        """The median position step between rows in motion [rad or m] (0 when none moves)."""
        q = ctx.signals["q"]
        dq = np.abs(np.diff(q))[ctx.moving()[1:]]
        dq = dq[dq > 0]
        return float(np.median(dq)) if len(dq) else 0.0

    def frequencies(self, ctx, residual) -> list[float]:
        """The ``peaks`` strongest spatial angular frequencies w [rad per q unit], strongest first:
        the largest peaks of the periodogram power summed over the two directions of motion, each
        with two periods or more in the range of q and two resolution widths (2 pi / range) or more
        from a stronger one.

        Each direction's residual is averaged in bins of q about half a typical sample step wide;
        an FFT of the binned series (empty bins zero) locates the peaks, and a Lomb-Scargle
        periodogram of the non-empty bins (unevenly spaced) refines each around its FFT bin.
        """
        q = ctx.signals["q"]
        step = self.step(ctx)
        span = float(np.ptp(q))
        h = max(step / 2 if step > 0 else span / 1000, span / self.max_bins)
        nb = int(span / h) + 1
        nfft = 1 << int(np.ceil(np.log2(nb * self.oversample)))
        direction = T.held_sign(ctx.signals["qd"])
        series = []
        for rows in (direction > 0, direction < 0):
            if rows.sum() < 2:
                continue
            idx = np.minimum(((q[rows] - q.min()) / h).astype(np.int64), nb - 1)
            count = np.bincount(idx, minlength=nb)
            total = np.bincount(idx, weights=residual[rows] - residual[rows].mean(), minlength=nb)
            full = count > 0
            mean = np.zeros(nb)
            mean[full] = total[full] / count[full]
            mean[full] -= mean[full].mean()
            series.append((q.min() + (np.flatnonzero(full) + 0.5) * h, mean[full], mean))
        w = 2 * np.pi * np.fft.rfftfreq(nfft, h)
        power = sum((np.abs(np.fft.rfft(mean, nfft)) ** 2 for *_, mean in series), np.zeros(len(w)))
        keep = w >= 2 * 2 * np.pi / span            # at least two periods in the range
        dw = w[1] - w[0]
        from scipy import signal  # imported here: it costs a noticeable part of start-up

        found: list[float] = []
        while len(found) < self.peaks and keep.any():
            k = int(np.flatnonzero(keep)[np.argmax(power[keep])])
            grid = np.linspace(max(w[k] - dw, w[keep][0]), w[k] + dw, 41)
            fine = sum(signal.lombscargle(centers, values, grid) for centers, values, _ in series)
            found.append(float(grid[int(np.argmax(fine))]))
            keep &= np.abs(w - found[-1]) >= 2 * 2 * np.pi / span
        return found or [float(2 * 2 * np.pi / span)]

    def terms(self, ctx, residual):
        out = []
        for w in self.frequencies(ctx, residual):
            for f in ("sin", "cos"):
                wave = {"f": f, "name": "q", "w": w}
                out.append(T.term(f"{f}@{w:.6g}", wave))
                out.append(T.term(f"sign*{f}@{w:.6g}", T.SIGN, wave))
        return out

    def params(self, coef, ctx):
        def amplitude(w, prefix=""):
            return float(np.hypot(coef.get(f"{prefix}sin@{w:.6g}", 0.0), coef.get(f"{prefix}cos@{w:.6g}", 0.0)))

        ws = {float(name.rsplit("@", 1)[1]) for name in coef}
        out = {}
        for i, w in enumerate(sorted(ws, key=lambda w: -np.hypot(amplitude(w), amplitude(w, "sign*"))), 1):
            out[f"period{i}"] = _par(2 * np.pi / w, ctx.q_unit)
            out[f"amplitude{i}"] = _par(amplitude(w), ctx.tau_unit)
            out[f"friction{i}"] = _par(amplitude(w, "sign*"), ctx.tau_unit)
        return out


class Hysteresis(Effect):
    """Friction with memory: Maxwell-slip elements (``T.slip_``), each a spring that deflects with the
    position and slips at its limit d, with the level terms (the elements take over part of the
    model's Coulomb level, so the effect nests ``level``). Its force follows the position since the
    last reversal rather than the velocity, as a smooth sign of motion would; a model without memory
    misses it at every reversal. It must beat ``level`` and ``velocity`` (a smooth sign of motion
    after each reversal) on held-out data.

    The limits are ``elements`` values log-spaced from ``low_steps`` times the log's median
    position step in motion (an element that slips within fewer steps is the sign of motion, which
    the level has) up to ``high_share`` of the position range (wider elements never slip in the
    log's reversals); both are the log's own, so a coarser or shorter log gets its own grid. Each
    element's coefficient is its break-away force. One element may come out slightly negative
    where its neighbours or the model's own Coulomb level carry the force; what is not physical
    is friction that gives energy back over a slow closed cycle of the position: the elements
    with the model's equivalent Coulomb level Fc, as rescaled (an element of limit 0), must dissipate
    ``loop_energy`` >= 0 at every amplitude, else the effect is ``implausible``."""

    name = N.HYSTERESIS
    rivals = ((N.LEVEL,), (N.VELOCITY,))
    description = "friction with memory: Maxwell-slip elements on the position since the last reversal"
    elements = 4
    low_steps = 2.0
    high_share = 0.05
    min_reversals = 4

    def limits(self, ctx) -> np.ndarray:
        """The elements' deflection limits (elements,) [rad or m], smallest first (empty: none fit)."""
        lo = self.low_steps * Position().step(ctx)
        hi = self.high_share * float(np.ptp(ctx.signals["q"]))
        if lo <= 0 or hi <= 2 * lo:
            return np.zeros(0)
        return np.geomspace(lo, hi, self.elements)

    def applicable(self, ctx):
        q = ctx.signals.get("q")
        if q is None or _constant(q):
            return "the log has no position range"
        if not len(self.limits(ctx)):
            return (f"the position range is under {2 * self.low_steps / self.high_share:g} position steps: no element "
                    "both deflects and slips")
        direction = T.held_sign(ctx.signals["qd"])
        reversals = int(np.count_nonzero(direction[1:] * direction[:-1] < 0))
        if reversals < self.min_reversals:
            return f"the joint reverses {reversals} times (fewer than {self.min_reversals})"
        return None

    def terms(self, ctx, residual):
        return LEVEL_TERMS + [T.term(f"slip@{d:.6g}", T.slip_(float(f"{d:.6g}"))) for d in self.limits(ctx)]

    def params(self, coef, ctx):
        out = {}
        forces = {float(k.split("@", 1)[1]): v for k, v in coef.items() if k.startswith("slip@")}
        for i, d in enumerate(sorted(forces), 1):
            out[f"d{i}"] = _par(d, ctx.q_unit)
            out[f"F{i}"] = _par(forces[d], ctx.tau_unit)
        out["F"] = _par(sum(forces.values()), ctx.tau_unit)
        bp, bv = _level_coefs(coef)
        lv = equivalent_levels(ctx.p, ctx.signals["qd"])
        out["Fc model"] = _par((1.0 + bp) * lv["Fc"] if np.isfinite(lv["Fc"]) else 0.0, ctx.tau_unit)
        out["Fv model"] = _par((1.0 + bp) * lv["Fv"] + bv if np.isfinite(lv["Fv"]) else bv, ctx.fv_unit)
        return out

    @staticmethod
    def loop_energy(d: np.ndarray, force: np.ndarray, amplitude: np.ndarray) -> np.ndarray:
        """Energy (len(amplitude),) [Nm rad or N m] the elements of limits d (k,) and break-away
        forces force (k,) dissipate over one symmetric cycle of each amplitude: an element slips
        2 (A - d) each way once A > d, so sum_i 4 F_i max(A - d_i, 0)."""
        return 4.0 * np.maximum(amplitude[:, None] - d[None, :], 0.0) @ force

    def implausible(self, params, ctx):
        n = sum(1 for k in params if k.startswith("d"))
        # the model's Coulomb level is one more element, of limit 0: the sum must not give energy back
        d = np.array([0.0] + [params[f"d{i}"]["value"] for i in range(1, n + 1)], dtype=np.float64)
        force = np.array([params["Fc model"]["value"] or 0.0] + [params[f"F{i}"]["value"] or 0.0
                                                                 for i in range(1, n + 1)], dtype=np.float64)
        # piecewise linear in A: negative somewhere only at a limit or, with a negative total, beyond the last
        energy = self.loop_energy(d, force, d[1:])
        bad = np.flatnonzero(energy < 0)
        if len(bad) or force.sum() < 0:
            where = (f"of amplitude {_fmt(float(d[1:][bad[0]]))} {params['d1']['unit']}" if len(bad) else
                     f"wider than {_fmt(float(d[-1]))} {params['d1']['unit']}")
            return (f"with the model's Coulomb level the elements give energy back over a cycle {where} "
                    "(negative break-away forces): that is no "
                    "friction; a smooth sign of motion (velocity) or a torque along the travel (position) may "
                    "describe the shape")
        return None

    def summary(self, params):
        n = sum(1 for k in params if k.startswith("d"))
        forces = ", ".join(f"{_fmt(params[f'F{i}']['value'])} at {_fmt(params[f'd{i}']['value'])}" for i in range(1, n + 1))
        return (f"break-away force {_fmt(params['F']['value'])} {params['F']['unit']} in {n} elements "
                f"({forces} {params['d1']['unit'] if n else ''}) over the model's Fc "
                f"{_fmt(params['Fc model']['value'])} {params['F']['unit']}")


class Column(Effect):
    """Another numeric column of the log: a Coulomb-like and an additive term in its deviation."""

    rivals = ((N.LEVEL,),)

    def __init__(self, column: str):
        self.column = column
        self.name = f"{N.COLUMN_PREFIX}{column}"
        self.description = f"friction depending on the column {column!r}"

    def applicable(self, ctx):
        if self.column not in ctx.signals:
            return f"the log has no column {self.column!r}"
        if _constant(ctx.signals[self.column]):
            return f"the column {self.column!r} is constant"
        return None

    def center(self, ctx) -> float:
        return float(np.mean(ctx.signals[self.column]))

    def terms(self, ctx, residual):
        f = T.dev(self.column, self.center(ctx))
        return LEVEL_TERMS + [T.term(f"sign*d{self.column}", T.SIGN, f), T.term(f"d{self.column}", f)]

    def params(self, coef, ctx):
        cu = ctx.column_units.get(self.column) or "unit"
        u = ctx.tau_unit
        lv = equivalent_levels(ctx.p, ctx.signals["qd"])
        bp = coef.get("p", 0.0)
        return {"ref": _par(self.center(ctx), ctx.column_units.get(self.column) or ""),
                "Fc": _par((1 + bp) * lv["Fc"], u),
                f"dFc/d{self.column}": _par(coef.get(f"sign*d{self.column}", 0.0), f"{u}/{cu}"),
                f"dtau/d{self.column}": _par(coef.get(f"d{self.column}", 0.0), f"{u}/{cu}")}


BUILTIN = (Position, Temperature, Drift, Direction, Acceleration, Gravity, Load, Payload, Quadrant, Velocity,
           Hysteresis, Level, Offset)
NAMES = tuple(cls.name for cls in BUILTIN)


def extra_columns(signals: dict[str, np.ndarray]) -> list[str]:
    """Numeric log columns that are not part of the contract (nor model outputs)."""
    return [c for c in signals if c not in KNOWN and not c.startswith("tau_") and c != "i_m"]


def library(signals: dict[str, np.ndarray], only: list[str] | None = None) -> list[Effect]:
    """All candidate effects for these signals (``only``: names to keep, ``column`` = all columns; an
    earlier name, ``fricli.core.effectnames.ALIASES``, stands for its effect)."""
    out: list[Effect] = [cls() for cls in BUILTIN]
    out += [Column(c) for c in extra_columns(signals)]
    if only:
        keep = {N.canonical(name) for name in only}
        out = [e for e in out if e.name in keep or (e.name.startswith(N.COLUMN_PREFIX) and N.COLUMN in keep)]
        named = {e.name for e in out}
        # a column asked for by name that the log lacks stays a candidate: it is reported as skipped
        out += [Column(name[len(N.COLUMN_PREFIX):]) for name in sorted(keep)
                if name.startswith(N.COLUMN_PREFIX) and name not in named]
    return out


class Coupling(Effect):
    """Friction that moves with the other joints of a coupled group (joints that share motors):
    terms in their velocities ``qd@<p>`` and in the direction ``sign_motor@<m>`` of each motor
    that turns with this joint and another, which the command adds to a joint's signals when the
    log records a coupled transmission. A per-joint model cannot follow a motor that turns with
    two joints; the remedy is one model of the group."""

    name = N.COUPLING
    description = "friction moving with the joints it shares motors with (their velocities, the shared motors' directions)"

    @staticmethod
    def signals(ctx) -> list[str]:
        return sorted(s for s in ctx.signals if s.startswith(("qd@", "sign_motor@")))

    def applicable(self, ctx):
        if not any(s.startswith("qd@") for s in self.signals(ctx)):
            return "the joint shares no motor with another joint (or their rows are not given)"
        return None

    def terms(self, ctx, residual):
        return LEVEL_TERMS + [T.term(s, T.sig_(s)) for s in self.signals(ctx)]

    def params(self, coef, ctx):
        out = {}
        for s in self.signals(ctx):
            kind, joint = s.split("@", 1)
            if kind == "qd":
                out[f"Fv@{joint}"] = _par(coef.get(s, 0.0), ctx.fv_unit)
            else:
                out[f"Fc motor {joint}"] = _par(coef.get(s, 0.0), ctx.tau_unit)
        return out

    def summary(self, params):
        joints = sorted(k.split("@", 1)[1] for k in params if k.startswith("Fv@"))
        return (f"moves with joint{'s' if len(joints) > 1 else ''} {', '.join(joints)} (shared motors: fit the group "
                "with identify --coupling); " + super().summary(params))


BUILTIN = BUILTIN + (Coupling,)
NAMES = tuple(cls.name for cls in BUILTIN)
