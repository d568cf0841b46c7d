"""What every candidate effect of the diagnosis is built on: the ``Context`` of one diagnosis (the
log's signals, the base model's prediction, units) and the ``Effect`` base class, with the
equivalent Coulomb and viscous levels of a model and the level terms shared by several effects."""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core import metrics
from fricli.models import terms as T


@dataclasses.dataclass
class Context:
    """What the effects may use: signals (n,), base prediction p (n,), units, column units."""

    signals: dict[str, np.ndarray]
    p: np.ndarray
    axis: str = "rotary"
    column_units: dict[str, str] = dataclasses.field(default_factory=dict)
    residual_ms: float = 0.0       # mean square of the model's residual [Nm^2] (0: not known)
    min_gain: float = 0.1          # share of it an effect must be able to remove to be tested
    presliding: float = 0.0        # the base model's pre-sliding travel [rad or m] (0: none, ``presliding_travel``)

    @property
    def tau_unit(self) -> str:
        return "Nm" if self.axis == "rotary" else "N"

    @property
    def q_unit(self) -> str:
        return "rad" if self.axis == "rotary" else "m"

    @property
    def v_unit(self) -> str:
        return self.q_unit + "/s"

    @property
    def fv_unit(self) -> str:
        return f"{self.tau_unit} s/{self.q_unit}"

    @property
    def inertia_unit(self) -> str:
        return "kg m^2" if self.axis == "rotary" else "kg"

    def model_inertia(self) -> float | None:
        """The joint's inertia as the robot model sees it: rms(tau_dyn) / rms(qdd) [kg m^2 or kg],
        None without tau_dyn or acceleration."""
        sig = self.signals
        if "tau_dyn" not in sig or "qdd" not in sig:
            return None
        a = float(np.sqrt(np.mean(np.square(sig["qdd"]))))
        return float(np.sqrt(np.mean(np.square(sig["tau_dyn"])))) / a if a > 0 else None

    def moving(self) -> np.ndarray:
        return metrics.in_motion(self.signals["qd"])

    def v_scale(self) -> float:
        """A typical high speed: the 95th percentile of |qd| over the rows in motion [rad/s]."""
        v = np.abs(self.signals["qd"][self.moving()])
        return float(np.percentile(v, 95)) if len(v) else 0.0


def presliding_travel(model, sig: dict[str, np.ndarray]) -> float:
    """The travel [rad or m] over which ``model``'s friction turns over after a reversal: a LuGre
    model's steady bristle deflection g/sigma0 at the log's median gravity load (g = fc + kc |tau_g|),
    a dissipative network's y_scale/sigma0; an augmented or adapted model's base's. 0 for a model
    without a pre-sliding state (its friction turns with sign(qd))."""
    while getattr(model, "base", None) is not None:
        model = model.base
    if all(hasattr(model, k) for k in ("fc", "kc", "sigma0")):
        load = float(np.median(np.abs(sig["tau_g"]))) if "tau_g" in sig else 0.0
        return max(model.fc + model.kc * load, 0.0) / model.sigma0
    sigma0 = getattr(model, "sigma0_", None)
    return float(model.y_scale_) / sigma0 if sigma0 else 0.0


def equivalent_levels(y: np.ndarray, qd: np.ndarray) -> dict[str, float]:
    """Coulomb and viscous levels of a friction curve y (n,) over velocity qd (n,):
    ``Fc``, ``Fv`` (both directions) and ``Fc+``, ``Fv+``, ``Fc-``, ``Fv-`` (one each), with
    tau = Fc*sign(qd) + Fv*qd, i.e. Fc- is the magnitude of the Coulomb level for qd < 0. Only
    the rows in motion (``metrics.in_motion``) count."""
    out = {}
    moving = metrics.in_motion(qd)
    for key, mask in (("", moving), ("+", moving & (qd > 0)), ("-", moving & (qd < 0))):
        if mask.sum() < 3:
            out["Fc" + key], out["Fv" + key] = float("nan"), float("nan")
            continue
        X = np.column_stack([np.sign(qd[mask]), qd[mask]])
        (fc, fv), *_ = np.linalg.lstsq(X, y[mask], rcond=None)
        out["Fc" + key], out["Fv" + key] = float(fc), float(fv)
    return out


def _par(value: float, unit: str) -> dict:
    """A parameter for the report; a value the log cannot determine is None (JSON null)."""
    value = float(value)
    return {"value": value if np.isfinite(value) else None, "unit": unit}


class Effect:
    """A candidate effect: a group of terms and how to read their coefficients."""

    name: str = ""
    #: combinations of simpler effects this one must beat on held-out data to be chosen
    rivals: tuple[tuple[str, ...], ...] = ()
    description: str = ""
    #: "friction", or "model" for an error of the robot model or the measurement (not friction)
    part: str = "friction"

    def applicable(self, ctx: Context) -> str | None:
        """None when the log supports the effect, else the reason it does not."""
        return None

    def implausible(self, params: dict[str, dict], ctx: Context) -> str | None:
        """None when the fitted parameters are physically plausible, else why not (and what
        else produces the same shape)."""
        return None

    def terms(self, ctx: Context, residual: np.ndarray) -> list[dict]:
        raise NotImplementedError

    def params(self, coef: dict[str, float], ctx: Context) -> dict[str, dict]:
        raise NotImplementedError

    def summary(self, params: dict[str, dict]) -> str:
        """One line for people."""
        return ", ".join(f"{k} {_fmt(v['value'])} {v['unit']}".rstrip() for k, v in params.items())


def _fmt(x: float | None) -> str:
    if x is None:
        return "n/a"
    if x == 0 or not np.isfinite(x):
        return f"{x:g}"
    digits = max(0, 3 - int(np.floor(np.log10(abs(x)))))
    return f"{x:.{min(digits, 6)}f}"


LEVEL_TERMS = [T.term("p", T.P), T.term("qd", T.sig_("qd"))]


def _level_coefs(coef: dict[str, float]) -> tuple[float, float]:
    return coef.get("p", 0.0), coef.get("qd", 0.0)
