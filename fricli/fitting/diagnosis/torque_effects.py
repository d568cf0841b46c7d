"""Candidate effects in the torques the robot model accounts for: a missing inertia
(``acceleration``), a gravity scale, a load or payload the gear holds and the driving/back-driven
quadrant. Their coefficients are torque ratios [Nm/Nm] or robot-model corrections, plausible only
within bounds (``RATIO_BOUND``, ``ROBOT_MODEL_TOLERANCE``)."""

from __future__ import annotations

import numpy as np

from fricli.core import effectnames as N
from fricli.fitting.diagnosis.context import Context, Effect, _fmt, _par
from fricli.models import terms as T


class Acceleration(Effect):
    name = N.ACCELERATION
    description = "a term in qdd (inertia missing or wrong in tau_dyn)"
    part = "model"

    def applicable(self, ctx):
        if _constant(ctx.signals["qdd"]):
            return "the log has no acceleration"
        return None

    def terms(self, ctx, residual):
        return [T.term("qdd", T.sig_("qdd"))]

    def params(self, coef, ctx):
        return {"inertia": _par(coef["qdd"], ctx.inertia_unit)}

    def implausible(self, params, ctx):
        j = params["inertia"]["value"]
        if j is None:
            return None
        ref = ctx.model_inertia()
        u = ctx.inertia_unit
        if j < 0 and (ref is None or -j > ROBOT_MODEL_TOLERANCE * ref):
            seen = f" ({_fmt(100 * -j / ref)} % of the {_fmt(ref)} {u} the robot model's tau_dyn shows)" if ref else ""
            return (f"a negative inertia{seen}; more likely a delay between the torque and the filtered "
                    f"acceleration, or a friction lag, than a robot model that heavy")
        sig = ctx.signals
        if j > 0 and "tau_m" in sig:
            need = j * float(np.sqrt(np.mean(np.square(sig["qdd"]))))
            have = float(np.sqrt(np.mean(np.square(sig["tau_m"]))))
            if need > have:
                return (f"its torque alone (rms {_fmt(need)} {ctx.tau_unit}) would exceed all the motor gave "
                        f"(rms {_fmt(have)} {ctx.tau_unit}); more likely a wrong acceleration (its unit or filter)")
        return None

    def summary(self, params):
        return f"missing inertia {_fmt(params['inertia']['value'])} {params['inertia']['unit']}"


#: a robot-model correction beyond this share (a gravity scale, a negative inertia) is suspicious
ROBOT_MODEL_TOLERANCE = 0.3


#: a ratio of torques [Nm/Nm] beyond this magnitude is not physical (kc, kq)
RATIO_BOUND = 1.0


def _needs_tau_g(ctx) -> str | None:
    if "tau_g" not in ctx.signals or _constant(ctx.signals["tau_g"]):
        return "the log has no varying 'tau_g'"
    return None


def _constant(x: np.ndarray) -> bool:
    """x (n,) is constant up to rounding: its spread is below sqrt(eps) of its magnitude."""
    return not np.ptp(x) > np.sqrt(np.finfo(np.float64).eps) * float(np.max(np.abs(x)))


def _ratio_reach(effect: Effect, ctx: Context, what: str) -> str | None:
    """None when ``effect``'s single term, a torque times a coefficient in Nm/Nm, could remove
    ``ctx.min_gain`` of the residual's mean square at the physical bound of that coefficient
    (``RATIO_BOUND``); else why the log cannot identify it."""
    if ctx.residual_ms <= 0:
        return None
    col = T.matrix(effect.terms(ctx, None), ctx.signals, ctx.p)[:, 0]
    spread = float(np.std(col))
    reach = RATIO_BOUND ** 2 * spread ** 2 / ctx.residual_ms
    if reach >= ctx.min_gain:
        return None
    u = ctx.tau_unit
    share = f"{100 * reach:.2g} %" if reach >= 1e-4 else "under 0.01 %"
    return (f"{what} varies too little on this log (std {spread:.2g} {u}): even {RATIO_BOUND:g} {u}/{u} would "
            f"explain {share} of the residual, under the {100 * ctx.min_gain:g} % an effect must remove")


