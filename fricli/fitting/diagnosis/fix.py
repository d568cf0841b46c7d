"""Turn a diagnosis into an augmented model (``diagnose --fix``).

The added effects' terms, with the coefficients fitted on the whole diagnosed log, are put on
top of the original model. When the original model is a LuGre model and a change of level,
a direction asymmetry or a temperature dependence was added, those effects are carried by the
LuGre model's own physical parameters instead: level scales Fc, Fs (and kc, ks) by one factor
and sets Fv; direction sets that factor and Fv per direction (fc_neg, fs_neg, fv_neg);
temperature sets t_ref (the log's mean temperature), alpha_c and alpha_v. The Stribeck shape
(vs, delta, Fs/Fc) and the bristle parameters stay as identified. Those few parameters are
refined on the log by Gauss-Newton together with the remaining terms, and the carried form is
kept when it fits the log as well as the additive one (in-sample MAE at most
``CARRY_TOLERANCE`` higher); otherwise the effects stay additive terms.

When an inertia term (``acceleration``) was added to a LuGre model, its bristle parameters
sigma0 and sigma1 are refined too: identify fits them to the transients of the log, and
without the inertia those transients held the inertia force (on a log without tau_dyn, like
EMPS, nearly all of it). The model lists them under ``refitted``.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.core import effectnames as N
from fricli.core import logs, metrics
from fricli.models import terms as T
from fricli.fitting.diagnosis.driver import Diagnosis
from fricli.models.augmented import AugmentedModel

CARRY_TOLERANCE = 0.02
CARRIABLE = (N.LEVEL, N.DIRECTION, N.TEMPERATURE)
SHARING = {N.DRIFT, N.VELOCITY}          # other effects whose groups include the level terms
SCALE_RANGE = (0.25, 4.0)                # a carried level factor outside this is not the same joint
SIGMA1_FLOOR = 1e-9                      # sigma1 >= sigma0 * floor on the log scale [s]
LEVEL_NAMES = ("p", "qd")
DIRECTION_NAMES = ("p*pos", "qd*pos")
TEMPERATURE_NAMES = ("p*dtemp", "qd*dtemp")


def augment(model, diagnosis: Diagnosis, log: logs.Log, carry: bool = True) -> AugmentedModel:
    """The augmented model for ``diagnosis`` (of ``model`` on ``log``)."""
    terms = list(diagnosis.terms)
    coef = np.array([diagnosis.coef[t["name"]] for t in terms])
    params = {e.name: e.params for e in diagnosis.effects if e.added}
    additive = _split(model, terms, coef, diagnosis, effects=diagnosis.added, params=params)
    if not carry or model.kind != "lugre":
        return additive
    carried = _carry_lugre(model, diagnosis, log, params)
    if carried is None:
        return additive
    y = logs.friction_target(log.signals)
    mae_add = metrics.errors(y, additive.predict(log.signals)[0])["mae"]
    mae_car = metrics.errors(y, carried.predict(log.signals)[0])["mae"]
    if mae_car > mae_add * (1.0 + CARRY_TOLERANCE):
        return additive
    carried.params = _final_params(carried, diagnosis, log)
    return carried


CARRIED_PARAMS = {N.LEVEL: ("fc", "fs", "fv", "kc", "ks"),
                  N.DIRECTION: ("fc", "fc_neg", "fs", "fs_neg", "fv", "fv_neg"),
                  N.TEMPERATURE: ("t_ref", "alpha_c", "alpha_v")}


def _final_params(model: AugmentedModel, diagnosis: Diagnosis, log: logs.Log) -> dict:
    """The added effects' parameters as the model now holds them: the LuGre parameters for
    carried effects, the effect's reading of the refitted coefficients for the others."""
    from fricli.fitting.diagnosis import effects as E
    from fricli.fitting.diagnosis.driver import column_units
    from fricli.models.lugre import unit_of

    sig = log.signals
    ctx = E.Context(sig, np.asarray(model.base.predict(sig)[0]), log.axis, column_units(log.table))
    lib = {e.name: e for e in E.library(sig)}
    coef = {t["name"]: float(c) for t, c in zip(model.terms + model.error_terms,
                                                 np.concatenate([model.coef, model.error_coef]))}
    out = {}
    for result in diagnosis.effects:
        if not result.added:
            continue
        if result.name in model.carried:
            base = model.base
            out[result.name] = {k: {"value": float(getattr(base, k)), "unit": unit_of(k, log.axis)}
                                for k in CARRIED_PARAMS[result.name]}
        else:
            names = [t["name"] for t in result.terms]
            out[result.name] = lib[result.name].params({n: coef.get(n, 0.0) for n in names}, ctx)
    return out


