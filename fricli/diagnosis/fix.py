"""Turn a diagnosis into an augmented model (``diagnose --fix``).

The added effects' terms, with the coefficients fitted on the whole diagnosed log, are put on
top of the original model. When the original model is a LuGre model and a change of level,
a direction asymmetry or a temperature dependence was added, those effects are carried by the
LuGre model's own physical parameters instead (Fc, Fs, Fv, kc, ks scaled; fc_neg, fs_neg,
fv_neg; t_ref, alpha_c, alpha_v), the remaining terms are refitted on top of it, and the
carried form is kept when it fits the log as well as the additive one (in-sample MAE at most
``CARRY_TOLERANCE`` higher); otherwise the effects stay additive terms.
"""

from __future__ import annotations

import numpy as np

from fricli import logs, metrics
from fricli.diagnosis import terms as T
from fricli.diagnosis.driver import Diagnosis
from fricli.models.augmented import AugmentedModel

CARRY_TOLERANCE = 0.02
CARRIABLE = ("level", "direction", "temperature")
LEVEL_NAMES = ("p", "qd")
DIRECTION_NAMES = ("p*pos", "qd*pos")
TEMPERATURE_NAMES = ("p*dtemp", "qd*dtemp")


def augment(model, diagnosis: Diagnosis, log: logs.Log, carry: bool = True) -> AugmentedModel:
    """The augmented model for ``diagnosis`` (of ``model`` on ``log``)."""
    terms = list(diagnosis.terms)
    coef = np.array([diagnosis.coef[t["name"]] for t in terms])
    params = {e.name: e.params for e in diagnosis.effects if e.added}
    additive = AugmentedModel(model, terms, coef, effects=diagnosis.added, params=params)
    if not carry or model.kind != "lugre":
        return additive
    carried = _carry_lugre(model, diagnosis, log, params)
    if carried is None:
        return additive
    y = logs.friction_target(log.signals)
    mae_add = metrics.errors(y, additive.predict(log.signals)[0])["mae"]
    mae_car = metrics.errors(y, carried.predict(log.signals)[0])["mae"]
    return carried if mae_car <= mae_add * (1.0 + CARRY_TOLERANCE) else additive


def _carry_lugre(model, diagnosis: Diagnosis, log: logs.Log, params: dict) -> AugmentedModel | None:
    added = set(diagnosis.added)
    which = [e for e in CARRIABLE if e in added]
    if "direction" in which and model.asymmetric:
        which.remove("direction")
    if "temperature" in which and model.thermal:
        which.remove("temperature")
    if not which:
        return None
    c = diagnosis.coef
    bp, bv = c.get("p", 0.0), c.get("qd", 0.0)
    absorbed = set(LEVEL_NAMES)
    s_pos = s_neg = 1.0 + bp
    fv_pos = fv_neg = bv
    if "direction" in which:
        s_pos += c.get("p*pos", 0.0)
        fv_pos += c.get("qd*pos", 0.0)
        absorbed |= set(DIRECTION_NAMES)
    s_mean = 0.5 * (s_pos + s_neg)
    if min(s_pos, s_neg) <= 0:
        return None
    new = dict(fc=model.fc * s_pos, fs=model.fs * s_pos, fv=model.fv * s_pos + fv_pos,
               kc=model.kc * s_mean, ks=model.ks * s_mean)
    if "direction" in which:
        new.update(fc_neg=model.fc * s_neg, fs_neg=model.fs * s_neg, fv_neg=model.fv * s_neg + fv_neg)
    if "temperature" in which:
        term = next(t for t in diagnosis.terms if t["name"] == "p*dtemp")
        t_ref = float(term["factors"][1]["center"])
        bpt, bvt = c.get("p*dtemp", 0.0), c.get("qd*dtemp", 0.0)
        fv_ref = new["fv"]
        if fv_ref <= 0:
            return None
        new.update(t_ref=t_ref, alpha_c=-bpt / s_mean, alpha_v=-(bpt * model.fv + bvt) / fv_ref)
        absorbed |= set(TEMPERATURE_NAMES)
    if min(new["fc"], new["fs"], new.get("fc_neg", 1.0), new.get("fs_neg", 1.0)) <= 0 or new["fv"] < 0:
        return None
    try:
        base = model.replace(**new)
    except ValueError:
        return None
    free = ["fc", "fs", "fv"]
    if "direction" in which:
        free += ["fc_neg", "fs_neg", "fv_neg"]
    if "level" in which and (model.kc or model.ks):
        free += ["kc", "ks"]
    if "temperature" in which:
        free += ["alpha_c", "alpha_v"]
    rest = [t for t in diagnosis.terms if t["name"] not in absorbed]
    base, coef = _refine(base, free, rest, log.signals)
    if base is None:
        return None
    return AugmentedModel(base, rest, coef, effects=diagnosis.added,
                          carried=[e for e in diagnosis.added if e in which], params=params)


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


def _refine(base, free: list[str], rest: list[dict], sig: dict, iterations: int = 4):
    """Gauss-Newton on the LuGre parameters ``free`` (finite-difference Jacobian of the
    prediction), jointly with the linear coefficients of the remaining terms ``rest``.
    Returns (LuGre model, coefficients of rest) or (None, None) when no physical model fits."""
    y = logs.friction_target(sig)

    def evaluate(model):
        p = np.asarray(model.predict(sig)[0])
        coef, r = _fit_terms(rest, sig, p, y - p)
        return p, coef, float(np.mean(r * r))

    def build(values):
        try:
            model = base.replace(**dict(zip(free, values)))
        except ValueError:
            return None
        if min(model.fc, model.fs) <= 0 or model.fv < 0 or (model.asymmetric and min(model.negative_levels()) < 0):
            return None
        return model

    theta = np.array([getattr(base, k) for k in free], dtype=np.float64)
    model = build(theta)
    if model is None:
        return None, None
    p, coef, cost = evaluate(model)
    for _ in range(iterations):
        J = np.empty((len(p), len(free)))
        for i, name in enumerate(free):
            h = 1e-4 * max(abs(theta[i]), 1e-3 if name.startswith("alpha") else 1e-2)
            step = theta.copy()
            step[i] += h
            trial = build(step)
            if trial is None:
                step[i] -= 2 * h
                h = -h
                trial = build(step)
            J[:, i] = (np.asarray(trial.predict(sig)[0]) - p) / h if trial is not None else 0.0
        delta, _ = _fit_terms(rest, sig, p, y - p, extra=J)
        delta = delta[:len(free)]
        improved = False
        for shrink in (1.0, 0.5, 0.25):
            cand = build(theta + shrink * delta)
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
