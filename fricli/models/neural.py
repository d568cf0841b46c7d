"""Neural friction models: NN_base ("mlp") and the two data-driven baselines of the paper.

    mlp     tau_f = NN(tau_g, qd): two hidden layers of 30 ELU units (the paper's NN_base). The
            same kind, with inputs (tau_g, sign(qd)) and one hidden layer, is the NN_add of a
            residual model.
    selmic  Selmic & Lewis (2002): one hidden layer of 30 units, 20 sigmoid and 10 jump units
            phi_k(x) = (1 - e^-x)^k (x >= 0), k = 1..10.
    nnacm   Ciliz & Tomizuka (2004, 2007), with gravity torque as an input:
            tau_f = NN(qd, tau_g) + beta1 0.5 (1 + sign qd) + beta2 0.5 (1 - sign qd),
            one hidden layer of 50 sigmoid units; beta1, beta2 are learned with the weights
            (the direction terms feed the linear output layer directly).

Velocity input. With ``velocity_scale`` set, the network sees u = asinh(qd / v0) instead of qd:
odd, linear for |qd| << v0 and logarithmic for |qd| >> v0, so slow velocity levels are spread
apart instead of crowding around 0 and the jump of friction at zero velocity is a step of
about 2 asinh(v_slow / v0) in u. v0 is given or ("auto") the VELOCITY_QUANTILE quantile of
|qd| over the training rows, and is stored with the model.

Inputs and the output are standardised with the mean and standard deviation of the training
data; these are stored with the weights. Losses are mean squared errors on standardised data.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.core import logs, metrics
from fricli.core.errors import DataError
from fricli.core.jsontext import is_count, is_finite_number
from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.numerics.nn import activations as acts
from fricli.numerics.nn.network import Network, predict_in_chunks
from fricli.numerics.nn.training import Standardizer, Trainer

FEATURES = ("qd", "tau_g", "sign(qd)", "pos(qd)", "neg(qd)")
VELOCITY_QUANTILE = 0.05   # velocity_scale="auto": v0 = this quantile of |qd| over the training rows


def feature(sig: dict[str, np.ndarray], name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
    """Input ``name`` for rows start:stop, float64. sign(qd) is 0 at rest; pos/neg(qd) are
    0.5 (1 +- sign qd)."""
    if name in ("sign(qd)", "pos(qd)", "neg(qd)"):
        s = np.sign(sig["qd"][start:stop])
        if name == "pos(qd)":
            return 0.5 * (1.0 + s)
        if name == "neg(qd)":
            return 0.5 * (1.0 - s)
        return s
    return logs.column(sig, name, start, stop)


def _rows(sig: dict[str, np.ndarray]) -> int:
    for key in ("qd", "t", "tau_g"):
        if key in sig:
            return len(sig[key])
    raise DataError("the log has no column 'qd'")


def _source(name: str) -> str:
    return "qd" if name.endswith("(qd)") else name


# What a trained network model records about its training (both neural model kinds).
_FITTED = ("steps", "best_step", "eval_every", "n_train", "n_val")


def record_training(model, trainer: Trainer, n_train: int, n_val: int) -> None:
    """Set the fitted training attributes of ``model`` from a finished ``trainer``."""
    model.history_train_, model.history_val_ = trainer.history_train_, trainer.history_val_
    model.best_step_, model.steps_, model.eval_every_ = trainer.best_step_, trainer.steps_, trainer.eval_every_
    model.n_train_, model.n_val_ = n_train, n_val


def training_params(model) -> dict:
    """The ``fitted`` entry of a trained model's params."""
    return {key: int(getattr(model, f"{key}_", 0)) for key in _FITTED}


def training_arrays(model) -> dict[str, np.ndarray]:
    """The loss histories (float64) of a trained model, for its arrays."""
    return {name: np.asarray(getattr(model, f"{name}_", np.empty(0)), dtype=np.float64)
            for name in ("history_train", "history_val")}


