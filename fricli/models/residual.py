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

NN_add never extrapolates: it is weighted by g(tau_g, s) in [0, 1], which is 1 where the bulk of
its training rows lie and 0 outside all of them. For each direction s the training rows of that
direction give the tau_g interval [lo, hi] (min and max) and its central part [a, b] (the
ENVELOPE_TAIL and 1 - ENVELOPE_TAIL quantiles); with u the distance from [a, b] as a share of
the tail's width (a - lo below, hi - b above),

                 g = (1 - min(u, 1)^2)^2          (1 on [a, b], 0 outside [lo, hi], C1)

and g = min(g+, g-) at rest (s = 0). lo and hi are widened by 1e-12 max(1, max |tau_g|), the
resolution below which the networks call an input constant (a joint with a vertical axis has
tau_g = 0 up to rounding). p above is base(log) + g NN_add. Model files written without the
envelope load with g = 1.

Both parts are children in the model file ("base/...", "add/..."); the base may be of any kind,
with its own state (e.g. the LuGre bristles), which ``predict`` carries across batches.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.models.neural import MLPFriction
from fricli.numerics.nn.activations import softplus

ADD_INPUTS = ("tau_g", "sign(qd)")
COMBINE = ("dissipative", "additive")
SOFTNESS = 0.01          # T of the dissipative form, as a share of the mean |friction target|
PRESLIDING_SHARE = 0.1   # v_ps for a base without its own: this share of the slowest training speed
# NN_add fades out over the outer ENVELOPE_TAIL of its training rows' tau_g on each side (per
# direction): the central 95 % of a sample, the usual statistical range of the data, is where
# the network is held by many rows; it is zero beyond the outermost row
ENVELOPE_TAIL = 0.025
SIDES = ("positive", "negative")   # the envelope's rows: qd > 0, qd < 0
CONSTANT = 1e-12         # relative resolution of tau_g (numerics.nn.training.Standardizer's "constant")


def soft_magnitude(x: np.ndarray, width: float) -> np.ndarray:
    """width * softplus(x / width) (n,), >= 0, = x for x >> width."""
    return width * softplus(x / width)


def envelope(tau_g: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """(2, 4) [Nm]: for s = +1 (row 0) and s = -1 (row 1), lo, a, b, hi of the tau_g (n,) of the
    rows moving that way (min, ENVELOPE_TAIL and 1 - ENVELOPE_TAIL quantiles, max), lo and hi
    widened by CONSTANT max(1, max |tau_g|); NaN for a direction without rows (g = 0 there)."""
    tau_g, qd = np.asarray(tau_g, dtype=np.float64), np.asarray(qd, dtype=np.float64)
    out = np.full((2, 4), np.nan)
    for i, rows in enumerate((qd > 0, qd < 0)):
        if rows.any():
            x = tau_g[rows]
            eps = CONSTANT * max(1.0, float(np.max(np.abs(x))))
            lo, a, b, hi = np.quantile(x, [0.0, ENVELOPE_TAIL, 1.0 - ENVELOPE_TAIL, 1.0])
            out[i] = lo - eps, a, b, hi + eps
    return out


def gate(env: np.ndarray, tau_g: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """g (n,) in [0, 1]: NN_add's weight at tau_g (n,) [Nm] and qd (n,) within the ``envelope``
    ``env`` (2, 4) (module doc)."""
    def one(lo, a, b, hi):
        if np.isnan(lo):
            return np.zeros_like(tau_g)
        u = np.maximum((a - tau_g) / (a - lo), (tau_g - b) / (hi - b))
        return np.square(1.0 - np.square(np.clip(u, 0.0, 1.0)))

    g_pos, g_neg = one(*env[0]), one(*env[1])
    return np.where(qd > 0, g_pos, np.where(qd < 0, g_neg, np.minimum(g_pos, g_neg)))


def indent(text: str, prefix: str = "  ") -> str:
    return "\n".join(prefix + line for line in text.splitlines())


def _read_envelope(saved) -> np.ndarray:
    """The (2, 4) envelope of a model file (None for a direction: no rows); ValueError when a
    direction's is not lo < a <= b < hi."""
    try:
        env = np.array([[np.nan] * 4 if saved[side] is None else saved[side] for side in SIDES], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise ValueError(f"unknown envelope {saved!r}") from None
    given = ~np.isnan(env).all(axis=1)
    if env.shape != (2, 4) or not np.isfinite(env[given]).all() or not (
            (env[given, 0] < env[given, 1]) & (env[given, 1] <= env[given, 2]) & (env[given, 2] < env[given, 3])).all():
        raise ValueError(f"unknown envelope {saved!r}")
    return env


@register
class ResidualFriction(FrictionModel):
    """base + add. Hyperparameters of NN_add as keyword arguments; ``fit`` trains NN_add."""

    kind = "residual"

    def __init__(self, base: FrictionModel, *, hidden_sizes=(30,), epochs: int = 200, batch_size: int = 64,
                 lr: float = 0.01, min_speed: float | None = None, units: dict | None = None,
                 add: FrictionModel | None = None, combine: str | None = None, envelope: np.ndarray | None = None):
        """``combine``: "dissipative" or "additive"; by default dissipative, unless ``base`` reads other
        joints' velocities (a coupled group's member): that joint's friction may act along its own
        motion (its motor turns with another joint), which the dissipative form would forbid."""
        self.base = base
        self.hidden_sizes, self.epochs, self.batch_size, self.lr = tuple(hidden_sizes), epochs, batch_size, lr
        self.min_speed, self.units = min_speed, dict(units or {})
        self.add = add
        self.envelope_ = None if envelope is None else np.asarray(envelope, dtype=np.float64)
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
        self.envelope_ = envelope(sig["tau_g"][train_rows], sig["qd"][train_rows])
        return self

    def predict(self, signals: dict[str, np.ndarray], state=None):
        """tau_f (n,) [Nm] (see the module's formulas); the state is the base's."""
        tau, state = self.base.predict(signals, state)
        return self.on_base(signals, tau), state

    def on_base(self, signals: dict[str, np.ndarray], tau: np.ndarray) -> np.ndarray:
        """tau_f (n,) [Nm] given the base's prediction ``tau`` (n,) over the same rows."""
        add = self.add.predict(signals)[0]
        if self.envelope_ is not None:
            add = add * gate(self.envelope_, signals["tau_g"], signals["qd"])
        p = tau + add
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
        if self.envelope_ is not None:   # files without the key: NN_add everywhere (g = 1)
            params["envelope"] = {"tail": ENVELOPE_TAIL, **{
                side: None if np.isnan(row[0]) else row.tolist() for side, row in zip(SIDES, self.envelope_)}}
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
        if "envelope" in params:
            model.envelope_ = _read_envelope(params["envelope"])
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
        if self.envelope_ is not None:
            tau = self.units.get("tau", "Nm")
            for label, (lo, a, b, hi) in zip(("qd > 0", "qd < 0"), self.envelope_):
                if np.isnan(lo):
                    lines.append(f"  NN_add weighted 0 ({label}: no training rows)")
                    continue
                lines.append(f"  NN_add weighted 1 for tau_g in [{a:.4g}, {b:.4g}] {tau}, 0 outside "
                             f"[{lo:.4g}, {hi:.4g}] ({label})")
        lines += ["  base:", indent(self.base.describe(), "    "), "  add:", indent(self.add.describe(), "    ")]
        return "\n".join(lines)
