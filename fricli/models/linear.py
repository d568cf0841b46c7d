"""The standard linear friction model (kind ``linear``): viscous, Coulomb and an offset,

    tau_f = Fv*qd + Fc*sign(qd) + offset                                           [Nm]

or, asymmetric (separate levels for each direction of motion, no offset: it would be the
difference of the two Coulomb levels),

    tau_f = Fv*qd + Fc      for qd > 0,   Fv_neg*qd - Fc_neg   for qd < 0,   0 at rest   [Nm]

the model of the inverse-dynamics identification literature (e.g. the EMPS benchmark). Both are
linear in their parameters: ``fit`` is ordinary least squares on the rows in motion
(``fricli.core.metrics.in_motion``) against the friction target (``fricli.core.logs.friction_target``).
Stateless. A linear axis uses the same equations in m/s and N.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fricli.core import logs, metrics
from fricli.core.errors import FitError
from fricli.models import register
from fricli.models.base import FrictionModel, parameter_info

# name -> (unit on a rotary axis, unit on a linear axis, meaning)
PARAM_INFO = parameter_info("fv", "fc", "offset", "fv_neg", "fc_neg")
SYMMETRIC = ("fv", "fc", "offset")
ASYMMETRIC = ("fv", "fc", "fv_neg", "fc_neg")


def unit_of(name: str, axis: str = "rotary") -> str:
    rot, lin, _ = PARAM_INFO[name]
    return lin if axis == "linear" else rot


def regressors(qd: np.ndarray, asymmetric: bool = False) -> list[np.ndarray]:
    """The columns (each (n,)) that multiply the parameters ``ASYMMETRIC`` or ``SYMMETRIC``, in
    that order, for velocities qd (n,): tau_f is their sum weighted by the parameters."""
    qd = np.asarray(qd, dtype=np.float64)
    if asymmetric:
        pos, neg = qd > 0.0, qd < 0.0
        return [np.where(pos, qd, 0.0), pos.astype(np.float64), np.where(neg, qd, 0.0), -neg.astype(np.float64)]
    return [qd, np.sign(qd), np.ones_like(qd)]


@register
class LinearFriction(FrictionModel):
    """tau_f = Fv*qd + Fc*sign(qd) + offset, or its asymmetric form (module doc); parameters in
    canonical units (Nm s/rad, Nm; N s/m, N on a linear axis)."""

    kind = "linear"

    def __init__(self, fv: float, fc: float, offset: float = 0.0, *, fv_neg: float | None = None,
                 fc_neg: float | None = None, axis: str = "rotary"):
        if (fv_neg is None) != (fc_neg is None):
            raise ValueError("an asymmetric model needs both fv_neg and fc_neg")
        if axis not in ("rotary", "linear"):
            raise ValueError(f"axis must be rotary or linear, not {axis!r}")
        self.fv, self.fc, self.offset = float(fv), float(fc), float(offset)
        self.fv_neg = None if fv_neg is None else float(fv_neg)
        self.fc_neg = None if fc_neg is None else float(fc_neg)
        self.axis = axis
        if self.asymmetric and self.offset != 0.0:
            raise ValueError("the asymmetric model has no offset")
        if not np.isfinite(self.coefficients()).all():
            raise ValueError("non-finite parameter")

    @property
    def asymmetric(self) -> bool:
        return self.fv_neg is not None

    def names(self) -> tuple[str, ...]:
        return ASYMMETRIC if self.asymmetric else SYMMETRIC

    def coefficients(self) -> np.ndarray:
        """The parameters (k,) in the order of ``regressors``."""
        return np.array([getattr(self, k) for k in self.names()], dtype=np.float64)

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """Friction tau_f (n,) [Nm] for qd (n,) [rad/s]: the regressors weighted by the
        parameters, summed left to right (the exported C code sums in the same order)."""
        out = np.zeros(len(signals["qd"]))
        for coef, column in zip(self.coefficients(), regressors(signals["qd"], self.asymmetric)):
            out += coef * column
        return out, None

    def required_inputs(self) -> set[str]:
        return {"qd"}

    def parameters(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in self.names()}

    def get_params(self) -> dict:
        return {**self.parameters(), "axis": self.axis}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "LinearFriction":
        unknown = set(params) - set(PARAM_INFO) - {"axis"}
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}")
        from fricli.models.lugre import check_numbers

        check_numbers(params, ("fv", "fc"), ("offset", "fv_neg", "fc_neg"))
        return cls(params["fv"], params["fc"], params.get("offset", 0.0), fv_neg=params.get("fv_neg"),
                   fc_neg=params.get("fc_neg"), axis=params.get("axis", "rotary"))

    def describe(self) -> str:
        lines = [f"linear friction model, {'asymmetric' if self.asymmetric else 'symmetric'} ({self.axis} axis)"]
        for name, value in self.parameters().items():
            lines.append(f"  {name:<8} {value:>12.6g} {unit_of(name, self.axis):<9} {PARAM_INFO[name][2]}")
        return "\n".join(lines)


def fit(signals: dict[str, np.ndarray], *, asymmetric: bool = False,
        axis: str = "rotary") -> tuple[LinearFriction, dict]:
    """Least-squares fit on the rows in motion of a log's signals (canonical units). Returns the
    model and its fit record: errors [Nm] over all rows and (``moving``) the rows in motion,
    ``moving_rows`` and the condition number of the regressor."""
    qd = np.asarray(signals["qd"], dtype=np.float64)
    moving = metrics.moving_both_ways(qd, "the linear model")
    y = logs.friction_target(signals)
    X = np.column_stack(regressors(qd[moving], asymmetric))
    theta, *_ = np.linalg.lstsq(X, y[moving], rcond=None)
    names = ASYMMETRIC if asymmetric else SYMMETRIC
    try:
        model = LinearFriction(**dict(zip(names, theta.tolist())), axis=axis)
    except ValueError as exc:
        raise FitError(f"the linear fit gave unusable parameters ({exc})") from None
    pred = model.predict(signals)[0]
    record = metrics.errors(y, pred)
    record.update(moving=metrics.errors(y[moving], pred[moving]), moving_rows=int(moving.sum()),
                  condition=float(np.linalg.cond(X)), notes=speed_notes(qd[moving], asymmetric, axis))
    return model, record


def speed_notes(qd: np.ndarray, asymmetric: bool, axis: str = "rotary") -> list[str]:
    """A note when the velocities in motion qd (n,) do not separate Coulomb from viscous friction:
    one speed in each direction (symmetric, with its offset) or in either (asymmetric), one speed
    meaning the 5th to 95th percentile of |qd| within a factor 1.5 (``identify``'s rule)."""
    one = []
    for side in (qd > 0, qd < 0):
        lo, hi = np.percentile(np.abs(qd[side]), [5, 95])
        one.append(hi < 1.5 * lo)
    if not (any(one) if asymmetric else all(one)):
        return []
    unit = "m/s" if axis == "linear" else "rad/s"
    speeds = " and ".join(f"{np.median(np.abs(qd[side])):.3g}" for side in (qd > 0, qd < 0))
    which = "each direction" if all(one) else ("the positive" if one[0] else "the negative") + " direction"
    terms = "Fc and Fv of that direction" if asymmetric else "Fc, Fv and the offset"
    return [f"the rows in motion cover one speed in {which} (about {speeds} {unit} out and back): "
            f"the log does not separate Coulomb from viscous friction, {terms} rest on the rows "
            "that accelerate between; log motion at several speeds to identify them"]