def training_options(params: dict) -> dict:
    """The training hyperparameters of a model file's params (its ``training`` entry) as keyword
    arguments of the model's constructor; ValueError when one has another type."""
    tr = params.get("training", {})
    if not isinstance(tr, dict):
        raise ValueError("the training entry is not an object")
    out = {"steps": tr.get("steps"), "epochs": tr.get("epochs"), "lr": tr.get("lr", 0.01),
           "batch_size": tr.get("batch_size", 0), "eval_every": tr.get("eval_every"),
           "schedule": tr.get("schedule", "constant"), "patience": tr.get("patience")}
    counts = ("steps", "epochs", "eval_every", "patience", "batch_size")
    bad = [k for k in counts if out[k] is not None and not is_count(out[k])]
    if not (is_finite_number(out["lr"]) and out["lr"] > 0):
        bad.append("lr")
    if not isinstance(out["schedule"], str):
        bad.append("schedule")
    if bad:
        raise ValueError(f"training {bad[0]} {tr.get(bad[0])!r} is not a valid value")
    return out


def load_training(model, params: dict, arrays: dict) -> None:
    """Set the fitted training attributes of ``model`` from a model file's params and arrays."""
    model.history_train_ = arrays.get("history_train", np.empty(0))
    model.history_val_ = arrays.get("history_val", np.empty(0))
    fitted = params.get("fitted", {})
    for key in _FITTED:
        setattr(model, f"{key}_", fitted.get(key, 0))


