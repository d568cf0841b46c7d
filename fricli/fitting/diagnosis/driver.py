"""The diagnosis driver: residual of a model on a log -> ranked effects (``fix.augment`` turns
the result into the augmented model)."""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core import effectnames as N
from fricli.core import logs, metrics
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.diagnosis import selection, structure
from fricli.models import terms as T
from fricli.core.errors import DataError, ModelFileError

DEFAULT_FOLDS = 10
DEFAULT_MIN_GAIN = 0.1
DEFAULT_ALPHA = 0.01
MIN_ROWS_PER_FOLD = 20
INTERVAL_LEVEL = 0.95
WORST_GAIN = -1.0                  # gains are clipped here: an effect that doubles the residual or worse is "worse"
#: effects that the same log may explain about equally, and what tells them apart
TWINS = {(N.GRAVITY, N.QUADRANT): "rests with a varying tau_g"}
#: robot-model effects that a calibration of the URDF (``fricli calibrate``) corrects where they live
CALIBRATED_EFFECTS = (N.GRAVITY, N.ACCELERATION)


@dataclasses.dataclass
class EffectResult:
    name: str
    significant: bool
    gain: float                    # share of the model's held-out squared residual it explains
    params: dict[str, dict]        # {name: {"value", "unit"}}
    added: bool
    summary: str
    terms: list[dict]
    step_gain: float = 0.0         # share of what was left of it when scored (when added, or at the end)
    part: str = "friction"         # or "model": an error of the robot model or the measurement
    implausible: str | None = None  # why the fitted parameters are out of plausible range (None: plausible)


@dataclasses.dataclass
class Diagnosis:
    """What ``diagnose`` found. ``effects`` is ranked: the added effects in the order they were
    added, then the others by the share they would still explain on top of them."""

    effects: list[EffectResult]
    added: list[str]
    mae_before: float              # held-out MAE of the model's friction [Nm or N]
    mae_after: float               # held-out MAE with the added effects fitted on the other blocks
    terms: list[dict]              # the added effects' terms, in order
    coef: dict[str, float]         # their coefficients fitted on the whole log
    rows: int
    folds: int
    min_gain: float
    alpha: float
    skipped: dict[str, str]        # effects that do not apply to this log, with the reason
    tau_unit: str
    alone: dict[str, float] = dataclasses.field(default_factory=dict)   # each candidate's gain on its own
    intervals: dict[str, list[float]] = dataclasses.field(default_factory=dict)  # mae_before, mae_after, cut
    unexplained: structure.Structure | None = None    # structure left in the held-out residual
    notes: list[str] = dataclasses.field(default_factory=list)   # for people: what the log cannot decide
    suspected: list[str] = dataclasses.field(default_factory=list)  # chosen, but implausible: not added
    # chosen, but not added because the held-out MAE would not fall: {"effects": [...], "mae_after": MAE}
    declined: dict = dataclasses.field(default_factory=dict)

    @property
    def cut(self) -> float:
        """Share of the held-out MAE the added effects remove."""
        return 1.0 - self.mae_after / self.mae_before if self.mae_before > 0 else 0.0

    @property
    def errors(self) -> list[str]:
        """Added effects that are errors of the robot model or the measurement, not friction."""
        return [e.name for e in self.effects if e.added and e.part == "model"]

    def error_term_names(self) -> set[str]:
        return {t["name"] for e in self.effects if e.added and e.part == "model" for t in e.terms}

    def to_json(self) -> dict:
        """The ``--json`` schema."""
        out = {"mae_before": self.mae_before, "mae_after": self.mae_after, "cut": self.cut,
               "intervals": {"level": INTERVAL_LEVEL, **self.intervals},
               "effects": [{"name": e.name, "significant": e.significant, "gain": e.gain, "params": e.params,
                            "part": e.part, "implausible": e.implausible} for e in self.effects],
               "added": list(self.added), "model_errors": self.errors, "suspected": list(self.suspected), "declined": dict(self.declined),
               "skipped": dict(self.skipped), "notes": list(self.notes)}
        if self.unexplained is not None:
            out["unexplained_share"] = self.unexplained.share
            out["unexplained"] = self.unexplained.to_json()
        return out


def column_units(table) -> dict[str, str]:
    out = {}
    for field in table.schema:
        unit = logs.field_unit(field)
        if unit:
            out[field.name] = unit
    return out


def residual(model, log: logs.Log) -> tuple[np.ndarray, np.ndarray]:
    """(tau_f_pred, friction_target - tau_f_pred), shapes (n,)."""
    sig = log.signals
    pred = np.asarray(model.predict(sig)[0], dtype=np.float64)
    if pred.shape != sig["t"].shape or not np.isfinite(pred).all():
        raise ModelFileError(f"the model's prediction on {log.name} is not finite")
    return pred, logs.friction_target(sig) - pred


