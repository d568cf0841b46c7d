"""train-base's friction with memory: Maxwell-slip elements on top of a trained network.

A network of speed, direction and load has no memory of the motion before (its pre-sliding
state holds one bristle deflection at most). Friction that follows the position since the last
reversal (hysteresis) shows in its residual. ``with_memory`` tests that residual with the
diagnosis's ``hysteresis`` candidate (``fricli.fitting.diagnosis``: four elements on the log's
own grid of deflection limits, with the level terms; blocked cross-validation over time; it must
beat the ``level`` and ``velocity`` candidates, a change of level and a smooth correction in
speed, on held-out blocks) and, when it is chosen (``auto``) or always (``on``), returns the
network with the elements as an ``augmented`` model.

The elements' energy rule of the diagnosis stands in every mode: elements that, with the
network's equivalent Coulomb level, give energy back over a slow cycle of the position
(``Hysteresis.implausible``) are not added, and neither are terms that would turn the friction in
steady sliding along the motion on any row of the log in motion (the network scaled by 1 + b_p,
a viscous change b_v qd and the elements' saturated forces; ``_along``).
"""

from __future__ import annotations

import numpy as np

from fricli.core import effectnames as N
from fricli.core import logs, metrics
from fricli.core.errors import DataError, ModelFileError
from fricli.fitting.diagnosis import driver
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.diagnosis import selection
from fricli.models import terms as T
from fricli.models.augmented import AugmentedModel
from fricli.models.base import FrictionModel

#: the candidates of the test: the elements, and what they must beat on held-out blocks
CANDIDATES = (N.HYSTERESIS, N.LEVEL, N.VELOCITY)


def with_memory(model: FrictionModel, log: logs.Log, memory: str = "auto") -> tuple[FrictionModel, dict]:
    """(model, summary): ``model`` (trained on ``log``) with Maxwell-slip elements when ``memory``
    is "on", or "auto" and the diagnosis chooses them on held-out blocks; else ``model`` itself
    ("off", train-base's third choice, does not come here).

    summary: "mode"; "chosen" (the elements are in the returned model); "why" (one line for
    people); "tested" (the diagnosis ran); with it "significant" (chosen by the held-out test),
    the held-out figures over the diagnosis's folds ("folds"; "mae_before": the network's
    residual MAE [Nm or N], "mae_after": with the elements fitted on the other folds,
    "rmse_before", "rmse_after", "gain": share of the held-out squared residual they remove
    alone), what the diagnosis added ("diagnosis_added": hysteresis, level, velocity), the
    network's scale 1 + b_p ("scale") and the elements' parameters ("params": limits d1..4,
    break-away forces F1..4, their sum F, the model's Coulomb and viscous level as rescaled);
    when chosen, "moving": MAE, RMSE, max [Nm or N] of the returned model over the log's rows
    in motion. A log the diagnosis cannot take (too few rows for its folds, a joint held still,
    no reversals) is not tested ("why" says why).
    """
    if memory not in ("auto", "on"):
        raise ValueError(f"unknown memory choice {memory!r}")
    try:
        diagnosis = driver.diagnose(model, log, only=list(CANDIDATES))
    except (DataError, ModelFileError) as exc:    # too few rows for the folds, a joint held still
        return model, {"mode": memory, "chosen": False, "tested": False, "why": f"not tested: {exc}"}
    if N.HYSTERESIS in diagnosis.skipped:
        return model, {"mode": memory, "chosen": False, "tested": False,
                       "why": f"not tested: {diagnosis.skipped[N.HYSTERESIS]}"}
    result = next(e for e in diagnosis.effects if e.name == N.HYSTERESIS)
    significant = N.HYSTERESIS in diagnosis.added
    fitted = _fit(model, log, result.terms, diagnosis.folds)
    params, coef, implausible, turned = (fitted.pop(k) for k in ("params", "coef", "implausible", "turned"))
    summary = {"mode": memory, "tested": True, "significant": significant, "folds": diagnosis.folds, **fitted,
               "params": params, "diagnosis_added": list(diagnosis.added)}
    unphysical = implausible or _turned(turned, fitted["scale"])
    better = fitted["mae_after"] < fitted["mae_before"]
    if unphysical:
        summary.update(chosen=False, why=f"not added: {unphysical}")
    elif memory == "auto" and not significant:
        summary.update(chosen=False, why=_why_not(diagnosis, result))
    elif memory == "auto" and not better:
        summary.update(chosen=False, why="not added: the held-out MAE would not fall (a few large residuals drive "
                                         "the elements)")
    else:
        summary.update(chosen=True, why=("chosen on held-out blocks" if significant else
                                         "--memory on (the held-out test alone would not have chosen them)"))
    if not summary["chosen"]:
        return model, summary
    terms = [dict(t) for t in result.terms]
    augmented = AugmentedModel(model, terms, np.array([coef[t["name"]] for t in terms]), effects=[N.HYSTERESIS],
                               params={N.HYSTERESIS: params})
    moving = metrics.in_motion(log.signals["qd"])
    summary["moving"] = metrics.errors(logs.friction_target(log.signals)[moving],
                                       augmented.predict(log.signals)[0][moving])
    return augmented, summary


