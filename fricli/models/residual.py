"""The adapted model: any base model plus a network that learned its residual (paper, L_add).

NN_add(tau_g, sign(qd)) has one hidden layer of 30 ELU units and is trained with Adam (lr
0.01) in mini-batches on target - base(log) over the moving rows of a short log of the new
dynamics. The base is kept unchanged, so what it learned about the velocity dependence is kept
too; NN_add only sees the gravity torque and the direction of motion, which one movement at one
velocity covers. Two ways to combine them (``combine``):

    dissipative  (default) the paper's sum, held against the motion above a pre-sliding speed:
                     p = base(log) + NN_add,   s = sign(qd)
                     m = T softplus(s p / T)                                   >= 0
                     w = (1 - (qd / v_ps)^2)^2 for |qd| < v_ps, else 0         (C1 switch)
                     tau_f = w p + (1 - w) s m
                 For |qd| >= v_ps, tau_f = s m: tau_f qd >= 0 for every input and any base.
                 Where the sum already acts against the motion by more than a few T (any real
                 friction level) m = s p, so tau_f is the paper's sum; at rest (w = 1) it is the
                 sum too, with the base's state (e.g. the LuGre bristles). T = SOFTNESS * mean
                 |target| of the training rows; v_ps is the base's pre-sliding speed if it has
                 one, else PRESLIDING_SHARE of the slowest training speed.
    additive     the paper's form, tau_f = base(log) + NN_add (model files written before the
                 dissipative form load as this). The default over a base that reads other
                 joints' velocities (a coupled group's member, ``fricli.models.coupled``): a
                 joint whose motor turns with another joint has friction along its own motion
                 whenever that motor turns against it.

A base that keeps robot-model errors apart from its friction (``fricli.models.augmented``: a
missing inertia, an offset) has them added after the combination, as they are: only friction
is held against the motion.

Both parts are children in the model file ("base/...", "add/..."); the base may be of any kind,
with its own state (e.g. the LuGre bristles), which ``predict`` carries across batches.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.models import register
from fricli.models.base import FrictionModel, predict_parts
from fricli.models.neural import MLPFriction
from fricli.numerics.nn.activations import softplus

ADD_INPUTS = ("tau_g", "sign(qd)")
COMBINE = ("dissipative", "additive")
SOFTNESS = 0.01          # T of the dissipative form, as a share of the mean |friction target|
PRESLIDING_SHARE = 0.1   # v_ps for a base without its own: this share of the slowest training speed


def soft_magnitude(x: np.ndarray, width: float) -> np.ndarray:
    """width * softplus(x / width) (n,), >= 0, = x for x >> width."""
    return width * softplus(x / width)


def indent(text: str, prefix: str = "  ") -> str:
    return "\n".join(prefix + line for line in text.splitlines())


@register
class ResidualFriction(FrictionModel):
    """base + add. Hyperparameters of NN_add as keyword arguments; ``fit`` trains NN_add."""

    kind = "residual"

    def __init__(self, base: FrictionModel, *, hidden_sizes=(30,), epochs: int = 200, batch_size: int = 64,
                 lr: float = 0.01, min_speed: float | None = None, units: dict | None = None,
                 add: FrictionModel | None = None, combine: str | None = None):
        """``combine``: "dissipative" or "additive"; by default dissipative, unless ``base`` reads other
        joints' velocities (a coupled group's member): that joint's friction may act along its own
        motion (its motor turns with another joint), which the dissipative form would forbid."""
        self.base = base
        self.hidden_sizes, self.epochs, self.batch_size, self.lr = tuple(hidden_sizes), epochs, batch_size, lr
        self.min_speed, self.units = min_speed, dict(units or {})
        self.add = add
        self.combine = combine or ("additive" if any(name.startswith("qd@") for name in base.required_inputs())
                                   else "dissipative")

    def fit(self, sig: dict[str, np.ndarray], target: np.ndarray, train_rows: np.ndarray, val_rows: np.ndarray,
            *, rng: np.random.Generator, on_eval: Callable | None = None,
            base_pred: np.ndarray | None = None) -> "ResidualFriction":
        """Train NN_add on target - base over the rows given; ``sig`` is the whole log, so a
        stateful base runs over it in order. ``base_pred`` may be given if already computed."""
        if self.combine not in COMBINE:
            raise ValueError(f"unknown combine {self.combine!r} (choose from {', '.join(COMBINE)})")
        if base_pred is None:
            base_pred = self.base.predict(sig)[0]
        target = np.asarray(target, dtype=np.float64)
        residual = target - base_pred
        if self.combine == "dissipative":
            rows = np.concatenate([train_rows, val_rows]).astype(np.int64)
            self.width_ = SOFTNESS * max(float(np.mean(np.abs(target[rows]))), 1e-12)
            speed = np.abs(sig["qd"][rows])
            own = getattr(self.base, "v_ps_", None)
            self.v_ps_ = float(own) if own else PRESLIDING_SHARE * float(speed[speed > 0].min())
        add = MLPFriction(inputs=ADD_INPUTS, hidden_sizes=self.hidden_sizes, steps=None, epochs=self.epochs,
                          batch_size=self.batch_size, lr=self.lr, units=self.units)
        pick = lambda rows: {k: v[rows] for k, v in sig.items() if k in ("t", "qd", "tau_g")}  # noqa: E731
        add.fit(pick(train_rows), residual[train_rows], pick(val_rows), residual[val_rows], rng=rng, on_eval=on_eval)
        self.add = add
        return self

    def predict(self, signals: dict[str, np.ndarray], state=None):
        """tau_f (n,) [Nm] (see the module's formulas); the state is the base's."""
        friction, error, state = self.predict_parts(signals, state)
        return friction + error, state

    def predict_parts(self, signals: dict[str, np.ndarray], state=None):
        """(friction (n,), robot-model error (n,), state) [Nm]. NN_add and the dissipative form act on
        the base's friction; the robot-model error terms a base keeps apart (a missing inertia, an
        offset, ``fricli.models.augmented``) pass through as they are: they need not oppose the motion."""
        friction, error, state = predict_parts(self.base, signals, state)
        return self.on_base(signals, friction), error, state

    def on_base(self, signals: dict[str, np.ndarray], tau: np.ndarray) -> np.ndarray:
        """The friction (n,) [Nm] given the base's friction ``tau`` (n,) over the same rows."""
        p = tau + self.add.predict(signals)[0]
        if self.combine == "additive":
            return p
        qd = signals["qd"]
        s = np.sign(qd)
        w = np.square(1.0 - np.square(np.minimum(np.abs(qd) / self.v_ps_, 1.0)))
        return w * p + (1.0 - w) * s * soft_magnitude(s * p, self.width_)

    def required_inputs(self) -> set[str]:
        return set(self.base.required_inputs()) | set(self.add.required_inputs())

    def children(self) -> dict[str, FrictionModel]:
        return {"base": self.base, "add": self.add}

    def get_params(self) -> dict:
        params = {"add_inputs": list(ADD_INPUTS), "hidden_sizes": list(self.hidden_sizes), "epochs": self.epochs,
                  "batch_size": self.batch_size, "lr": self.lr, "min_speed": self.min_speed, "units": self.units}
        if self.combine != "additive":   # files without the key are the paper's additive form
            params["combine"] = {"form": self.combine, "width": self.width_, "v_ps": self.v_ps_}
        return params

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "ResidualFriction":
        combine = params.get("combine")
        model = cls(children["base"], hidden_sizes=params.get("hidden_sizes", (30,)), epochs=params.get("epochs", 200),
                    batch_size=params.get("batch_size", 64), lr=params.get("lr", 0.01),
                    min_speed=params.get("min_speed"), units=params.get("units"), add=children["add"],
                    combine="additive" if combine is None else combine["form"])
        if combine is not None:
            width, v_ps = combine["width"], combine["v_ps"]
            if model.combine not in COMBINE or not (isinstance(width, (int, float)) and width > 0
                                                    and isinstance(v_ps, (int, float)) and v_ps > 0):
                raise ValueError(f"unknown combination {combine!r}")
            model.width_, model.v_ps_ = float(width), float(v_ps)
        return model

    def describe(self) -> str:
        if self.combine == "additive":
            lines = ["residual: base model + NN_add(tau_g, sign(qd)) learned on the base's residual"]
        else:
            unit = self.units.get("qd", "rad/s")
            lines = ["residual: base model + NN_add(tau_g, sign(qd)) learned on the base's residual, "
                     "held against the motion (dissipative)",
                     f"  p = base + NN_add; tau_f = sign(qd) T softplus(sign(qd) p / T) for |qd| >= v_ps, "
                     f"blending into p towards rest; T {self.width_:.4g} {self.units.get('tau', 'Nm')}, "
                     f"v_ps {self.v_ps_:.4g} {unit}"]
        if self.min_speed is not None:
            unit = self.units.get("qd", "rad/s")
            lines.append(f"  NN_add trained on rows moving faster than {self.min_speed:.4g} {unit}")
        lines += ["  base:", indent(self.base.describe(), "    "), "  add:", indent(self.add.describe(), "    ")]
        return "\n".join(lines)