def diagnose(model, log: logs.Log, *, folds: int = DEFAULT_FOLDS, min_gain: float = DEFAULT_MIN_GAIN,
             alpha: float = DEFAULT_ALPHA, only: list[str] | None = None,
             max_effects: int | None = None, accept_implausible: bool = False) -> Diagnosis:
    """Test the residual of ``model`` on ``log`` against the candidate effects.

    folds: contiguous folds of the blocked cross-validation over time; min_gain: share of the
    remaining held-out squared residual an effect must remove to be added; alpha: significance
    level; only: effect names to test (``column`` = every column effect); max_effects: stop
    after adding this many. An effect chosen with parameters out of plausible range
    (``Effect.implausible``, e.g. a gravity scale beyond +-30 %) is a suspicion: reported, not
    added, and the selection runs again without it, unless ``accept_implausible``.
    """
    n = len(log)
    if folds < 3:
        raise ValueError("folds must be at least 3")
    if n < folds * MIN_ROWS_PER_FOLD:
        raise DataError(f"too few rows to diagnose ({n}; need at least {folds * MIN_ROWS_PER_FOLD} "
                        f"for {folds} folds)")
    sig = log.signals
    if "q" in sig and metrics.held_still(sig["q"][:, None])[0]:
        span = float(np.ptp(sig["q"]))
        unit = "m" if log.axis == "linear" else "rad"
        raise DataError(f"the joint's position spans {span:.3g} {unit}, less than {metrics.HELD_SPAN:g} {unit}, "
                        "over the whole log: it is held still, and the torque "
                        "that holds it (stiction, a push on the arm) is no friction to diagnose; diagnose a log in "
                        "which it moves")
    p, r = residual(model, log)
    ctx = E.Context(sig, p, log.axis, column_units(log.table), residual_ms=float(np.mean(r * r)),
                    min_gain=min_gain, presliding=E.presliding_travel(model, sig))
    lib = E.library(sig, only)
    skipped = {}
    usable = []
    for effect in lib:
        reason = effect.applicable(ctx)
        if reason:
            skipped[effect.name] = reason
        else:
            usable.append(effect)
    design = selection.Design(r, folds)
    registry: dict[str, dict] = {}
    cache: dict[str, list[str]] = {}

    columns = T.Columns(sig, p)

    def add_terms(term_list: list[dict]) -> list[str]:
        names = []
        for term in term_list:
            if term["name"] not in registry:
                registry[term["name"]] = term
                design.add(term["name"], columns.value(term))
            names.append(term["name"])
        return names

    def candidates(chosen_terms, current):
        out = []
        for effect in usable:
            if effect.name in suspects:
                continue
            if effect.name in cache:
                names = cache[effect.name]
            else:
                names = add_terms(effect.terms(ctx, current))
                if not isinstance(effect, E.Position):
                    cache[effect.name] = names
            out.append(selection.Candidate(effect.name, names, effect.rivals))
        return out

    by_name = {e.name: e for e in usable}

    def result(name, significant, gain, step_gain, params, names, added):
        effect = by_name[name]
        return EffectResult(name, significant, max(gain, WORST_GAIN), params, added, effect.summary(params),
                            [registry[t] for t in names], max(step_gain, WORST_GAIN), effect.part,
                            effect.implausible(params, ctx))

    suspects: dict[str, EffectResult] = {}
    while True:
        sel = selection.forward(design, candidates, alpha=alpha, min_gain=min_gain, max_effects=max_effects,
                                twins=tuple(TWINS))
        coef = design.fit(sel.terms)
        results = [result(step.name, True, step.gain, step.step_gain,
                          by_name[step.name].params({t: coef[t] for t in step.terms}, ctx), step.terms, True)
                   for step in sel.steps]
        bad = [e for e in results if e.implausible]
        if accept_implausible or not bad:
            break
        for e in bad:
            suspects[e.name] = dataclasses.replace(e, added=False)
    others = []
    for name, sc in sel.final.items():
        params = by_name[name].params(_marginal_fit(design, sel.terms, sc.terms), ctx)
        others.append(result(name, sc.significant, sc.gain, sc.step_gain, params, sc.terms, False))
    others.sort(key=lambda e: -e.gain)
    left = r - design.heldout_prediction(sel.terms) if sel.terms else r
    mae_before = float(np.mean(np.abs(r)))
    mae_after = float(np.mean(np.abs(left))) if sel.terms else mae_before
    notes = _twin_notes(design, sel, cache, alpha, min_gain, set(suspects))
    added, terms, declined = list(sel.added), list(sel.terms), {}
    if added and mae_after >= mae_before:
        # less squared error but a larger typical error: a few large residuals (an edge, a
        # transient) drive the effects, and adding them would make the model worse on most rows
        declined = {"effects": added, "mae_after": mae_after}
        results = [dataclasses.replace(e, added=False) for e in results]
        added, terms, left, mae_after, notes = [], [], r, mae_before, []
    return Diagnosis(effects=results + list(suspects.values()) + others, added=added,
                     mae_before=mae_before, mae_after=mae_after,
                     terms=[registry[t] for t in terms], coef={t: coef[t] for t in terms}, rows=n,
                     folds=folds, min_gain=min_gain, alpha=alpha, skipped=skipped, tau_unit=ctx.tau_unit,
                     alone={name: max(sc.gain, WORST_GAIN) for name, sc in sel.first.items()},
                     intervals=fold_intervals(r, left, folds),
                     unexplained=structure.analyse(left, sig, alpha),
                     notes=notes, suspected=list(suspects), declined=declined)


