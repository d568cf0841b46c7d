"""The extended LuGre friction model (kind ``lugre``).

    Fc(tau_l) = Fc + kc*|tau_g|,  Fs(tau_l) = Fs + ks*|tau_g|                  [Nm]
    g(v)      = Fc(tau_l) + (Fs(tau_l) - Fc(tau_l)) * exp(-|v/vs|^delta)       [Nm], > 0
    dz/dt     = v - sigma0*|v|/g * z                                           [rad/s]
    tau_f     = sigma0*z + sigma1*dz/dt + Fv*v                                 [Nm]

In steady sliding (constant v) tau_f = sign(v)*g(v) + Fv*v. Optional effects, absent by
default: direction asymmetry (``fc_neg``, ``fs_neg``, ``fv_neg`` used for v < 0) and
temperature dependence (Fc, Fs scaled by 1 - alpha_c*(T - t_ref), Fv by exp(-alpha_v*(T - t_ref))).
The bristle state is integrated exactly for v and g held over each sample interval (the update of
``fricli.numerics.physics``, a linear recurrence solved with BLAS ``dtbsv``; see docs/lugre.md). A linear
axis uses the same equations in m, m/s and N.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from fricli.numerics import physics
from fricli.core.errors import DataError
from fricli.models import register
from fricli.models.base import FrictionModel, parameter_info

CHUNK = 1 << 16           # rows per internal block: keeps the temporaries in cache
_G_MIN = 1e-12            # floor on the Stribeck curve g [Nm], so the bristle rate stays finite


STATIC = ("fc", "fs", "vs", "delta", "fv", "kc", "ks")
DYNAMIC = ("sigma0", "sigma1")
OPTIONAL = ("fc_neg", "fs_neg", "fv_neg", "t_ref", "alpha_c", "alpha_v")

# name -> (unit on a rotary axis, unit on a linear axis, meaning)
PARAM_INFO = parameter_info(*STATIC, *DYNAMIC, *OPTIONAL)


# parameters a dissipative friction model never has below 0 (a model file with one is damaged)
NON_NEGATIVE = ("fc", "fs", "fv", "sigma1", "fc_neg", "fs_neg", "fv_neg")


def check_numbers(params: dict, required, optional=()) -> None:
    """ValueError unless every ``required`` parameter is a number (a JSON number, not a string or a
    boolean) and every ``optional`` one present is a number or null."""
    for k in tuple(required) + tuple(optional):
        value = params.get(k)
        if value is None and k in optional:
            continue
        if k not in params:
            raise ValueError(f"parameter {k!r} is missing")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"parameter {k!r} is {type(value).__name__} {value!r}, not a number")


def unit_of(name: str, axis: str = "rotary") -> str:
    rot, lin, _ = PARAM_INFO[name]
    return lin if axis == "linear" else rot


@register
class LuGreModel(FrictionModel):
    """Extended LuGre model with load dependence; parameters in canonical units (see module doc).

    ``predict`` carries the state (z [rad], t_last [s]) from one batch of rows to the next.
    """

    kind = "lugre"

    def __init__(self, fc: float, fs: float, vs: float, delta: float, fv: float, kc: float = 0.0,
                 ks: float = 0.0, sigma0: float = 1e4, sigma1: float = 0.0, *, fc_neg: float | None = None,
                 fs_neg: float | None = None, fv_neg: float | None = None, t_ref: float | None = None,
                 alpha_c: float = 0.0, alpha_v: float = 0.0, axis: str = "rotary"):
        self.fc, self.fs, self.vs, self.delta, self.fv = float(fc), float(fs), float(vs), float(delta), float(fv)
        self.kc, self.ks, self.sigma0, self.sigma1 = float(kc), float(ks), float(sigma0), float(sigma1)
        self.fc_neg = None if fc_neg is None else float(fc_neg)
        self.fs_neg = None if fs_neg is None else float(fs_neg)
        self.fv_neg = None if fv_neg is None else float(fv_neg)
        self.t_ref = None if t_ref is None else float(t_ref)
        self.alpha_c, self.alpha_v = float(alpha_c), float(alpha_v)
        if axis not in ("rotary", "linear"):
            raise ValueError(f"axis must be rotary or linear, not {axis!r}")
        self.axis = axis
        values = [getattr(self, k) for k in STATIC + DYNAMIC + ("alpha_c", "alpha_v")]
        values += [getattr(self, k) for k in OPTIONAL if getattr(self, k) is not None]
        if not all(math.isfinite(x) for x in values):
            raise ValueError("non-finite parameter")
        if self.vs <= 0 or self.delta <= 0 or self.sigma0 <= 0:
            raise ValueError("vs, delta and sigma0 must be positive")

    # ------------------------------------------------------------------ options

    @property
    def asymmetric(self) -> bool:
        return self.fc_neg is not None or self.fs_neg is not None or self.fv_neg is not None

    @property
    def thermal(self) -> bool:
        return self.t_ref is not None and (self.alpha_c != 0.0 or self.alpha_v != 0.0)

    @property
    def loaded(self) -> bool:
        return self.kc != 0.0 or self.ks != 0.0

    def negative_levels(self) -> tuple[float, float, float]:
        """(Fc, Fs, Fv) used for v < 0; Fs keeps the positive side's Stribeck bump Fs - Fc."""
        fc_n = self.fc if self.fc_neg is None else self.fc_neg
        fs_n = self.fs_neg if self.fs_neg is not None else self.fs + (fc_n - self.fc)
        fv_n = self.fv if self.fv_neg is None else self.fv_neg
        return fc_n, fs_n, fv_n

    # --------------------------------------------------------------- equations

    def _levels(self, v: np.ndarray, tau_g: np.ndarray | None, temp: np.ndarray | None):
        """Fc(tau_l), Fs(tau_l) [Nm] and Fv, each (n,) or scalar, for velocities v (n,)."""
        if self.asymmetric:
            fc_n, fs_n, fv_n = self.negative_levels()
            neg = v < 0
            fc = np.where(neg, fc_n, self.fc)
            fs = np.where(neg, fs_n, self.fs)
            fv = np.where(neg, fv_n, self.fv)
        else:
            fc, fs, fv = self.fc, self.fs, self.fv
        if self.loaded and tau_g is not None:
            load = np.abs(tau_g)
            fc = fc + self.kc * load
            fs = fs + self.ks * load
        if self.thermal:
            dT = temp - self.t_ref
            scale = 1.0 - self.alpha_c * dT
            fc = fc * scale
            fs = fs * scale
            if self.alpha_v != 0.0:
                fv = fv * np.exp(-self.alpha_v * dT)
        return fc, fs, fv

    def _inputs(self, signals: dict[str, np.ndarray]):
        v = signals["qd"]
        tau_g = signals.get("tau_g") if self.loaded else None
        temp = None
        if self.thermal:
            temp = signals.get("temp")
            if temp is None:
                raise DataError("the model depends on temperature but the log has no 'temp' column")
        return v, tau_g, temp

    def steady_state(self, v: np.ndarray, tau_g: np.ndarray | None = None,
                     temp: np.ndarray | None = None) -> np.ndarray:
        """Friction (n,) [Nm] in steady sliding at constant velocity v (n,): sign(v)*g + Fv*v."""
        v = np.asarray(v, dtype=np.float64)
        fc, fs, fv = self._levels(v, tau_g, temp)
        g = np.maximum(physics.stribeck(v, fc, fs, self.vs, self.delta), _G_MIN)
        return np.sign(v) * g + fv * v

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """Friction tau_f (n,) [Nm] for signals t [s], qd [rad/s] (and tau_g, temp when used).

        ``state`` is (z [rad], t_last [s]) from the previous batch, or None to start in the
        steady state of the first sample. Returns (tau_f, state after the last sample).
        """
        t = np.asarray(signals["t"], dtype=np.float64)
        v, tau_g, temp = self._inputs(signals)
        v = np.asarray(v, dtype=np.float64)
        n = len(t)
        out = np.empty(n)
        if n == 0:
            return out, state
        z, t_last = (None, None) if state is None else state
        buf = physics.Buffers(min(n, CHUNK))
        for i in range(0, n, CHUNK):
            sl = slice(i, i + CHUNK)
            ts = t[sl]
            dt = physics.intervals(ts, t_last)
            z = self._chunk(v[sl], None if tau_g is None else tau_g[sl], None if temp is None else temp[sl],
                            dt, z, out[sl], buf)
            t_last = float(ts[-1])
        return out, (z, t_last)

    def _chunk(self, v, tau_g, temp, dt, z0, out, buf) -> float:
        """One block of ``predict``, in place into ``out``; returns the last bristle state."""
        fc, fs, fv = self._levels(v, tau_g, temp)
        g = physics.stribeck_shape(v, self.vs, self.delta, out=out)
        g *= np.subtract(fs, fc)
        g += fc
        np.maximum(g, _G_MIN, out=g)
        return physics.lugre_friction(v, g, fv, self.sigma0, self.sigma1, dt, z0,
                                      out=out, buffers=buf)[1]

    def bristle_response(self, signals: dict[str, np.ndarray]) -> Callable[[float, float], np.ndarray]:
        """f(sigma0, sigma1): ``predict(signals)[0]`` of this model with those bristle parameters,
        from the start's steady state. The Stribeck curve, which they do not change, is computed
        once: for fitting them. The array f returns is reused by the next call."""
        t = np.asarray(signals["t"], dtype=np.float64)
        v, tau_g, temp = self._inputs(signals)
        v = np.asarray(v, dtype=np.float64)
        fc, fs, fv = self._levels(v, tau_g, temp)
        g = physics.stribeck_shape(v, self.vs, self.delta)
        g *= np.subtract(fs, fc)
        g += fc
        np.maximum(g, _G_MIN, out=g)
        dt = physics.intervals(t)
        out, buf = np.empty(len(v)), physics.Buffers(len(v))

        def friction(sigma0: float, sigma1: float) -> np.ndarray:
            return physics.lugre_friction(v, g, fv, sigma0, sigma1, dt, out=out, buffers=buf)[0]
        return friction

    def required_inputs(self) -> set[str]:
        need = {"t", "qd"}
        if self.loaded:
            need.add("tau_g")
        if self.thermal:
            need.add("temp")
        return need

    # ------------------------------------------------------------ persistence

    def get_params(self) -> dict:
        out = {k: getattr(self, k) for k in STATIC + DYNAMIC + OPTIONAL}
        out["axis"] = self.axis
        return out

    def parameters(self) -> dict[str, float]:
        """The physical parameters that are set (optional ones only when present)."""
        out = {k: getattr(self, k) for k in STATIC + DYNAMIC}
        if self.asymmetric:
            out.update(zip(("fc_neg", "fs_neg", "fv_neg"), self.negative_levels()))
        if self.thermal:
            out.update(t_ref=self.t_ref, alpha_c=self.alpha_c, alpha_v=self.alpha_v)
        return out

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "LuGreModel":
        known = set(STATIC + DYNAMIC + OPTIONAL + ("axis",))
        unknown = set(params) - known
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}")
        check_numbers(params, STATIC + DYNAMIC, OPTIONAL)
        negative = [k for k in NON_NEGATIVE if params.get(k) is not None and params[k] < 0]
        if negative:
            raise ValueError(f"{negative[0]} = {params[negative[0]]:g} is negative (friction levels, viscous "
                             "friction and damping are at least 0)")
        args = {k: params[k] for k in STATIC + DYNAMIC}
        args.update({k: params.get(k) for k in ("fc_neg", "fs_neg", "fv_neg", "t_ref")})
        args.update(alpha_c=params.get("alpha_c") or 0.0, alpha_v=params.get("alpha_v") or 0.0,
                    axis=params.get("axis", "rotary"))
        return cls(**args)

    def replace(self, **changes) -> "LuGreModel":
        """A copy with some parameters changed."""
        params = self.get_params()
        params.update(changes)
        return type(self).from_parts(params, {}, {})

    def describe(self) -> str:
        lines = [f"extended LuGre model ({self.axis} axis)"]
        for name, value in self.parameters().items():
            _, _, meaning = PARAM_INFO[name]
            lines.append(f"  {name:<8} {value:>12.6g} {unit_of(name, self.axis):<9} {meaning}")
        return "\n".join(lines)
