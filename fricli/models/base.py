"""The interface every friction model kind implements."""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

#: the parameters the physical model kinds (lugre, linear, gms) share, declared once:
#: name -> (unit on a rotary axis, unit on a linear axis, meaning)
PARAMETERS = {
    "fc": ("Nm", "N", "Coulomb friction"),
    "fs": ("Nm", "N", "static (stiction) friction"),
    "fst": ("Nm", "N", "Stribeck excess friction near rest"),
    "vs": ("rad/s", "m/s", "Stribeck velocity"),
    "delta": ("-", "-", "Stribeck exponent"),
    "fv": ("Nm s/rad", "N s/m", "viscous friction"),
    "offset": ("Nm", "N", "torque offset"),
    "kc": ("Nm/Nm", "N/N", "load slope of Coulomb friction (per |tau_g|)"),
    "ks": ("Nm/Nm", "N/N", "load slope of static friction (per |tau_g|)"),
    "sigma0": ("Nm/rad", "N/m", "bristle stiffness"),
    "sigma1": ("Nm s/rad", "N s/m", "bristle (micro-)damping"),
    "fc_neg": ("Nm", "N", "Coulomb friction for negative velocity"),
    "fs_neg": ("Nm", "N", "static friction for negative velocity"),
    "fv_neg": ("Nm s/rad", "N s/m", "viscous friction for negative velocity"),
    "t_ref": ("degC", "degC", "reference temperature"),
    "alpha_c": ("1/K", "1/K", "temperature coefficient of Coulomb/static friction"),
    "alpha_v": ("1/K", "1/K", "temperature coefficient of viscous friction (exponential)"),
    "q_lo": ("rad", "m", "start of the position range of the position terms"),
    "q_hi": ("rad", "m", "end of the position range of the position terms"),
}


def parameter_info(*names: str, **meanings: str) -> dict[str, tuple[str, str, str]]:
    """``PARAMETERS`` of ``names``, in that order; ``meanings``: a kind's own meaning of a parameter."""
    return {name: PARAMETERS[name][:2] + (meanings.get(name, PARAMETERS[name][2]),) for name in names}


class FrictionModel:
    """A friction model: ``predict`` maps a log's signals to tau_f [Nm] (positive along motion).

    Signals are float64 arrays of shape (n,) in canonical units (see ``fricli.core.logs``).
    ``state`` carries history (e.g. the LuGre bristle state) from one batch of rows to the
    next; stateless kinds ignore it and return None.
    """

    kind: ClassVar[str] = ""

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        raise NotImplementedError

    def required_inputs(self) -> set[str]:
        """Signal names ``predict`` reads."""
        raise NotImplementedError

    def get_params(self) -> dict:
        """JSON-serialisable hyperparameters and scalar parameters."""
        return {}

    def get_arrays(self) -> dict[str, np.ndarray]:
        """Array parameters by name (no '/' in names)."""
        return {}

    def children(self) -> dict[str, "FrictionModel"]:
        return {}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict[str, "FrictionModel"]):
        raise NotImplementedError

    def describe(self) -> str:
        """One line per parameter with units, for people."""
        return self.kind

    def __call__(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        return self.predict(signals)[0]


def predict_parts(model: FrictionModel, signals: dict[str, np.ndarray], state: Any = None):
    """(friction (n,), robot-model error (n,), state) [Nm] of any model: its own ``predict_parts``
    where it keeps robot-model errors apart (``AugmentedModel``, and a model over one), else its
    prediction as friction and no error."""
    own = getattr(model, "predict_parts", None)
    if own is not None:
        return own(signals, state)
    tau, state = model.predict(signals, state)
    tau = np.asarray(tau, dtype=np.float64)
    return tau, np.zeros_like(tau), state