def _twin_notes(design, sel, cache: dict[str, list[str]], alpha: float, min_gain: float,
                suspected: set[str] = frozenset()) -> list[str]:
    """A note for each added effect whose twin (``TWINS``) would explain the log nearly as well, or
    better where the twin was ``suspected`` (declined as implausible): the added one may then carry
    the declined correction under its own name."""
    notes = []
    for pair, evidence in TWINS.items():
        for a, b in (pair, pair[::-1]):
            if a not in sel.added or b in sel.added or a not in cache or b not in cache:
                continue
            others = [t for t in sel.terms if t not in cache[a]]
            swapped = others + [t for t in cache[b] if t not in others]
            cmp = selection.compare(design.sse(sel.terms), design.sse(swapped), alpha)
            if b in suspected:
                worse = f"{abs(100 * cmp.gain):.0f} % more" if cmp.gain < 0 else "no less"
                notes.append(f"{a} added where the suspicious {b} explains this log as well or better ({a} leaves "
                             f"{worse} held-out squared error): {a} may carry that error of the robot model as "
                             f"friction; check the robot model first ({evidence} would tell them apart)")
            elif not cmp.clear(min_gain):
                gain = 100 * cmp.gain
                than = (f"{a} leaves {abs(gain):.0f} % {'less' if gain > 0 else 'more'} held-out squared error"
                        if abs(gain) >= 0.5 else "both leave the same held-out squared error to within 0.5 %")
                notes.append(f"{a} or {b}: this log does not tell them apart clearly ({than}); {evidence} would")
    return notes


def fold_intervals(before: np.ndarray, after: np.ndarray, folds: int) -> dict[str, list[float]]:
    """Intervals (INTERVAL_LEVEL, Student t over the folds of the blocked cross-validation) of
    the held-out MAE before and after, from the folds' MAEs, and of the cut (1 - after/before),
    from the folds' cuts: ``{"mae_before": [lo, hi], "mae_after": [lo, hi], "cut": [lo, hi]}``."""
    from scipy import special  # the t quantile of scipy.stats.t.ppf, without importing scipy.stats (a quarter second)

    edges = selection.fold_bounds(len(before), folds)
    b = np.array([np.mean(np.abs(before[i:j])) for i, j in zip(edges[:-1], edges[1:])])
    a = np.array([np.mean(np.abs(after[i:j])) for i, j in zip(edges[:-1], edges[1:])])
    q = float(special.stdtrit(folds - 1, 0.5 + INTERVAL_LEVEL / 2)) / float(np.sqrt(folds))

    def around(x):
        half = q * float(np.std(x, ddof=1))
        return [float(x.mean()) - half, float(x.mean()) + half]

    cut = around(1.0 - a / np.where(b > 0, b, 1.0))
    return {"mae_before": around(b), "mae_after": around(a), "cut": [cut[0], min(cut[1], 1.0)]}


def _marginal_fit(design: selection.Design, chosen: list[str], names: list[str]) -> dict[str, float]:
    """Coefficients of ``names`` fitted to what the chosen terms leave of the residual."""
    left = design.r - design.fitted(chosen)
    sub = selection.Design(left, design.folds)
    for name in names:
        sub.add(name, design.cols[design.names.index(name)])
    return sub.fit(names)


def robot_model_joints(results: dict) -> list:
    """The joints of a whole-arm diagnosis (``{joint: Diagnosis.to_json()}``) whose gravity or
    acceleration effect was chosen, added or held back as implausible: what the robot model gets
    wrong there, rather than their friction."""
    return [j for j, r in results.items()
            if any(e in CALIBRATED_EFFECTS for e in list(r.get("added", [])) + list(r.get("suspected", [])))]
