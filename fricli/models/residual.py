"""The adapted model: any base model plus a network that learned its residual (paper, L_add).

    tau_f = base(log) + NN_add(tau_g, sign(qd))

NN_add has one hidden layer of 30 ELU units and is trained with Adam (lr 0.01) in
mini-batches on target - base(log) over a short log of the new dynamics. The base is kept
unchanged, so what it learned about the velocity dependence is kept too; NN_add only sees the
gravity torque and the direction of motion, which one movement at one velocity covers.

Both parts are children in the model file ("base/...", "add/..."); the base may be of any kind,
with its own state (e.g. the LuGre bristles), which ``predict`` carries across batches.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.models.neural import MLPFriction

ADD_INPUTS = ("tau_g", "sign(qd)")


def indent(text: str, prefix: str = "  ") -> str:
    return "\n".join(prefix + line for line in text.splitlines())


@register
class ResidualFriction(FrictionModel):
    """base + add. Hyperparameters of NN_add as keyword arguments; ``fit`` trains NN_add."""

    kind = "residual"

    def __init__(self, base: FrictionModel, *, hidden_sizes=(30,), epochs: int = 200, batch_size: int = 64,
                 lr: float = 0.01, min_speed: float | None = None, units: dict | None = None,
                 add: FrictionModel | None = None):
        self.base = base
        self.hidden_sizes, self.epochs, self.batch_size, self.lr = tuple(hidden_sizes), epochs, batch_size, lr
        self.min_speed, self.units = min_speed, dict(units or {})
        self.add = add

    def fit(self, sig: dict[str, np.ndarray], target: np.ndarray, train_rows: np.ndarray, val_rows: np.ndarray,
            *, rng: np.random.Generator, on_eval: Callable | None = None,
            base_pred: np.ndarray | None = None) -> "ResidualFriction":
        """Train NN_add on target - base over the rows given; ``sig`` is the whole log, so a
        stateful base runs over it in order. ``base_pred`` may be given if already computed."""
        if base_pred is None:
            base_pred = self.base.predict(sig)[0]
        residual = np.asarray(target, dtype=np.float64) - base_pred
        add = MLPFriction(inputs=ADD_INPUTS, hidden_sizes=self.hidden_sizes, steps=None, epochs=self.epochs,
                          batch_size=self.batch_size, lr=self.lr, units=self.units)
        pick = lambda rows: {k: v[rows] for k, v in sig.items() if k in ("t", "qd", "tau_g")}  # noqa: E731
        add.fit(pick(train_rows), residual[train_rows], pick(val_rows), residual[val_rows], rng=rng, on_eval=on_eval)
        self.add = add
        return self

    def predict(self, signals: dict[str, np.ndarray], state=None):
        """tau_f (n,) [Nm] = base + add; the state is the base's."""
        tau, state = self.base.predict(signals, state)
        return tau + self.add.predict(signals)[0], state

    def required_inputs(self) -> set[str]:
        return set(self.base.required_inputs()) | set(self.add.required_inputs())

    def children(self) -> dict[str, FrictionModel]:
        return {"base": self.base, "add": self.add}

    def get_params(self) -> dict:
        return {"add_inputs": list(ADD_INPUTS), "hidden_sizes": list(self.hidden_sizes), "epochs": self.epochs,
                "batch_size": self.batch_size, "lr": self.lr, "min_speed": self.min_speed, "units": self.units}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "ResidualFriction":
        return cls(children["base"], hidden_sizes=params.get("hidden_sizes", (30,)), epochs=params.get("epochs", 200),
                   batch_size=params.get("batch_size", 64), lr=params.get("lr", 0.01),
                   min_speed=params.get("min_speed"), units=params.get("units"), add=children["add"])

    def describe(self) -> str:
        lines = ["residual: base model + NN_add(tau_g, sign(qd)) learned on the base's residual"]
        if self.min_speed is not None:
            unit = self.units.get("qd", "rad/s")
            lines.append(f"  NN_add trained on rows moving faster than {self.min_speed:.4g} {unit}")
        lines += ["  base:", indent(self.base.describe(), "    "), "  add:", indent(self.add.describe(), "    ")]
        return "\n".join(lines)