class NeuralFriction(FrictionModel):
    """A friction model tau_f = y_mean + y_scale * net((inputs - x_mean) / x_scale, skip).

    Hyperparameters are keyword arguments; ``fit`` trains; fitted attributes end in ``_``.
    """

    kind = ""
    label = ""

    def __init__(self, *, inputs=("tau_g", "qd"), hidden=((30, "elu"), (30, "elu")), skip=(),
                 steps: int | None = 50_000, epochs: int | None = None, lr: float = 0.01,
                 batch_size: int = 0, eval_every: int | None = None, units: dict | None = None,
                 velocity_scale: float | str | None = None, schedule: str = "constant",
                 patience: int | None = None, precision: str = "single"):
        self.inputs, self.skip = tuple(inputs), tuple(skip)
        self.precision = precision
        if not (velocity_scale is None or velocity_scale == "auto"
                or (isinstance(velocity_scale, (int, float)) and velocity_scale > 0)):
            raise ValueError(f"velocity_scale must be None, 'auto' or a positive speed, got {velocity_scale!r}")
        self.velocity_scale = velocity_scale
        self.v0_: float | None = None if velocity_scale in (None, "auto") else float(velocity_scale)
        for name in self.inputs + self.skip:
            if name not in FEATURES:
                raise ValueError(f"unknown input {name!r}")
        self.hidden = tuple((int(n), a) for n, a in hidden)
        self.steps, self.epochs, self.lr, self.batch_size = steps, epochs, lr, batch_size
        self.eval_every, self.units = eval_every, dict(units or {})
        self.schedule, self.patience = schedule, patience
        self.net_: Network | None = None

    # ------------------------------------------------------------------ fitting

    def _input(self, sig: dict[str, np.ndarray], name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Network input ``name`` for rows start:stop before standardisation: asinh(qd / v0)
        for qd when the model has a velocity scale."""
        x = feature(sig, name, start, stop)
        if name == "qd" and self.v0_ is not None:
            return np.arcsinh(x / self.v0_)
        return x

    def _features(self, sig: dict[str, np.ndarray]) -> np.ndarray:
        return np.stack([self._input(sig, name) for name in self.inputs + self.skip])

    def _fit_velocity_scale(self, sig: dict[str, np.ndarray]) -> None:
        if self.velocity_scale != "auto" or "qd" not in self.inputs:
            return
        qd = feature(sig, "qd")
        speed = np.abs(qd[metrics.in_motion(qd)])
        v0 = float(np.quantile(speed, VELOCITY_QUANTILE)) if speed.size else 0.0
        if not v0 > 0:
            raise DataError("no moving training samples to scale the velocity input with")
        self.v0_ = v0

    def new_network(self) -> Network:
        hidden = [(n, acts.from_spec(a) if not isinstance(a, acts.Activation) else a) for n, a in self.hidden]
        return Network(len(self.inputs), hidden, n_out=1, n_skip=len(self.skip))

    def fit(self, sig: dict[str, np.ndarray], target: np.ndarray, val_sig: dict[str, np.ndarray] | None = None,
            val_target: np.ndarray | None = None, *, rng: np.random.Generator,
            on_eval: Callable | None = None) -> "NeuralFriction":
        """Train on signals ``sig`` (rows already selected) against ``target`` (n,) [Nm]."""
        self._fit_velocity_scale(sig)
        x = self._features(sig)
        y = np.asarray(target, dtype=np.float64)[None, :]
        if x.shape[1] == 0:
            raise DataError("no training samples")
        keep = tuple(range(len(self.inputs), len(self.inputs) + len(self.skip)))
        self.x_std_ = Standardizer(keep=keep).fit(x)
        self.y_std_ = Standardizer().fit(y)
        net = self.new_network().init(rng)
        xv = tv = None
        if val_sig is not None and len(val_target):
            xv = self.x_std_.transform(self._features(val_sig))
            tv = self.y_std_.transform(np.asarray(val_target, dtype=np.float64)[None, :])
        trainer = Trainer(steps=self.steps if self.epochs is None else None, epochs=self.epochs, lr=self.lr,
                          batch_size=self.batch_size, eval_every=self.eval_every, on_eval=on_eval,
                          schedule=self.schedule, patience=self.patience)
        trainer.fit(net, self.x_std_.transform(x), self.y_std_.transform(y), xv, tv, rng=rng)
        self.net_ = net
        record_training(self, trainer, x.shape[1], 0 if xv is None else xv.shape[1])
        return self

    # ------------------------------------------------------------------ predicting

    def required_inputs(self) -> set[str]:
        return {_source(name) for name in self.inputs + self.skip}

    def predict(self, signals: dict[str, np.ndarray], state=None) -> tuple[np.ndarray, None]:
        """tau_f (n,) [Nm] for the log's signals; stateless. The network runs in float32
        (``precision="single"``, the fast default) or float64 (``"double"``, as exported C code)."""
        if self.net_ is None:
            raise ValueError("the model is not fitted")
        names = self.inputs + self.skip
        n = _rows(signals)
        out = np.empty(n, dtype=np.float64)
        if n == 0:
            return out, None
        net, mean_x, scale_x = self.net_, self.x_std_.mean_, self.x_std_.scale_
        if self.precision == "double":
            net = net.astype(np.float64)
        elif self.precision != "single":
            raise ValueError(f"precision must be 'single' or 'double', not {self.precision!r}")
        y_mean, y_scale = float(self.y_std_.mean_[0]), float(self.y_std_.scale_[0])

        def run(part: list[tuple[int, int]]) -> None:
            ws = None
            for start, stop in part:
                if ws is None or ws.n != stop - start:
                    ws = net.workspace(stop - start, backward=False)
                for i, name in enumerate(names):
                    dest = ws.x[i] if i < len(self.inputs) else ws.s[i - len(self.inputs)]
                    np.subtract(self._input(signals, name, start, stop), mean_x[i], out=dest, casting="same_kind")
                    dest *= dest.dtype.type(1.0 / scale_x[i])
                y = net.forward(ws)[0]
                np.multiply(y, y_scale, out=out[start:stop])
                out[start:stop] += y_mean

        predict_in_chunks(n, run)
        return out, None

    # ------------------------------------------------------------------ files

    def get_params(self) -> dict:
        params = {"inputs": list(self.inputs), "skip": list(self.skip),
                  "hidden": [[n, a if isinstance(a, (str, dict)) else a.spec()] for n, a in self.hidden],
                  "training": {"steps": self.steps, "epochs": self.epochs, "lr": self.lr,
                               "batch_size": self.batch_size, "eval_every": self.eval_every,
                               "schedule": self.schedule, "patience": self.patience},
                  "units": self.units}
        if self.velocity_scale is not None:
            # only models with a transformed velocity carry the key (older files read as without)
            params["velocity"] = {"transform": "asinh", "scale": self.velocity_scale, "v0": self.v0_}
        if self.net_ is not None:
            params["network"] = self.net_.spec()
            params["fitted"] = training_params(self)
        return params

    def get_arrays(self) -> dict[str, np.ndarray]:
        if self.net_ is None:
            return {}
        arrays = {f"W{i}": w.copy() for i, w in enumerate(self.net_.weights)}
        arrays.update(x_mean=self.x_std_.mean_, x_scale=self.x_std_.scale_,
                      y_mean=self.y_std_.mean_, y_scale=self.y_std_.scale_, **training_arrays(self))
        return arrays

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "NeuralFriction":
        model = cls(inputs=params["inputs"], skip=params.get("skip", ()), hidden=[tuple(h) for h in params["hidden"]],
                    units=params.get("units"), **training_options(params))
        velocity = params.get("velocity")
        if velocity is not None:
            v0 = velocity.get("v0")
            if velocity.get("transform") != "asinh" or not (v0 is None or isinstance(v0, (int, float)) and v0 > 0):
                raise ValueError(f"unknown velocity transform {velocity!r}")
            model.velocity_scale, model.v0_ = velocity.get("scale", "auto"), None if v0 is None else float(v0)
        spec = params["network"]
        n_layers = len(spec["hidden"]) + 1
        model.net_ = Network.from_spec(spec, [arrays[f"W{i}"] for i in range(n_layers)])
        if model.net_.n_in != len(model.inputs) or model.net_.n_skip != len(model.skip):
            raise ValueError("the network does not match the model's inputs")
        model.x_std_ = Standardizer.from_arrays(arrays["x_mean"], arrays["x_scale"])
        model.y_std_ = Standardizer.from_arrays(arrays["y_mean"], arrays["y_scale"])
        if model.x_std_.mean_.size != len(model.inputs) + len(model.skip) or model.y_std_.mean_.size != 1:
            raise ValueError("standardisation arrays do not match the inputs")
        load_training(model, params, arrays)
        return model

    # ------------------------------------------------------------------ people

    def _architecture(self) -> str:
        layers = []
        for n, a in self.hidden:
            spec = a if isinstance(a, (str, dict)) else a.spec()
            layers.append(f"{n} {_describe_activation(spec)}")
        inputs = ", ".join(self._input_label(name) for name in self.inputs)
        skip = f"; direct to the output: {', '.join(self.skip)}" if self.skip else ""
        return f"inputs ({inputs}){skip}; hidden layers: {' | '.join(layers) or 'none'}; linear output"

    def _input_label(self, name: str) -> str:
        if name != "qd" or self.velocity_scale is None:
            return name
        v0 = "v0" if self.v0_ is None else f"{self.v0_:.4g} {self.units.get('qd', 'rad/s')}"
        return f"asinh(qd / {v0})"

    def describe(self) -> str:
        tau = self.units.get("tau", "Nm")
        lines = [f"{self.kind}: {self.label}", f"  {self._architecture()}"]
        if self.net_ is None:
            return "\n".join(lines + ["  (not fitted)"])
        lines.append(f"  {self.net_.n_params} parameters")
        how = (f"{self.epochs} epochs of mini-batches of {self.batch_size}" if self.epochs is not None
               else f"{self.steps_} {'full-batch' if not self.batch_size else f'mini-batch ({self.batch_size})'} steps")
        lr = f"lr {self.lr:g}" + (", cosine decay to 0" if self.schedule == "cosine" else "")
        lines.append(f"  trained with Adam ({lr}) for {how} on {self.n_train_} samples "
                     f"({self.n_val_} for validation); weights kept from step {self.best_step_}")
        for i, name in enumerate(self.inputs + self.skip):
            lines.append(f"  input {self._input_label(name)}: mean {self.x_std_.mean_[i]:.4g}, scale {self.x_std_.scale_[i]:.4g}")
        lines.append(f"  output: mean {self.y_std_.mean_[0]:.4g} {tau}, scale {self.y_std_.scale_[0]:.4g} {tau}")
        if self.history_val_.size:
            lines.append(f"  final losses (standardised MSE): train {self.history_train_[-1]:.4g}, "
                         f"validation {self.history_val_[-1]:.4g}; best validation {self.history_val_.min():.4g}")
        return "\n".join(lines)


def _describe_activation(spec) -> str:
    if isinstance(spec, str):
        return spec.upper() if spec == "elu" else spec
    if spec.get("name") == "mixed":
        return "(" + " + ".join(f"{n} {_describe_activation(s)}" for n, s in spec["parts"]) + ")"
    if spec.get("name") == "jump":
        ks = spec["k"]
        return f"jump (k = {ks[0]}..{ks[-1]})" if ks == list(range(ks[0], ks[-1] + 1)) else f"jump (k = {ks})"
    return str(spec.get("name"))


@register
class MLPFriction(NeuralFriction):
    """NN_base: tau_f = NN(tau_g, qd), by default two hidden layers of 30 ELU units."""

    kind = "mlp"
    label = "dense network (NN_base)"

    def __init__(self, *, hidden_sizes=(30, 30), **kwargs):
        kwargs.setdefault("hidden", tuple((n, "elu") for n in hidden_sizes))
        super().__init__(**kwargs)


def selmic_hidden(units: int = 30, jumps: int = 10) -> tuple:
    """One hidden layer: ``units - jumps`` sigmoid units and ``jumps`` jump units k = 1..jumps."""
    if units <= jumps:
        raise ValueError(f"the Selmic & Lewis layer needs more than {jumps} units")
    return ((units, {"name": "mixed", "parts": [[units - jumps, "sigmoid"],
                                                 [jumps, {"name": "jump", "k": list(range(1, jumps + 1))}]]}),)


@register
class SelmicFriction(NeuralFriction):
    """Selmic & Lewis: one hidden layer of 20 sigmoid and 10 jump units."""

    kind = "selmic"
    label = "Selmic & Lewis network with sigmoid and jump units"

    def __init__(self, *, hidden_sizes=(30,), **kwargs):
        if len(hidden_sizes) != 1:
            raise ValueError("the Selmic & Lewis network has one hidden layer")
        kwargs.setdefault("hidden", selmic_hidden(hidden_sizes[0]))
        super().__init__(**kwargs)


@register
class NNACMFriction(NeuralFriction):
    """Ciliz & Tomizuka: NN(qd, tau_g) + beta1 0.5 (1 + sign qd) + beta2 0.5 (1 - sign qd)."""

    kind = "nnacm"
    label = "neural network with adaptive Coulomb friction (NNACM)"

    def __init__(self, *, hidden_sizes=(50,), **kwargs):
        kwargs.setdefault("hidden", tuple((n, "sigmoid") for n in hidden_sizes))
        kwargs.setdefault("inputs", ("qd", "tau_g"))
        kwargs.setdefault("skip", ("pos(qd)", "neg(qd)"))
        super().__init__(**kwargs)

    def betas(self) -> tuple[float, float]:
        """(beta1, beta2) [Nm]: the learned Coulomb levels for positive and negative motion
        (on top of the network, whose bias absorbs their common part)."""
        w = self.net_.weights[-1][0]
        scale = float(self.y_std_.scale_[0])
        return float(w[-2]) * scale, float(w[-1]) * scale

    def describe(self) -> str:
        text = super().describe()
        if self.net_ is not None:
            b1, b2 = self.betas()
            tau = self.units.get("tau", "Nm")
            text += f"\n  beta1 {b1:.4g} {tau}, beta2 {b2:.4g} {tau} (difference {b1 - b2:.4g} {tau})"
        return text


ARCHS = {"mlp": MLPFriction, "selmic": SelmicFriction, "nnacm": NNACMFriction}