def _carry_lugre(model, diagnosis: Diagnosis, log: logs.Log, params: dict) -> AugmentedModel | None:
    """The carried form: the LuGre model with the effects as its own parameters, refined on the
    log together with the remaining terms, or None when the effects cannot be carried."""
    added = set(diagnosis.added)
    which = [e for e in CARRIABLE if e in added]
    if N.DIRECTION in which and model.asymmetric:
        which.remove(N.DIRECTION)
    if N.TEMPERATURE in which and model.thermal:
        which.remove(N.TEMPERATURE)
    if added & SHARING or any(a.startswith(N.COLUMN_PREFIX) for a in added):
        which = []          # their level terms cannot be told apart from a carried level
    bristles = N.ACCELERATION in added
    if not which and not bristles:
        return None
    c = diagnosis.coef
    absorbed = set(LEVEL_NAMES) if which else set()
    bp, bv = (c.get("p", 0.0), c.get("qd", 0.0)) if which else (0.0, 0.0)
    # knobs: Coulomb/static scale and viscous level per direction (the Stribeck shape, Fs/Fc
    # and the load slopes' ratio stay as identified), the temperature coefficients, and the
    # bristle parameters when an inertia term was found (log scale)
    knobs = {"s_pos": 1.0 + bp, "fv": model.fv * (1.0 + bp) + bv}
    if bristles:
        knobs["log_sigma0"] = math.log(model.sigma0)
        knobs["log_sigma1"] = math.log(max(model.sigma1, model.sigma0 * SIGMA1_FLOOR))
    if N.DIRECTION in which:
        knobs["s_neg"] = knobs["s_pos"]
        knobs["fv_neg"] = knobs["fv"]
        knobs["s_pos"] += c.get("p*pos", 0.0)
        knobs["fv"] += model.fv * c.get("p*pos", 0.0) + c.get("qd*pos", 0.0)
        absorbed |= set(DIRECTION_NAMES)
    t_ref = None
    if N.TEMPERATURE in which:
        term = next(t for t in diagnosis.terms if t["name"] == "p*dtemp")
        t_ref = float(term["factors"][1]["center"])
        bpt, bvt = c.get("p*dtemp", 0.0), c.get("qd*dtemp", 0.0)
        s_mean = knobs["s_pos"] if "s_neg" not in knobs else 0.5 * (knobs["s_pos"] + knobs["s_neg"])
        knobs["alpha_c"] = -bpt / s_mean if s_mean > 0 else 0.0
        knobs["alpha_v"] = -(bpt * model.fv + bvt) / knobs["fv"] if knobs["fv"] > 0 else 0.0
        absorbed |= set(TEMPERATURE_NAMES)
    scale_load = N.LEVEL in which

    def build(values: dict):
        s_pos, s_neg = values["s_pos"], values.get("s_neg")
        s_load = (s_pos if s_neg is None else 0.5 * (s_pos + s_neg)) if scale_load else 1.0
        if not all(SCALE_RANGE[0] <= s <= SCALE_RANGE[1] for s in (s_pos, s_neg or s_pos)):
            return None
        new = dict(fc=model.fc * s_pos, fs=model.fs * s_pos, fv=values["fv"], kc=model.kc * s_load,
                   ks=model.ks * s_load)
        if "log_sigma0" in values:
            if not all(-700 < values[k] < 700 for k in ("log_sigma0", "log_sigma1")):
                return None
            new.update(sigma0=math.exp(values["log_sigma0"]), sigma1=math.exp(values["log_sigma1"]))
        if s_neg is not None:
            new.update(fc_neg=model.fc * s_neg, fs_neg=model.fs * s_neg, fv_neg=values["fv_neg"])
        if "alpha_c" in values:
            new.update(t_ref=t_ref, alpha_c=values["alpha_c"], alpha_v=values["alpha_v"])
        if min(new["fc"], new["fs"], new.get("fc_neg", 1.0), new.get("fs_neg", 1.0)) <= 0:
            return None
        if new["fv"] < 0 or new.get("fv_neg", 0.0) < 0:
            return None
        try:
            return model.replace(**new)
        except ValueError:
            return None

    rest = [t for t in diagnosis.terms if t["name"] not in absorbed]
    base, coef = _refine(build, knobs, rest, log.signals)
    if base is None:
        return None
    refitted = ["sigma0", "sigma1"] if bristles else []
    return _split(base, rest, coef, diagnosis, effects=diagnosis.added,
                  carried=[e for e in diagnosis.added if e in which], refitted=refitted, params=params)


