"""The augmented model (kind ``augmented``): a base model plus the terms of diagnosed effects.

    tau_f = p + sum_j coef[j] * term_j(signals, p),   p = base.predict(signals)

The base is a child model of any kind, stored in the same file; the terms are the regressor
terms of ``fricli.models.terms`` (JSON in the model's params, coefficients as the array
``coef``). Effects that a LuGre base can express as its own physical parameters (direction
asymmetry, temperature dependence, a change of level) are carried by the base instead and
listed under ``carried`` (base parameters refitted along with them under ``refitted``).
``predict`` carries the base's state and the held direction of motion from one batch of rows
to the next.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fricli.models import terms as T
from fricli.models import register
from fricli.models.base import FrictionModel


@register
class AugmentedModel(FrictionModel):
    kind = "augmented"

    def __init__(self, base: FrictionModel, terms: list[dict], coef: np.ndarray, *, effects: list[str] = (),
                 carried: list[str] = (), refitted: list[str] = (), params: dict | None = None):
        """base: the model to augment; terms: term specs; coef (len(terms),) [Nm per term unit];
        effects: names of the added effects in the order added; carried: those the base now
        expresses itself; refitted: base parameters refitted on the diagnosed log; params: the
        effects' physical parameters (for people and ``inspect``)."""
        coef = np.asarray(coef, dtype=np.float64).reshape(-1)
        if len(coef) != len(terms):
            raise ValueError(f"{len(terms)} terms but {len(coef)} coefficients")
        if not np.isfinite(coef).all():
            raise ValueError("non-finite coefficient")
        for term in terms:
            T.check(term)
        self.base = base
        self.terms = [dict(t) for t in terms]
        self.coef = coef
        self.effects = list(effects)
        self.carried = list(carried)
        self.refitted = list(refitted)
        self.params = dict(params or {})

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """tau_f (n,) [Nm]; state = (base state, held direction of motion)."""
        base_state, direction = (None, None) if state is None else state
        p, base_state = self.base.predict(signals, base_state)
        p = np.asarray(p, dtype=np.float64)
        if not self.terms:
            return p, (base_state, direction)
        cols = T.Columns(signals, p, direction)
        out = p + cols.matrix(self.terms) @ self.coef
        return out, (base_state, cols.state)

    def required_inputs(self) -> set[str]:
        return set(self.base.required_inputs()) | T.inputs(self.terms)

    def get_params(self) -> dict:
        return {"terms": self.terms, "effects": self.effects, "carried": self.carried, "refitted": self.refitted,
                "params": self.params}

    def get_arrays(self) -> dict[str, np.ndarray]:
        return {"coef": self.coef}

    def children(self) -> dict[str, FrictionModel]:
        return {"base": self.base}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "AugmentedModel":
        return cls(children["base"], params["terms"], arrays["coef"], effects=params.get("effects", []),
                   carried=params.get("carried", []), refitted=params.get("refitted", []),
                   params=params.get("params", {}))

    def describe(self) -> str:
        lines = [f"augmented model: {self.base.kind} base + {', '.join(self.effects) or 'no effects'}"]
        if self.carried:
            lines.append(f"  carried by the base as its own parameters: {', '.join(self.carried)}")
        if self.refitted:
            lines.append(f"  base parameters refitted with the added effects: {', '.join(self.refitted)}")
        for name, pars in self.params.items():
            text = ", ".join(f"{k} {'n/a' if v['value'] is None else format(v['value'], '.6g')} {v['unit']}".rstrip()
                             for k, v in pars.items())
            lines.append(f"  {name}: {text}")
        for term, c in zip(self.terms, self.coef):
            lines.append(f"  {term['name']:<24} {c:>12.6g}")
        lines.append("base:")
        lines.extend("  " + line for line in self.base.describe().splitlines())
        return "\n".join(lines)
