"""The augmented model (kind ``augmented``): a base model plus the terms of diagnosed effects.

    tau_f = p + sum_j coef[j] * term_j(signals, p) + sum_k error_coef[k] * error_term_k(signals, p)

with p = base.predict(signals). The first sum is friction; the second corrects errors of the
robot model or the measurement that show in the friction target but are not friction (a
gravity torque off by a factor, a missing inertia, a torque offset). They are kept apart
(``error_terms``, ``error_coef``) because what consumes a friction model may need friction
alone: ``friction_only()`` drops them, ``predict_parts`` returns both. The base is a child
model of any kind, stored in the same file; the terms are the regressor terms of
``fricli.models.terms`` (JSON in the model's params, coefficients as arrays). Effects that a
LuGre base can express as its own physical parameters (direction asymmetry, temperature
dependence, a change of level) are carried by the base instead and listed under ``carried``
(base parameters refitted along with them under ``refitted``). ``predict`` carries the base's
state and what the terms hold (direction of motion, gravity torque) from one batch of rows to the
next.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fricli.core import effectnames
from fricli.models import register
from fricli.models import terms as T
from fricli.models.base import FrictionModel, predict_parts


@register
class AugmentedModel(FrictionModel):
    kind = "augmented"

    def __init__(self, base: FrictionModel, terms: list[dict], coef: np.ndarray, *, effects: list[str] = (),
                 carried: list[str] = (), refitted: list[str] = (), params: dict | None = None,
                 error_terms: list[dict] = (), error_coef: np.ndarray = (), errors: list[str] = ()):
        """base: the model to augment; terms: friction term specs; coef (len(terms),) [Nm per term
        unit]; effects: names of the added effects in the order added; carried: those the base now
        expresses itself; refitted: base parameters refitted on the diagnosed log; params: the
        effects' physical parameters (for people and ``inspect``); error_terms, error_coef: the
        robot-model error terms and their coefficients; errors: the effects they belong to."""
        self.base = base
        self.terms, self.coef = _checked(terms, coef)
        self.error_terms, self.error_coef = _checked(error_terms, error_coef)
        self.effects = list(effects)
        self.carried = list(carried)
        self.refitted = list(refitted)
        self.params = dict(params or {})
        self.errors = list(errors)

    def predict_parts(self, signals: dict[str, np.ndarray], state: Any = None):
        """(friction (n,), robot-model error (n,), state) [Nm]; their sum is ``predict``."""
        base_state, direction = (None, None) if state is None else state
        base_friction, base_error, base_state = predict_parts(self.base, signals, base_state)
        if not self.terms and not self.error_terms:
            return base_friction, base_error, (base_state, direction)
        cols = T.Columns(signals, base_friction + base_error, direction)
        friction = base_friction + cols.combination(self.terms, self.coef)
        error = base_error + cols.combination(self.error_terms, self.error_coef)
        return friction, error, (base_state, cols.state)

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """tau_f (n,) [Nm] with the robot-model errors corrected (what the log's friction target
        holds); state = (base state, held direction of motion)."""
        friction, error, state = self.predict_parts(signals, state)
        return friction + error, state

    def friction_only(self) -> "AugmentedModel":
        """The same model without the robot-model error terms: friction alone."""
        friction = [e for e in self.effects if e not in self.errors]
        params = {k: v for k, v in self.params.items() if k not in self.errors}
        return AugmentedModel(self.base, self.terms, self.coef, effects=friction, carried=self.carried,
                              refitted=self.refitted, params=params)

    def required_inputs(self) -> set[str]:
        return set(self.base.required_inputs()) | T.inputs(self.terms) | T.inputs(self.error_terms)

    def get_params(self) -> dict:
        return {"terms": self.terms, "effects": self.effects, "carried": self.carried, "refitted": self.refitted,
                "params": self.params, "error_terms": self.error_terms, "errors": self.errors}

    def get_arrays(self) -> dict[str, np.ndarray]:
        return {"coef": self.coef, "error_coef": self.error_coef}

    def children(self) -> dict[str, FrictionModel]:
        return {"base": self.base}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "AugmentedModel":
        def names(key):   # effect names as registered (an earlier name read as the one it stands for)
            return [effectnames.canonical(e) for e in params.get(key, [])]

        return cls(children["base"], params["terms"], arrays["coef"], effects=names("effects"),
                   carried=names("carried"), refitted=params.get("refitted", []),
                   params={effectnames.canonical(k): v for k, v in params.get("params", {}).items()},
                   error_terms=params.get("error_terms", []), error_coef=arrays.get("error_coef", np.zeros(0)),
                   errors=names("errors"))

    def describe(self) -> str:
        friction = [e for e in self.effects if e not in self.errors]
        lines = [f"augmented model: {self.base.kind} base + {', '.join(friction) or 'no friction effects'}"]
        if self.carried:
            lines.append(f"  carried by the base as its own parameters: {', '.join(self.carried)}")
        if self.refitted:
            lines.append(f"  base parameters refitted with the added effects: {', '.join(self.refitted)}")
        lines.extend(_effect_lines(self.params, friction, self.terms, self.coef))
        if self.errors:
            lines.append(f"robot-model errors (not friction): {', '.join(self.errors)}")
            lines.extend(_effect_lines(self.params, self.errors, self.error_terms, self.error_coef))
        lines.append("base:")
        lines.extend("  " + line for line in self.base.describe().splitlines())
        return "\n".join(lines)


def _effect_lines(params: dict, names: list[str], terms: list[dict], coef: np.ndarray) -> list[str]:
    lines = []
    for name in names:
        pars = params.get(name, {})
        text = ", ".join(f"{k} {'n/a' if v['value'] is None else format(v['value'], '.6g')} {v['unit']}".rstrip()
                         for k, v in pars.items())
        lines.append(f"  {name}: {text}")
    for term, c in zip(terms, coef):
        lines.append(f"  {term['name']:<24} {c:>12.6g}")
    return lines


def _checked(terms, coef) -> tuple[list[dict], np.ndarray]:
    coef = np.asarray(coef, dtype=np.float64).reshape(-1)
    if len(coef) != len(terms):
        raise ValueError(f"{len(terms)} terms but {len(coef)} coefficients")
    if not np.isfinite(coef).all():
        raise ValueError("non-finite coefficient")
    for term in terms:
        T.check(term)
    return [dict(t) for t in terms], coef