def _ratio_text(name: str, par: dict) -> str:
    """``"kc 0.01 Nm/Nm"``; beyond the physical bound only the side it lies on (the figure means nothing)."""
    v = par["value"]
    if v is not None and abs(v) > RATIO_BOUND:
        return f"{name} {'>' if v > 0 else '<'} {RATIO_BOUND if v > 0 else -RATIO_BOUND:g} {par['unit']} (not physical)"
    return f"{name} {_fmt(v)} {par['unit']}"


def _ratio_implausible(name: str, value: float | None, unit: str) -> str | None:
    if value is None or abs(value) <= RATIO_BOUND:
        return None
    return (f"|{name}| > {RATIO_BOUND:g} {unit} is not physical (the friction would exceed the torque through "
            f"the gear); the shape more likely comes from tau_g (a gravity or payload error) than from friction")


#: the load term turns over the model's pre-sliding travel d only where the position's noise at rest,
#: the 95th percentile of its steps there, stays below d / REST_NOISE_SHARE: it then moves the term of a
#: joint at rest by a fifth of its range at most instead of flipping its sign
REST_NOISE_SHARE = 5.0


def load_travel(ctx: Context) -> float:
    """The travel d [rad or m] over which the load, payload and direction terms turn over after a
    reversal: the base model's pre-sliding travel (``Context.presliding``), 0 (the sign of motion)
    for a model without one or where the position's noise at rest would move the element across it."""
    d = ctx.presliding
    if not d > 0 or "q" not in ctx.signals:
        return 0.0
    rest = ~ctx.moving()
    both = rest[1:] & rest[:-1]
    if both.any():
        noise = float(np.percentile(np.abs(np.diff(ctx.signals["q"])[both]), 95))
        if d <= REST_NOISE_SHARE * noise:
            return 0.0
    return float(f"{d:.6g}")


class Load(Effect):
    """The Coulomb level grows with the gravity load on the gear, kc*|tau_g|. That friction turns
    over after a reversal as the rest of the Coulomb friction does: within the base model's
    pre-sliding travel d (a slip element of limit d), not at the sample where qd changes sign,
    which a joint reversing slowly takes many samples to cover; without a pre-sliding travel, with
    the direction of motion held through rests."""

    name = N.LOAD
    # a level that grows with |tau_g| must explain more than a level that does not
    rivals = ((N.LEVEL,),)
    description = "Coulomb level growing with |tau_g|, the gravity load on the gear (its normal force)"

    def applicable(self, ctx):
        return _needs_tau_g(ctx) or _ratio_reach(self, ctx, "|tau_g|*sign(qd)")

    def terms(self, ctx, residual):
        d = load_travel(ctx)
        if d:
            return [T.term("|tau_g|*slip", T.abs_("tau_g"), T.slip_(d))]
        return [T.term("|tau_g|*sign", T.abs_("tau_g"), T.SIGN)]

    def params(self, coef, ctx):
        kc = coef["|tau_g|*slip"] if "|tau_g|*slip" in coef else coef["|tau_g|*sign"]
        return {"kc": _par(kc, f"{ctx.tau_unit}/{ctx.tau_unit}")}

    def implausible(self, params, ctx):
        return _ratio_implausible("kc", params["kc"]["value"], params["kc"]["unit"])

    def summary(self, params):
        return _ratio_text("kc", params["kc"])


class Payload(Effect):
    """A payload the robot model lacks loads the gear: the friction's load dependence follows the
    torque through the gear, |tau_l| with tau_l = tau_m - tau_dyn - p (motor torque minus inertia and friction),
    where the model sees only |tau_g|. That friction turns over after a reversal as ``Load``'s does:
    within the base model's pre-sliding travel, else with the direction of motion."""

    name = N.PAYLOAD
    description = "friction growing with |tau_l| - |tau_g|: the gear carries a load tau_g lacks (a payload)"

    def applicable(self, ctx):
        # a payload loads the gear through gravity: where tau_g cannot load it, neither can a payload,
        # and the gear load tau_l would only echo the model's own residual
        return (_needs_tau_g(ctx) or _ratio_reach(Load(), ctx, "|tau_g|*sign(qd)")
                or _ratio_reach(self, ctx, "(|tau_l| - |tau_g|)*sign(qd)"))

    def terms(self, ctx, residual):
        d = load_travel(ctx)
        if d:
            return [T.term("(|tau_l|-|tau_g|)*slip", T.OVERLOAD, T.slip_(d))]
        return [T.term("(|tau_l|-|tau_g|)*sign", T.OVERLOAD, T.SIGN)]

    def params(self, coef, ctx):
        kc = coef["(|tau_l|-|tau_g|)*slip"] if "(|tau_l|-|tau_g|)*slip" in coef else coef["(|tau_l|-|tau_g|)*sign"]
        return {"kc": _par(kc, f"{ctx.tau_unit}/{ctx.tau_unit}")}

    def implausible(self, params, ctx):
        kc = params["kc"]["value"]
        if kc is not None and kc < 0:
            # |tau_l| - |tau_g| is the residual itself where no payload loads the gear, so a
            # fit of it can echo any residual; a real payload only adds friction
            return ("kc < 0 is not physical (friction falling as the gear carries more load); tau_l holds "
                    "the model's own residual, so the term echoes it rather than a payload")
        return _ratio_implausible("kc", kc, params["kc"]["unit"])

    def summary(self, params):
        return _ratio_text("kc", params["kc"])


