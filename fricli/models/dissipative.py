"""The dissipative network (kind ``dissipative``, the default of ``train-base``): friction that
never pushes the joint, with the load dependence as its own factor.

    tau_f = y_scale * tanh(qd / v_ps) * m
    m     = softplus(r0) + softplus(b1) * |tau_g| / g_scale
    r0    = NN(u, sign(qd)),   u = (asinh(|qd| / v0) - u_mean) / u_scale

NN is a dense network (by default two hidden layers of 30 ELU units) with two linear outputs,
r0 and b1; b1 is the bias of the second alone (its weights from the hidden layer stay 0), so
the load slope k = y_scale softplus(b1) / g_scale [Nm/Nm] is one learned constant.
The magnitude m is non-negative for every input and every weight, and tanh(qd / v_ps) has the
sign of qd, so tau_f * qd >= 0 everywhere: friction acts against the motion by structure.
Above the pre-sliding speed v_ps (recorded in the model) tanh(qd / v_ps) is close to sign(qd);
below it the prediction fades to zero at rest, where the bristles hold a torque set by the
motion before.

The network sees the speed and the direction only; the gravity torque enters through one
non-negative slope (the Coulomb and static levels of an extended LuGre model grow as fc +
kc |tau_g| and fs + ks |tau_g|, with kc and ks close). A velocity dependence learned at one load
therefore carries over to every other load, where a network of (tau_g, qd) has to see every
pair; and the slope is learned from every speed at once, so a slow level seen at one load
cannot trade it for a different velocity dependence. Asymmetry between the directions comes
through the sign(qd) input.

Beyond the training speeds. A network of asinh(|qd| / v0) extrapolates logarithmically in the
speed, and a direction trained only at slow speeds can bend anywhere. Above the top training
speed v_top of its direction (v_max, recorded per direction) the network sees v_top, and the
magnitude grows linearly with the speed instead, by the mean slope of the learned magnitude
(at tau_g = 0) over the upper half of the training speeds, at least 0 (``slope``):

    m(|qd| > v_top) = m(v_top) + slope * (|qd| - v_top)

Below the slowest training speed v_low of its direction (v_min) the network sees v_low: the
magnitude holds its level there, and tanh(qd / v_ps) takes it to zero at rest. Its input stays in
the range it was trained on; a log of one speed (u_scale, the spread of u, near 0) would
otherwise put a slower row hundreds of u_scale away, where the network's value means nothing.

Models written without these records extrapolate as the network does (without v_min: below).

Over a physical prior, optional (``set_prior``; train-base by default). The magnitude is then
the blend of the network's and the static curve p of the LuGre model (Stribeck, viscous and
load terms, fitted on the same rows; ``PRIOR_KEYS``):

    y_scale * m  ->  lambda * y_scale * m + (1 - lambda) * p,   0 <= lambda <= 1
    p = fc + kc |tau_g| + (fs - fc + (ks - kc) |tau_g|) exp(-|qd / vs|^delta) + fv |qd|   >= 0

so the network is a correction of the prior, p + lambda (y_scale m - p), scaled by the share
lambda that held-out rows of the training log give it (``fricli.fitting.learning.blend_prior``).
Both terms are non-negative, and so is the blend: the model stays dissipative.

Pre-sliding (bristle) state, optional (``fit_bristles``; train-base --bristles). Friction then
follows the LuGre bristle equations with the learned magnitude as the steady state:

    g     = y_scale * m(qd, tau_g)  (the magnitude above, c = 1)                  [Nm], > 0
    dz/dt = qd - sigma0 |qd| z / g                                                [rad]
    tau_f = sigma0 z                                                              [Nm]

In steady sliding tau_f = sign(qd) g, the learned curve; at a reversal the friction passes
through zero over a bristle deflection of about g / sigma0 instead of at qd = 0 (the tanh
factor is not used). The state z runs over the rows in time order with the exact update of
``fricli.numerics.physics.lugre_friction`` and is carried from one ``predict`` batch to the next
(state (z [rad], t_last [s]), as for LuGre). With g > 0 the map qd -> tau_f is passive: its
work is at least -sigma0 z0^2 / 2. sigma0 is fitted on the training log (``fit_bristles``).

v0 is the VELOCITY_QUANTILE quantile of the training speeds (as for ``mlp``), v_ps =
PRESLIDING_SHARE * v0, g_scale the mean |tau_g| of the training rows (1, and no load term, when
|tau_g| varies too little to show a load slope: ``metrics.load_can_show``), y_scale the RMS of the
training target. Training minimises the mean squared error of
tau_f / y_scale with the trainer of ``fricli.numerics.nn.training`` (the head is part of the
network, ``fricli.numerics.nn.heads``).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.core import metrics
from fricli.core.errors import DataError
from fricli.core.jsontext import is_count, is_finite_number
from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.models.neural import (VELOCITY_QUANTILE, _describe_activation, load_training, record_training,
                                  training_arrays, training_options, training_params)
from fricli.numerics import physics, piecewise
from fricli.numerics.nn import activations as acts
from fricli.numerics.nn.heads import DissipativeHead, HeadedNetwork
from fricli.numerics.nn.network import predict_in_chunks
from fricli.numerics.nn.training import Trainer

PRESLIDING_SHARE = 0.1   # v_ps = this share of v0
PRIOR_KEYS = ("fc", "fs", "vs", "delta", "fv", "kc", "ks")   # the prior's parameters, as LuGreModel's
G_MIN = 1e-12            # floor on the bristle curve g [Nm], so the bristle rate stays finite
# fit_bristles: the bristle deflection g_typ / sigma0 [rad] searched (as identify's bounds)
DEFLECTION_RANGE = (1e-8, 1.0)
BRISTLE_BLOCK = 1 << 16  # rows per block of the bristle recurrence in predict (as LuGreModel's)
PIECES_ROWS = 1 << 16    # a batch of this many rows or more takes the networks' magnitude from its pieces


@register
class DissipativeFriction(FrictionModel):
    """tau_f = y_scale tanh(qd / v_ps) (softplus(r0(|qd|, sign qd)) + softplus(b1) |tau_g| / g_scale).

    Hyperparameters are keyword arguments; ``fit`` trains; fitted attributes end in ``_``.
    """

    kind = "dissipative"
    label = "dissipative network: non-negative magnitude times a smooth sign of qd"

    def __init__(self, *, hidden_sizes=(30, 30), activation: str = "elu", steps: int | None = 50_000,
                 epochs: int | None = None, lr: float = 0.01, batch_size: int = 0, eval_every: int | None = None,
                 units: dict | None = None, velocity_scale: float | str = "auto",
                 presliding_speed: float | str = "auto", schedule: str = "constant", patience: int | None = None,
                 precision: str = "single"):
        self.precision = precision
        self.hidden_sizes, self.activation = tuple(hidden_sizes), activation
        self.schedule, self.patience = schedule, patience
        self.steps, self.epochs, self.lr, self.batch_size = steps, epochs, lr, batch_size
        self.eval_every, self.units = eval_every, dict(units or {})
        self.velocity_scale, self.presliding_speed = velocity_scale, presliding_speed
        self.nets_: list[HeadedNetwork] | None = None   # one network, or the members of an ensemble
        self.v_max_: tuple[float, float] | None = None    # top training speed (positive, negative direction)
        self.v_min_: tuple[float, float] | None = None    # slowest training speed (positive, negative direction)
        self.slope_: tuple[float, float] | None = None    # magnitude per speed beyond it, / y_scale [1 / (rad/s)]
        self.sigma0_: float | None = None                 # bristle stiffness [Nm/rad]; None: no pre-sliding state
        self.prior_: dict | None = None                   # static LuGre curve (PRIOR_KEYS, LuGreModel's units)
        self.blend_: float | None = None                  # lambda in [0, 1]: the network's share over the prior
        self.load_ = True                                 # whether |tau_g| enters (metrics.load_can_show)
        self._pieces: tuple | None = None                 # (what they were built from, magnitude_pieces)

    @property
    def net_(self) -> HeadedNetwork | None:
        """The (first) network."""
        return self.nets_[0] if self.nets_ else None

    @net_.setter
    def net_(self, net: HeadedNetwork | None) -> None:
        self.nets_ = None if net is None else [net]

    # ------------------------------------------------------------------ inputs

    def new_network(self) -> HeadedNetwork:
        hidden = [(int(n), acts.from_spec(self.activation)) for n in self.hidden_sizes]
        return HeadedNetwork(2, hidden, DissipativeHead(), constant_outputs=(1,))

    def _rows(self, sig: dict[str, np.ndarray], dtype=np.float64, sliding: bool = False) -> np.ndarray:
        """Network inputs and aux rows (4, n) float64: u, sign(qd), c, |tau_g| / g_scale with
        c = tanh(qd / v_ps) computed in ``dtype``, the precision of the network that reads the rows
        (``sliding``: c = 1)."""
        if "qd" not in sig:
            raise DataError("the log has no column 'qd'")
        qd = np.asarray(sig["qd"], dtype=np.float64)
        g = sig.get("tau_g")
        g = np.zeros_like(qd) if g is None else np.asarray(g, dtype=np.float64)
        out = np.empty((4, qd.size))
        speed = np.abs(qd) if self.v_max_ is None else np.minimum(np.abs(qd), self._by_direction(qd, self.v_max_))
        if self.v_min_ is not None:
            np.maximum(speed, self._by_direction(qd, self.v_min_), out=speed)
        out[0] = self.speed_input(speed)
        np.sign(qd, out=out[1])
        if sliding:
            out[2] = 1.0
        else:
            np.tanh(qd / self.v_ps_, out=out[2], dtype=dtype)
        np.abs(g, out=out[3])
        out[3] *= (1.0 / self.g_scale_) if self.load_ else 0.0
        return out

    @staticmethod
    def _by_direction(qd: np.ndarray, pair: tuple[float, float]) -> np.ndarray:
        """pair[0] where qd > 0, pair[1] elsewhere (n,)."""
        return np.where(qd > 0, pair[0], pair[1])

    # ------------------------------------------------------------------ fitting

    def fit(self, sig: dict[str, np.ndarray], target: np.ndarray, val_sig: dict[str, np.ndarray] | None = None,
            val_target: np.ndarray | None = None, *, rng: np.random.Generator,
            on_eval: Callable | None = None, scales_from: "DissipativeFriction | None" = None,
            snapshots: bool = False, stop=None) -> "DissipativeFriction":
        """Train on signals ``sig`` (moving rows already selected) against ``target`` (n,) [Nm].

        ``scales_from``: a model whose scales (``set_scales``) to take instead of fitting them
        on ``sig``; ``snapshots``: keep the weights at every loss record in ``snapshots_``
        (one theta per record of ``history_val_``) and, without validation rows, leave the
        choice of weights to the caller (the last step's stay). ``on_eval`` returning True ends
        training there.
        """
        target = np.asarray(target, dtype=np.float64)
        if target.size == 0:
            raise DataError("no training samples")
        if scales_from is None:
            self.set_scales(sig, target)
        else:
            for key in self._SCALARS:
                setattr(self, f"{key}_", getattr(scales_from, f"{key}_"))
        net = self.new_network().init(rng)
        self.sigma0_ = self.prior_ = self.blend_ = self.v_max_ = self.v_min_ = None   # a refit's inputs unlimited
        x = self._rows(sig)
        y = (target / self.y_scale_)[None, :]
        xv = tv = None
        if val_sig is not None and val_target is not None and len(val_target):
            xv = self._rows(val_sig)
            tv = (np.asarray(val_target, dtype=np.float64) / self.y_scale_)[None, :]
        self.snapshots_ = []
        def with_snapshot(*args):
            self.snapshots_.append(net.theta.copy())
            return None if on_eval is None else on_eval(*args)

        record = with_snapshot if snapshots else on_eval
        trainer = Trainer(steps=self.steps if self.epochs is None else None, epochs=self.epochs, lr=self.lr,
                          batch_size=self.batch_size, eval_every=self.eval_every, on_eval=record,
                          schedule=self.schedule, patience=self.patience, stop=stop, keep_best=not snapshots)
        trainer.fit(net, x, y, xv, tv, rng=rng)
        self.net_ = net
        record_training(self, trainer, x.shape[1], 0 if xv is None else xv.shape[1])
        self._fit_extrapolation(np.asarray(sig["qd"], dtype=np.float64))
        return self

    def set_scales(self, sig: dict[str, np.ndarray], target: np.ndarray) -> None:
        """v0, v_ps, g_scale, u_mean, u_scale and y_scale from the training rows ``sig`` and ``target`` (n,) [Nm]."""
        speed = np.abs(np.asarray(sig["qd"], dtype=np.float64))
        moving = speed[speed > 0]
        if not moving.size:
            raise DataError("no moving training samples")
        self.v0_ = (float(np.quantile(moving, VELOCITY_QUANTILE)) if self.velocity_scale == "auto"
                    else float(self.velocity_scale))
        self.v_ps_ = (PRESLIDING_SHARE * self.v0_ if self.presliding_speed == "auto"
                      else float(self.presliding_speed))
        if not (self.v0_ > 0 and self.v_ps_ > 0):
            raise DataError("no moving training samples to scale the velocity with")
        g = np.abs(np.asarray(sig.get("tau_g", np.zeros_like(speed)), dtype=np.float64))
        # a |tau_g| too constant to show a load slope (identify's rule; rounding noise on a vertical
        # axis, a wrist whose centre of mass lies on its axis) stays out of the magnitude: a slope
        # learned there would scale every larger load the joint meets later
        self.load_ = metrics.load_can_show(g, target)
        self.g_scale_ = float(g.mean()) if self.load_ else 1.0
        u = np.arcsinh(speed / self.v0_)
        self.u_mean_, self.u_scale_ = float(u.mean()), float(u.std()) if u.std() > 1e-12 else 1.0
        rms = float(np.sqrt(np.mean(np.asarray(target, dtype=np.float64) ** 2)))
        self.y_scale_ = rms if rms > 0 else 1.0

    def set_members(self, nets: list[HeadedNetwork], qd: np.ndarray) -> None:
        """Make the model the mean of ``nets`` (networks of ``new_network`` trained on this model's
        scales); the extrapolation from the training velocities qd (n,)."""
        self.nets_, self.v_max_, self.v_min_, self.slope_ = list(nets), None, None, None
        self.prior_ = self.blend_ = None
        self._fit_extrapolation(np.asarray(qd, dtype=np.float64))

    def _fit_extrapolation(self, qd: np.ndarray) -> None:
        """v_max_, v_min_ and slope_ from the training velocities qd (n,) (see the module doc)."""
        top = [float(np.max(np.abs(qd[side]), initial=0.0)) for side in (qd > 0, qd < 0)]
        low = [float(np.min(np.abs(qd[side]), initial=np.inf)) for side in (qd > 0, qd < 0)]
        self.v_max_ = (top[0] or top[1], top[1] or top[0])
        low = (low[0] if np.isfinite(low[0]) else low[1], low[1] if np.isfinite(low[1]) else low[0])
        self.v_min_ = low if np.isfinite(low).all() else None   # the slope below is taken with it in place
        self.slope_ = (0.0, 0.0)
        slopes = []
        for direction, v in zip((1.0, -1.0), self.v_max_):
            m = self.magnitude({"qd": direction * np.array([0.5 * v, v]), "tau_g": np.zeros(2)})
            slopes.append(max(0.0, float(m[1] - m[0]) / (0.5 * v) / self.y_scale_))
        self.slope_ = (slopes[0], slopes[1])

    # ------------------------------------------------------------------ predicting

    def required_inputs(self) -> set[str]:
        return {"qd", "tau_g"} if self.sigma0_ is None else {"t", "qd", "tau_g"}

    def magnitude_pieces(self) -> piecewise.SignedPieces | None:
        """mean_k softplus(r0_k) as pieces of u (``piecewise.network_pieces``), built once for the current
        networks and scales; None without a top speed (u unbounded) or where they miss ``piecewise.TOL``."""
        if self.nets_ is None or self.v_max_ is None:
            return None
        key = (self.v0_, self.u_mean_, self.u_scale_, self.v_min_, self.v_max_,
               b"".join(net.theta.tobytes() for net in self.nets_))
        if self._pieces is None or self._pieces[0] != key:
            low = (0.0, 0.0) if self.v_min_ is None else self.v_min_
            ranges = [self.speed_input(np.array([v, max(v, top)])) for v, top in zip(low, self.v_max_)]
            self._pieces = (key, piecewise.network_pieces(self.nets_, ranges, float(self.speed_input(low[1]))))
        return self._pieces[1]

    def speed_input(self, speed: np.ndarray) -> np.ndarray:
        """The network input u (n,) of the clamped speed |qd| (n,) [rad/s]."""
        return (np.arcsinh(np.asarray(speed, dtype=np.float64) / self.v0_) - self.u_mean_) / self.u_scale_

    def load_slope(self) -> float:
        """k [Nm/Nm]: the growth of the friction magnitude per |tau_g| (0 without a load term)."""
        if not self.load_:
            return 0.0
        b1 = np.array([float(net.weights[-1][1, -1]) for net in self.nets_])
        return self.y_scale_ * float(np.mean(acts.softplus(b1))) / self.g_scale_

    def magnitude(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        """|tau_f| above the pre-sliding speed (n,) [Nm], >= 0: y_scale * m, or with the prior
        blend * y_scale * m + (1 - blend) * p."""
        return self._run(signals, sliding=True)

    def set_prior(self, prior: dict | None, blend: float | None = None) -> None:
        """Blend the network with the static curve ``prior`` (PRIOR_KEYS [Nm, rad/s, Nm s/rad,
        Nm/Nm], as ``LuGreModel``'s) by ``blend`` in [0, 1]; None: the network alone."""
        if prior is None:
            self.prior_ = self.blend_ = None
            return
        self.prior_ = {k: float(prior[k]) for k in PRIOR_KEYS}
        self.blend_ = float(blend)

    def prior_magnitude(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        """p = fc + kc |tau_g| + (fs - fc + (ks - kc) |tau_g|) exp(-|qd / vs|^delta) + fv |qd| (n,) [Nm],
        >= 0: the prior's steady friction magnitude (tau_g absent: 0)."""
        p = self.prior_
        qd = np.asarray(signals["qd"], dtype=np.float64)
        g = signals.get("tau_g")
        load = np.zeros_like(qd) if g is None else np.abs(np.asarray(g, dtype=np.float64))
        out = physics.stribeck_shape(qd, p["vs"], p["delta"])
        out *= load * (p["ks"] - p["kc"]) + (p["fs"] - p["fc"])
        out += load * p["kc"] + p["fc"]
        out += np.abs(qd) * p["fv"]
        return out

    def predict(self, signals: dict[str, np.ndarray], state=None) -> tuple[np.ndarray, object]:
        """tau_f (n,) [Nm]. Without the bristle state: stateless (state None). With it (``sigma0_``):
        ``state`` (z [rad], t_last [s]) from the previous batch, or None to start in the steady
        state of the first row; returns (tau_f, state after the last row)."""
        if self.net_ is None:
            raise ValueError("the model is not fitted")
        if self.sigma0_ is None:
            return self._run(signals, sliding=False), None
        if "t" not in signals:
            raise DataError("the log has no column 't' (the pre-sliding state runs in time)")
        t = np.asarray(signals["t"], dtype=np.float64)
        if not t.size:
            return np.empty(0), state
        z, t_last = (None, None) if state is None else state
        qd = np.asarray(signals["qd"], dtype=np.float64)
        tau = self._bristle_curve(signals)
        buf = physics.Buffers(min(t.size, BRISTLE_BLOCK))
        for i in range(0, t.size, BRISTLE_BLOCK):   # blocks whose temporaries stay in the cache
            sl = slice(i, i + BRISTLE_BLOCK)
            z = physics.lugre_friction(qd[sl], tau[sl], 0.0, self.sigma0_, 0.0, physics.intervals(t[sl], t_last), z,
                                       out=tau[sl], buffers=buf)[1]
            t_last = float(t[sl][-1])
        return tau, (z, t_last)

    def _bristle_curve(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        """g = the magnitude, floored at G_MIN (n,) [Nm]."""
        g = self.magnitude(signals)
        return np.maximum(g, G_MIN, out=g)

    @staticmethod
    def _bristles(qd: np.ndarray, g: np.ndarray, dt: np.ndarray, sigma0: float,
                  z0: float | None) -> tuple[np.ndarray, float]:
        """tau_f = sigma0 z (n,) [Nm] and the last z [rad] for speeds qd (n,), curve g (n,) and
        intervals dt (n,) [s] (``physics.lugre_friction`` without damping and viscous term)."""
        return physics.lugre_friction(qd, g, 0.0, sigma0, 0.0, dt, z0)

    def fit_bristles(self, sig: dict[str, np.ndarray], target: np.ndarray, rows: np.ndarray,
                     slow: np.ndarray | None = None, min_gain: float | None = None) -> float:
        """Set ``sigma0_`` [Nm/rad] to the least mean squared error of tau_f against ``target`` (n,)
        [Nm] over ``rows`` (indices), the state run over every row of ``sig`` in order: a grid of
        bristle deflections g_typ / sigma0 over DEFLECTION_RANGE (g_typ the median magnitude over
        ``rows``), refined by a bounded scalar search. When that error is not ``min_gain`` below
        the stiffest state's (``rows`` do not show the stiffness: the state has settled on them),
        it is fitted again over ``rows`` and ``slow`` (indices of rows of slow motion, where a
        reversal passes), if given (then with ``min_gain``: train-base's, ``learning.MIN_GAIN``).
        Returns that error, rooted [Nm]."""
        if slow is not None and min_gain is None:
            raise ValueError("fit_bristles: slow rows need min_gain")
        rmse, ratio = self._fit_bristles(sig, target, rows)
        if slow is not None and len(slow) and ratio > 1.0 - min_gain:
            rmse = self._fit_bristles(sig, target, np.union1d(rows, slow))[0]
        return rmse

    def _fit_bristles(self, sig, target, rows) -> tuple[float, float]:
        """``fit_bristles`` over ``rows`` alone: (rooted error [Nm], its ratio to the stiffest state's)."""
        from scipy.optimize import minimize_scalar

        self.sigma0_ = None
        qd = np.asarray(sig["qd"], dtype=np.float64)
        g = self._bristle_curve(sig)
        dt = physics.intervals(np.asarray(sig["t"], dtype=np.float64))
        y = np.asarray(target, dtype=np.float64)[rows]
        g_typ = float(np.median(g[rows]))

        def cost(log_deflection: float) -> float:
            tau = self._bristles(qd, g, dt, g_typ / 10.0 ** log_deflection, None)[0]
            return float(np.mean((tau[rows] - y) ** 2))

        lo, hi = (float(np.log10(b)) for b in DEFLECTION_RANGE)
        grid = np.linspace(lo, hi, 17)
        costs = [cost(x) for x in grid]
        k = int(np.argmin(costs))
        res = minimize_scalar(cost, bounds=(grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]),
                              method="bounded", options={"xatol": 1e-3})
        best = float(res.x) if res.fun < costs[k] else float(grid[k])
        self.sigma0_ = g_typ / 10.0 ** best
        rmse = float(np.sqrt(min(res.fun, costs[k])))
        return rmse, rmse / float(np.sqrt(costs[0]))

    def _run(self, signals: dict[str, np.ndarray], sliding: bool) -> np.ndarray:
        """y_scale * head output (n,), in chunks (``predict_in_chunks``); ``sliding``: c = 1. The network
        runs in float32 (``precision="single"``) or float64 (``"double"``, as exported C code); from
        PIECES_ROWS rows on, the magnitude comes from ``magnitude_pieces`` (double to 1e-12)."""
        n = len(signals["qd"]) if "qd" in signals else 0
        if self.precision not in ("single", "double"):
            raise ValueError(f"precision must be 'single' or 'double', not {self.precision!r}")
        out = np.empty(n, dtype=np.float64)
        # terms of weight 0 are left out (they would add 0): the networks at blend 0, the prior at
        # blend 1, the extrapolation when both slopes are 0
        uses_net = self.prior_ is None or self.blend_ != 0.0
        uses_prior = self.prior_ is not None and self.blend_ != 1.0
        slopes = uses_net and self.v_max_ is not None and max(self.slope_) > 0.0
        pieces = self.magnitude_pieces() if uses_net and n >= PIECES_ROWS else None
        nets = [] if pieces is not None else [
            net.astype(np.float64) if self.precision == "double" else net for net in self.nets_]
        dtype = np.float64 if pieces is not None else nets[0].dtype
        load = self.load_slope() * self.g_scale_ if pieces is not None else 0.0   # y_scale mean softplus(b1)

        def run(part: list[tuple[int, int]]) -> None:
            ws = [None] * len(nets)
            for start, stop in part:
                rows = {k: v[start:stop] for k, v in signals.items() if k in ("qd", "tau_g")}
                if uses_net or not sliding:
                    x = self._rows(rows, dtype, sliding)
                c = 1.0 if sliding else x[2]
                if not uses_net:
                    out[start:stop] = 0.0
                if pieces is not None:   # y_scale c (m + mean softplus(b1) |tau_g| / g_scale)
                    out[start:stop] = (pieces(x[0], x[1]) * self.y_scale_ + load * x[3]) * c
                for k, net in enumerate(nets if uses_net else ()):
                    if ws[k] is None or ws[k].n != stop - start:
                        ws[k] = net.workspace(stop - start, backward=False)
                    ws[k].set_inputs(x)
                    if k == 0:
                        np.multiply(net.forward(ws[k])[0], self.y_scale_, out=out[start:stop])
                    else:
                        out[start:stop] += net.forward(ws[k])[0] * self.y_scale_
                if len(nets) > 1 and uses_net:
                    out[start:stop] /= len(nets)
                if slopes:
                    qd = signals["qd"][start:stop]
                    if qd.max() > self.v_max_[0] or qd.min() < -self.v_max_[1]:   # a row beyond v_max
                        beyond = np.abs(qd) - self._by_direction(qd, self.v_max_)
                        grow = self._by_direction(qd, self.slope_) * np.maximum(beyond, 0.0) * self.y_scale_
                        out[start:stop] += grow * c
                if uses_prior:
                    out[start:stop] *= self.blend_
                    out[start:stop] += (1.0 - self.blend_) * c * self.prior_magnitude(rows)

        predict_in_chunks(n, run)
        return out

    # ------------------------------------------------------------------ files

    _SCALARS = ("v0", "v_ps", "g_scale", "u_mean", "u_scale", "y_scale")

    def get_params(self) -> dict:
        params = {"hidden_sizes": list(self.hidden_sizes), "activation": self.activation,
                  "training": {"steps": self.steps, "epochs": self.epochs, "lr": self.lr,
                               "batch_size": self.batch_size, "eval_every": self.eval_every,
                               "schedule": self.schedule, "patience": self.patience},
                  "velocity_scale": self.velocity_scale, "presliding_speed": self.presliding_speed,
                  "units": self.units}
        if self.net_ is not None:
            params["network"] = self.net_.spec()
            if len(self.nets_) > 1:
                params["members"] = len(self.nets_)
            params["scales"] = {key: getattr(self, f"{key}_") for key in self._SCALARS}
            if not self.load_:
                params["load"] = False
            if self.v_max_ is not None:
                params["extrapolation"] = {"v_max": list(self.v_max_), "slope": list(self.slope_)}
                if self.v_min_ is not None:
                    params["extrapolation"]["v_min"] = list(self.v_min_)
            if self.sigma0_ is not None:
                params["bristles"] = {"sigma0": self.sigma0_}
            if self.prior_ is not None:
                params["prior"] = {**self.prior_, "blend": self.blend_}
            params["fitted"] = training_params(self)
        return params

    def get_arrays(self) -> dict[str, np.ndarray]:
        if self.net_ is None:
            return {}
        arrays = {f"{_member(k)}W{i}": w.copy() for k, net in enumerate(self.nets_) for i, w in enumerate(net.weights)}
        arrays.update(training_arrays(self))
        return arrays

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "DissipativeFriction":
        model = cls(hidden_sizes=params["hidden_sizes"], activation=params.get("activation", "elu"),
                    units=params.get("units"), velocity_scale=params.get("velocity_scale", "auto"),
                    presliding_speed=params.get("presliding_speed", "auto"), **training_options(params))
        scales = params["scales"]
        for key in cls._SCALARS:
            value = scales[key]
            if not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f"scale {key} is not a finite number")
            if key != "u_mean" and not value > 0:
                raise ValueError(f"scale {key} must be positive")
            setattr(model, f"{key}_", float(value))
        model.load_ = params.get("load", True)
        if not isinstance(model.load_, bool):
            raise ValueError(f"damaged load flag {model.load_!r}")
        members = params.get("members", 1)
        if not is_count(members, 1):
            raise ValueError(f"damaged member count {members!r}")
        nets = []
        for k in range(members):
            net = model.new_network()
            if params.get("network", {}).get("head") != net.head.name:
                raise ValueError("the network does not match the model")
            net.set_weights([arrays[f"{_member(k)}W{i}"] for i in range(len(net.shapes))])
            if net.theta[net.frozen].any():
                raise ValueError("the load slope depends on the speed")
            nets.append(net)
        model.nets_ = nets
        extra = params.get("extrapolation")
        if extra is not None:
            v_max, slope = extra.get("v_max"), extra.get("slope")
            if not (_pair(v_max) and _pair(slope) and min(v_max) > 0 and min(slope) >= 0):
                raise ValueError(f"damaged extrapolation {extra!r}")
            model.v_max_, model.slope_ = (float(v_max[0]), float(v_max[1])), (float(slope[0]), float(slope[1]))
            v_min = extra.get("v_min")      # absent in models written before it: no limit below
            if v_min is not None:
                if not (_pair(v_min) and 0 < min(v_min) and v_min[0] <= v_max[0] and v_min[1] <= v_max[1]):
                    raise ValueError(f"damaged extrapolation {extra!r}")
                model.v_min_ = (float(v_min[0]), float(v_min[1]))
        bristles = params.get("bristles")
        if bristles is not None:
            sigma0 = bristles.get("sigma0") if isinstance(bristles, dict) else None
            if not (is_finite_number(sigma0) and sigma0 > 0):
                raise ValueError(f"damaged bristle parameters {bristles!r}")
            model.sigma0_ = float(sigma0)
        prior = params.get("prior")
        if prior is not None:
            if not (isinstance(prior, dict) and all(is_finite_number(prior.get(k)) for k in PRIOR_KEYS + ("blend",))
                    and min(prior[k] for k in PRIOR_KEYS) >= 0 and prior["vs"] > 0 and prior["delta"] > 0
                    and 0 <= prior["blend"] <= 1):
                raise ValueError(f"damaged prior {prior!r}")
            model.set_prior(prior, prior["blend"])
        load_training(model, params, arrays)
        return model

    # ------------------------------------------------------------------ people

    def describe(self) -> str:
        tau, v = self.units.get("tau", "Nm"), self.units.get("qd", "rad/s")
        act = _describe_activation(self.activation)
        lines = [f"{self.kind}: {self.label}",
                 "  tau_f = y_scale tanh(qd / v_ps) (softplus(r0) + softplus(b1) |tau_g| / g_scale)"
                 if self.sigma0_ is None else
                 "  tau_f = sigma0 z, dz/dt = qd - sigma0 |qd| z / g, g = y_scale (softplus(r0) + softplus(b1) "
                 "|tau_g| / g_scale)",
                 f"  r0 = NN(asinh(|qd| / v0), sign(qd)); hidden layers: "
                 f"{' | '.join(f'{n} {act}' for n in self.hidden_sizes)}; linear output"]
        if self.net_ is None:
            return "\n".join(lines + ["  (not fitted)"])
        if len(self.nets_) > 1:
            lines.append(f"  the mean of {len(self.nets_)} such networks (r0 and b1 each), trained on "
                         "different blocks of the log")
        lines += [f"  {sum(net.n_params for net in self.nets_)} parameters",
                  f"  v0 {self.v0_:.4g} {v}, pre-sliding speed v_ps {self.v_ps_:.4g} {v}, "
                  f"g_scale {self.g_scale_:.4g} {tau}, y_scale {self.y_scale_:.4g} {tau}",
                  f"  load slope k = y_scale softplus(b1) / g_scale = {self.load_slope():.4g} {tau}/{tau}"
                  if self.load_ else "  no load term: |tau_g| varied too little over the training rows to show a "
                  "load slope (as identify decides kc = ks = 0)"]
        if self.v_min_ is not None:
            lines.append(f"  below the slowest training speeds (+{self.v_min_[0]:.4g} / -{self.v_min_[1]:.4g} {v}) the "
                         "magnitude holds its level there")
        if self.v_max_ is not None:
            lines.append(f"  beyond the top training speeds (+{self.v_max_[0]:.4g} / -{self.v_max_[1]:.4g} {v}) the "
                         f"magnitude grows by {self.y_scale_ * self.slope_[0]:.4g} / "
                         f"{self.y_scale_ * self.slope_[1]:.4g} {tau} per {v}")
        if self.prior_ is not None:
            p = self.prior_
            lines.append(f"  blended with the LuGre static curve p by lambda = {self.blend_:.3g}: magnitude lambda "
                         f"y_scale m + (1 - lambda) p; p: fc {p['fc']:.4g}, fs {p['fs']:.4g} {tau}, vs {p['vs']:.4g} "
                         f"{v}, delta {p['delta']:.3g}, fv {p['fv']:.4g} {tau} s/{self.units.get('q', 'rad')}, "
                         f"kc {p['kc']:.3g}, ks {p['ks']:.3g}")
        if self.sigma0_ is not None:
            q = self.units.get("q", "rad")
            lines.append(f"  pre-sliding (bristle) state z: sigma0 {self.sigma0_:.4g} {tau}/{q} (deflection y_scale / "
                         f"sigma0 {self.y_scale_ / self.sigma0_:.3g} {q}); in steady sliding tau_f = sign(qd) g")
        how = (f"{self.epochs} epochs of mini-batches of {self.batch_size}" if self.epochs is not None
               else f"{self.steps_} {'full-batch' if not self.batch_size else f'mini-batch ({self.batch_size})'} steps")
        held = (f"{self.n_val_} for validation" if len(self.nets_) == 1 else
                "each network trained on all but one fold of them, validated on that one")
        lines.append(f"  trained with Adam (lr {self.lr:g}) for {how} on {self.n_train_} samples "
                     f"({held}); weights kept from step {self.best_step_}")
        return "\n".join(lines)


def _member(k: int) -> str:
    """Prefix of member k's arrays: none for the first (a single network's file), "M{k}_" after."""
    return f"M{k}_" if k else ""


def _pair(value) -> bool:
    """Two finite numbers."""
    return isinstance(value, list) and len(value) == 2 and all(is_finite_number(x) for x in value)