def _split(base, terms: list[dict], coef: np.ndarray, diagnosis: Diagnosis, **kwargs) -> AugmentedModel:
    """The augmented model with the robot-model error terms apart from the friction terms."""
    errors = diagnosis.error_term_names()
    coef = np.asarray(coef, dtype=np.float64)
    is_error = np.array([t["name"] in errors for t in terms], dtype=bool)
    return AugmentedModel(base, [t for t, e in zip(terms, is_error) if not e], coef[~is_error],
                          error_terms=[t for t, e in zip(terms, is_error) if e], error_coef=coef[is_error],
                          errors=diagnosis.errors, **kwargs)


def _fit_terms(terms: list[dict], sig: dict, p: np.ndarray, target: np.ndarray,
               extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Least squares of target (n,) on [extra columns, terms]: (coefficients, residual)."""
    cols = [] if extra is None else [extra]
    if terms:
        cols.append(T.Columns(sig, p).matrix(terms))
    if not cols:
        return np.zeros(0), target
    X = np.hstack(cols)
    scale = np.sqrt(np.mean(X * X, axis=0))
    scale[scale == 0] = 1.0
    beta, *_ = np.linalg.lstsq(X / scale, target, rcond=1e-10)
    beta = beta / scale
    return beta, target - X @ beta


def _refine(build, knobs: dict, rest: list[dict], sig: dict, iterations: int = 4):
    """Gauss-Newton on the ``knobs`` of the model ``build(knobs)`` (finite-difference Jacobian of
    its prediction), jointly with the linear coefficients of the remaining terms ``rest``.
    Returns (model, coefficients of rest), or (None, None) when no physical model results."""
    y = logs.friction_target(sig)
    names = list(knobs)

    def evaluate(model):
        p = np.asarray(model.predict(sig)[0])
        coef, r = _fit_terms(rest, sig, p, y - p)
        return p, coef, float(np.mean(r * r))

    def make(theta):
        return build(dict(zip(names, theta)))

    theta = np.array([knobs[k] for k in names], dtype=np.float64)
    model = make(theta)
    if model is None:
        return None, None
    p, coef, cost = evaluate(model)
    for _ in range(iterations):
        J = np.zeros((len(p), len(names)))
        for i, name in enumerate(names):
            h = 1e-4 * max(abs(theta[i]), 1e-3 if name.startswith(("alpha", "s_")) else 1e-2)
            if name.startswith("log_"):
                h = 1e-3
            for sign in (1.0, -1.0):
                step = theta.copy()
                step[i] += sign * h
                trial = make(step)
                if trial is not None:
                    J[:, i] = (np.asarray(trial.predict(sig)[0]) - p) / (sign * h)
                    break
        delta, _ = _fit_terms(rest, sig, p, y - p, extra=J)
        delta = delta[:len(names)]
        improved = False
        for shrink in (1.0, 0.5, 0.25):
            cand = make(theta + shrink * delta)
            if cand is None:
                continue
            cp, ccoef, ccost = evaluate(cand)
            if ccost < cost:
                theta, model, p, coef, cost = theta + shrink * delta, cand, cp, ccoef, ccost
                improved = True
                break
        if not improved or np.all(np.abs(delta) <= 1e-6 * np.maximum(np.abs(theta), 1e-3)):
            break
    return model, coef


def refit(model, log: logs.Log):
    """``model``'s kind fitted again on ``log`` (LuGre and linear, as ``identify`` fits them; other kinds
    are returned unchanged): the friction of a log whose robot-model terms changed."""
    if model.kind == "lugre":
        from fricli.fitting.identify import LuGreIdentifier

        return LuGreIdentifier().fit(log.signals, units=log.units, axis=log.axis).model_
    if model.kind == "linear":
        from fricli.models import linear

        return linear.fit(log.signals, asymmetric=bool(getattr(model, "asymmetric", False)), axis=log.axis)[0]
    return model