class Gravity(Effect):
    """The logged gravity torque is off by a factor: the residual holds k*tau_g, at rest as in
    motion, and the true gravity torque is (1 + k) times the logged one."""

    name = N.GRAVITY
    description = "the logged tau_g (the robot model's gravity) is off by a factor: a robot-model error"
    part = "model"

    def applicable(self, ctx):
        return _needs_tau_g(ctx) or _ratio_reach(self, ctx, "tau_g")

    def terms(self, ctx, residual):
        return [T.term("tau_g", T.sig_("tau_g"))]

    def implausible(self, params, ctx):
        scale = params["scale"]["value"]
        if scale is None or abs(scale - 1.0) <= ROBOT_MODEL_TOLERANCE:
            return None
        mapping = ("the joint's zero or sign convention against the URDF (an encoder offset of a multiple of pi/2 "
                   "left out of the mapping, or the joint turning the other way: fricli import checks the mapping "
                   "against the URDF, docs/robot-import.md)")
        if scale < 0:     # no mass, gain or spring makes gravity act the other way round
            return (f"a gravity scale of {_fmt(scale)}: the logged tau_g acts against the measured torque; the "
                    f"likely cause is {mapping}, or a reversed sign of tau_m")
        return (f"a gravity scale of {_fmt(scale)} is outside 1 +- {100 * ROBOT_MODEL_TOLERANCE:g} %, more than "
                f"CAD masses usually miss by (calibrate the robot model to tell); a torque proportional to tau_g "
                f"also comes from {mapping}, a drive gain or torque constant error, a cable or hose, a "
                f"counterbalance spring, or a wrong payload")

    def params(self, coef, ctx):
        k = coef["tau_g"]
        return {"scale": _par(1.0 + k, ""),
                "error": _par(100.0 * (1.0 / (1.0 + k) - 1.0) if k > -1 else float("nan"), "%")}

    def summary(self, params):
        e = params["error"]["value"]
        if e is None:
            return "logged tau_g has the wrong sign"
        return (f"logged tau_g {_fmt(abs(e))} % {'low' if e < 0 else 'high'} "
                f"(true = {_fmt(params['scale']['value'])} x logged)")


class Quadrant(Effect):
    """Friction that differs between the quadrants of (qd, tau_g): the Coulomb level is
    Fc + kq*tau_g*sign(qd), higher when the joint drives against the gravity load on the gear
    (sign(qd*tau_g) > 0) than when that load back-drives it. In the signed friction that is
    kq*tau_g, held through rests at its value when the motion stopped (the bristles hold the
    friction they had), which tells it apart from an error of the logged gravity torque."""

    name = N.QUADRANT
    rivals = ((N.OFFSET,),)
    description = "friction kq*|tau_g| higher when the joint drives against tau_g than when back-driven"

    def applicable(self, ctx):
        return _needs_tau_g(ctx) or _ratio_reach(self, ctx, "tau_g held through rests")

    def terms(self, ctx, residual):
        return [T.term("tau_g held", T.HELDGRAVITY)]

    def implausible(self, params, ctx):
        return _ratio_implausible("kq", params["kq"]["value"], params["kq"]["unit"])

    def params(self, coef, ctx):
        return {"kq": _par(coef["tau_g held"], f"{ctx.tau_unit}/{ctx.tau_unit}")}

    def summary(self, params):
        return f"{_ratio_text('kq', params['kq'])}: Coulomb level + kq*tau_g*sign(qd) (driving vs back-driven)"