def _fit(model: FrictionModel, log: logs.Log, terms: list[dict], folds: int) -> dict:
    """The effect's ``terms`` fitted to the residual of ``model`` on ``log``: on all rows
    ("coef", "params") and, on each of ``folds`` blocks of time, on the other blocks (held-out
    MAE and RMS before and after, "gain")."""
    p, r = driver.residual(model, log)
    design = selection.Design(r, folds)
    columns = T.Columns(log.signals, p)
    names = [t["name"] for t in terms]
    for term in terms:
        design.add(term["name"], columns.value(term))
    coef = design.fit(names)
    left = r - design.heldout_prediction(names)
    ctx = E.Context(log.signals, p, log.axis, driver.column_units(log.table))
    effect = E.Hysteresis()
    params = effect.params(coef, ctx)
    before, after = metrics.errors(r, np.zeros_like(r)), metrics.errors(r, r - left)
    sse0 = float(r @ r)
    return {"coef": coef, "params": params, "implausible": effect.implausible(params, ctx),
            "mae_before": before["mae"], "mae_after": after["mae"], "rmse_before": before["rmse"],
            "rmse_after": after["rmse"], "gain": 1.0 - float(left @ left) / sse0 if sse0 > 0 else 0.0,
            "scale": 1.0 + coef.get("p", 0.0), "turned": _along(model, log.signals, coef)}


def _along(model: FrictionModel, sig: dict[str, np.ndarray], coef: dict[str, float]) -> int:
    """Rows in motion of ``sig`` where the friction in steady sliding (every element slipping)
    would point along the motion: (1 + b_p) m + b_v |qd| + sum(F_i) < 0, m the network's
    magnitude (``magnitude``). 0 for a base without one (mlp, selmic, nnacm: no direction
    constraint to keep)."""
    if not hasattr(model, "magnitude"):
        return 0
    moving = metrics.in_motion(sig["qd"])
    rows = {k: v[moving] for k, v in sig.items() if k in model.required_inputs() | {"t"}}
    force = sum(v for k, v in coef.items() if k.startswith("slip@"))
    sliding = (1.0 + coef.get("p", 0.0)) * model.magnitude(rows) + coef.get("qd", 0.0) * np.abs(rows["qd"]) + force
    return int(np.count_nonzero(sliding < 0))


def _turned(rows: int, scale: float) -> str | None:
    """Why the effect's terms may not go on the network (the network scaled by ``scale`` = 1 + b_p;
    ``rows`` rows in motion where steady sliding would go along the motion, ``_along``); None when
    they may."""
    if scale > 0 and rows == 0:
        return None
    return (f"with the level terms (the network x{scale:.3g} and a viscous change) the friction in steady sliding "
            f"would point along the motion on {rows} rows in motion: that is no friction")


def _why_not(diagnosis: driver.Diagnosis, result: driver.EffectResult) -> str:
    """Why the held-out test did not choose the elements, for people."""
    if diagnosis.declined and N.HYSTERESIS in diagnosis.declined.get("effects", []):
        return "not added: with them the held-out MAE would not fall"
    if result.implausible:
        return f"not added: {result.implausible}"
    if result.gain <= 0:
        return "not chosen: on held-out blocks the elements do not lower the network's residual"
    if diagnosis.added:
        instead = " and ".join({N.LEVEL: "a change of level", N.VELOCITY: "a smooth correction in speed"}[e]
                               for e in diagnosis.added)
        return (f"not chosen: {instead} explains the network's held-out residual (fricli diagnose --fix adds it); "
                f"the elements remove {100 * max(result.gain, 0.0):.1f} % more")
    if not result.significant:
        return (f"not chosen: on held-out blocks the elements remove {100 * max(result.gain, 0.0):.1f} % of the "
                "network's squared residual, not significantly more than a change of level or a smooth correction "
                "in speed")
    return (f"not chosen: they remove {100 * max(result.gain, 0.0):.1f} % of the held-out squared residual, less "
            f"than the {100 * diagnosis.min_gain:g} % asked for, or no more than a change of level or a smooth "
            "correction in speed")
