"""The Generalized Maxwell-Slip friction model (kind ``gms``): hysteresis with non-local memory.

N elasto-plastic (Maxwell-slip) elements in parallel, element i a spring of break-away force
F_i [Nm] that slips once its deflection reaches d_i [rad] (stiffness k_i = F_i / d_i), beside a
sliding curve and the load term:

    z_i[k] = clip(z_i[k-1] + (q[k] - q[k-1]), -d_i, d_i)                      [rad]
    tau_f  = sum_i F_i z_i / d_i                                              (elements)
           + (c(u) + kc |tau_g|) s + fst exp(-(qd / vs)^2) s + fv qd          [Nm]
    s      = sign(qd), held at the last direction of motion while qd = 0 (the Coulomb level is an
             element that slips at once: at rest it holds the force it slipped with)
    c(u)   = fc + the piecewise-linear interpolation of the levels c_j >= 0 at u = j/K, j = 0..K
             (the Coulomb level along the travel; K = 0: fc alone)
    u      = clip((q - q_lo) / (q_hi - q_lo), 0, 1)                           (position within the fitted range)

and, kept apart as a robot-model error (a torque of the position alone that the rigid-body model
left in the friction target: a gravity or cable error, an offset; ``predict_parts``), not friction:

    e(u)   = e_0 + sum_k e_k1 sin(pi k u) + e_k2 cos(pi k u)                  [Nm]

(Al-Bender, Lampaert, Swevers, "The generalized Maxwell-slip model", IEEE TAC 2005, in its
elasto-plastic discrete form.) While an element sticks, its deflection follows the position;
once it reaches its limit it slides with its force held at F_i. The forces F_i, fc, the levels
c_j, fst, fv and kc are >= 0, so the friction is passive: the elements store at
most sum_i F_i d_i / 2 and the clip only removes energy; every other friction term opposes the
motion. Beyond the position range it was fitted on (q_lo, q_hi), the position terms keep their
values at its ends. A linear axis uses the same equations in m and N.

State: the element deflections z (N,) [rad], the previous position [rad], whether a row was
seen, and the held direction s (0 before the first motion). The first row starts with every element slipped in its direction of motion (sign(qd) d_i;
0 at rest), as the LuGre model starts in its steady state; batches carry the state, so a log
predicted in batches equals the whole log predicted at once.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fricli.core.errors import DataError
from fricli.models import register
from fricli.models.base import FrictionModel, parameter_info
from fricli.models.terms import held_sign
from fricli.numerics.physics import stop

# name -> (unit on a rotary axis, unit on a linear axis, meaning)
PARAM_INFO = parameter_info("fc", "fst", "vs", "fv", "kc", "q_lo", "q_hi",
                            fc="Coulomb friction (an element that slips at once)")


def unit_of(name: str, axis: str = "rotary") -> str:
    rot, lin, _ = PARAM_INFO[name]
    return lin if axis == "linear" else rot


def element_states(q: np.ndarray, qd: np.ndarray, deflection: np.ndarray, state: Any = None) -> tuple[np.ndarray, Any]:
    """Element deflections z (n, N) [rad] of the elements with limits ``deflection`` (N,) for
    positions q (n,) and velocities qd (n,) (the direction of the first row's start), and the
    state after the last row: (z (N,), q_prev, started)."""
    d = np.asarray(deflection, dtype=np.float64)
    if len(q) == 0:
        return np.empty((0, len(d))), state
    if state is None:
        z, q_prev = np.sign(qd[0]) * d, float(q[0])
    else:
        z, q_prev, _ = state
    out = stop(q, d, z, q_prev)
    return out, (out[-1].copy(), float(q[-1]), True)


def position_basis(q: np.ndarray, q_lo: float, q_hi: float, k: int) -> np.ndarray:
    """sin(pi j u), cos(pi j u) for j = 1..k (n, 2k), u = clip((q - q_lo) / (q_hi - q_lo), 0, 1)."""
    u = np.clip((np.asarray(q, dtype=np.float64) - q_lo) / (q_hi - q_lo), 0.0, 1.0)
    out = np.empty((len(u), 2 * k))
    for j in range(1, k + 1):
        out[:, 2 * j - 2] = np.sin(np.pi * j * u)
        out[:, 2 * j - 1] = np.cos(np.pi * j * u)
    return out


def hats(q: np.ndarray, q_lo: float, q_hi: float, k: int) -> np.ndarray:
    """The k + 1 piecewise-linear hat functions (n, k + 1) of u = clip((q - q_lo) / (q_hi - q_lo), 0, 1)
    with nodes at u = j/k: a level along the travel interpolated between its values at the nodes."""
    u = np.clip((np.asarray(q, dtype=np.float64) - q_lo) / (q_hi - q_lo), 0.0, 1.0)
    return np.clip(1.0 - np.abs(u[:, None] * k - np.arange(k + 1)[None, :]), 0.0, None)


def _direction_and_elements(q, qd, deflection, state):
    """((element deflections (n, N), held direction of motion (n,)), state after the last row)."""
    elements, s0 = (None, 0.0) if state is None else state
    z, elements = element_states(q, qd, deflection, elements)
    s = held_sign(qd, s0)
    return (z, s), (elements, float(s[-1]) if len(s) else s0)


def columns(signals: dict[str, np.ndarray], deflection: np.ndarray, vs: float, load: bool, q_range=(0.0, 1.0),
            coulomb_ks=(), error_k: int = -1, state: Any = None) -> tuple[np.ndarray, Any]:
    """The regressor of the model: z_i / d_i (N), sign(qd), exp(-(qd/vs)^2) sign(qd), qd, with
    ``load`` |tau_g| sign(qd), then for each K in ``coulomb_ks`` the K + 1 hats along the travel
    times sign(qd), then the robot-model error's offset and position terms (1 + 2 error_k; none for
    -1); and the element state after the last row."""
    qd = np.asarray(signals["qd"], dtype=np.float64)
    s, state = _direction_and_elements(signals["q"], qd, deflection, state)
    z, s = s
    cols = [z / np.asarray(deflection)[None, :], s[:, None], (np.exp(-(qd / vs) ** 2) * s)[:, None], qd[:, None]]
    if load:
        cols.append((np.abs(signals["tau_g"]) * s)[:, None])
    for k in coulomb_ks:
        cols.append(hats(signals["q"], *q_range, k) * s[:, None])
    if error_k >= 0:
        cols += [np.ones((len(qd), 1)), position_basis(signals["q"], *q_range, error_k)]
    return np.hstack(cols), state


@register
class GMSModel(FrictionModel):
    """Maxwell-slip elements (``deflection`` d_i [rad], ``force`` F_i [Nm], both (N,)) beside a
    Coulomb, Stribeck, viscous and load term (module doc); every coefficient >= 0."""

    kind = "gms"

    def __init__(self, deflection, force, *, fc: float = 0.0, fst: float = 0.0, vs: float = 0.01,
                 fv: float = 0.0, kc: float = 0.0, q_lo: float = 0.0, q_hi: float = 1.0, coulomb_pos=(),
                 error=(), axis: str = "rotary"):
        self.deflection = np.asarray(deflection, dtype=np.float64).reshape(-1)
        self.force = np.asarray(force, dtype=np.float64).reshape(-1)
        self.coulomb_pos = np.asarray(coulomb_pos, dtype=np.float64).reshape(-1)
        self.error = np.asarray(error, dtype=np.float64).reshape(-1)
        if self.deflection.shape != self.force.shape:
            raise ValueError("deflection and force must have the same length")
        if len(self.coulomb_pos) == 1 or (len(self.error) and len(self.error) % 2 != 1):
            raise ValueError("the Coulomb level along the travel needs two levels or more, and the error's "
                             "position terms come in sin/cos pairs after its offset")
        if axis not in ("rotary", "linear"):
            raise ValueError(f"axis must be rotary or linear, not {axis!r}")
        self.fc, self.fst, self.vs, self.fv, self.kc = float(fc), float(fst), float(vs), float(fv), float(kc)
        self.q_lo, self.q_hi = float(q_lo), float(q_hi)
        self.axis = axis
        passive = np.concatenate([self.force, [self.fc, self.fst, self.fv, self.kc], self.coulomb_pos])
        values = np.concatenate([passive, [self.q_lo, self.q_hi], self.error,
                                 self.deflection])
        if not np.isfinite(values).all():
            raise ValueError("non-finite parameter")
        if (passive < 0).any():
            raise ValueError("every element force, Coulomb level and fst, fv, kc must be >= 0 (passivity)")
        if (self.deflection <= 0).any() or not self.vs > 0 or not self.q_hi > self.q_lo:
            raise ValueError("element deflections and vs must be > 0, and q_hi > q_lo")

    @property
    def loaded(self) -> bool:
        return self.kc != 0.0

    @property
    def has_model_error(self) -> bool:
        """Whether the model corrects a robot-model error (its position terms and offset)."""
        return bool(len(self.error))

    @property
    def coulomb_k(self) -> int:
        """Intervals K of the Coulomb level along the travel (0: fc alone)."""
        return max(len(self.coulomb_pos) - 1, 0)

    @property
    def error_k(self) -> int:
        """Harmonics of the robot-model error's position terms; -1 without any (no offset either)."""
        return (len(self.error) - 1) // 2 if len(self.error) else -1

    def coulomb_level(self, q: np.ndarray) -> np.ndarray:
        """The Coulomb level c(u) >= 0 (n,) [Nm] at positions q (n,) (module doc)."""
        level = np.full(len(q), self.fc)
        if self.coulomb_k:
            u = np.clip((np.asarray(q, dtype=np.float64) - self.q_lo) / (self.q_hi - self.q_lo), 0.0, 1.0)
            level += np.interp(u * self.coulomb_k, np.arange(self.coulomb_k + 1.0), self.coulomb_pos)
        return level

    def predict_parts(self, signals: dict[str, np.ndarray], state: Any = None):
        """(friction (n,), robot-model error (n,), state) [Nm]; their sum is ``predict``. Each part
        summed term by term, left to right (the exported C code sums in the same order)."""
        qd = np.asarray(signals["qd"], dtype=np.float64)
        if "q" not in signals:
            raise DataError("the log has no column 'q' (the position), which the model's elements deflect with")
        q = np.asarray(signals["q"], dtype=np.float64)
        (z, s), state = _direction_and_elements(q, qd, self.deflection, state)
        friction = np.zeros(len(qd))
        for i in range(len(self.force)):
            friction += self.force[i] * (z[:, i] / self.deflection[i])
        level = self.coulomb_level(q)
        if self.loaded:
            level = level + self.kc * np.abs(signals["tau_g"])
        friction += level * s
        friction += self.fst * (np.exp(-(qd / self.vs) ** 2) * s)
        friction += self.fv * qd
        error = np.zeros(len(qd))
        if len(self.error):
            error += self.error[0]
            if self.error_k:
                error += position_basis(q, self.q_lo, self.q_hi, self.error_k) @ self.error[1:]
        return friction, error, state

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """tau_f (n,) [Nm] with the robot-model error (what the log's friction target holds)."""
        friction, error, state = self.predict_parts(signals, state)
        return friction + error, state

    def friction_only(self) -> "GMSModel":
        """The same model without the robot-model error part: friction alone."""
        return GMSModel(self.deflection, self.force, **dict(self.parameters(), coulomb_pos=self.coulomb_pos),
                        axis=self.axis)

    def energy(self, state) -> float:
        """Energy [J] the elements store in ``state``: sum_i F_i z_i^2 / (2 d_i)."""
        z = np.asarray(state[0][0])
        return float(np.sum(self.force * z * z / (2 * self.deflection)))

    def required_inputs(self) -> set[str]:
        return {"q", "qd"} | ({"tau_g"} if self.loaded else set())

    def parameters(self) -> dict[str, float]:
        return {"fc": self.fc, "fst": self.fst, "vs": self.vs, "fv": self.fv, "kc": self.kc,
                "q_lo": self.q_lo, "q_hi": self.q_hi}

    def steady_parameters(self) -> dict[str, float]:
        """The steady-sliding curve in the LuGre model's terms [Nm, rad/s]: ``fc`` the friction once
        every element slips (the Coulomb level, its mean along the travel, and the elements'
        break-away forces), ``fs`` = fc + fst, ``vs``, ``fv``, ``kc``. How the Coulomb level is shared
        between the elements and fc is not well determined by a fit; their sum is."""
        level = self.fc + float(np.sum(self.force))
        if self.coulomb_k:
            pos = np.asarray(self.coulomb_pos, dtype=np.float64)
            level += float(np.sum(pos) - 0.5 * (pos[0] + pos[-1])) / self.coulomb_k
        return {"fc": level, "fs": level + self.fst, "vs": self.vs, "fv": self.fv, "kc": self.kc}

    def get_params(self) -> dict:
        return {**self.parameters(), "axis": self.axis}

    def get_arrays(self) -> dict[str, np.ndarray]:
        return {"deflection": self.deflection, "force": self.force, "coulomb_pos": self.coulomb_pos,
                "error": self.error}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "GMSModel":
        unknown = set(params) - set(PARAM_INFO) - {"axis"}
        if unknown:
            raise ValueError(f"unknown parameters {sorted(unknown)}")
        return cls(arrays["deflection"], arrays["force"], coulomb_pos=arrays.get("coulomb_pos", ()),
                   error=arrays.get("error", ()), **params)

    def describe(self) -> str:
        q, tau = ("m", "N") if self.axis == "linear" else ("rad", "Nm")
        lines = [f"Generalized Maxwell-slip model, {len(self.force)} elements ({self.axis} axis)"]
        for name, value in self.parameters().items():
            lines.append(f"  {name:<8} {value:>12.6g} {unit_of(name, self.axis):<9} {PARAM_INFO[name][2]}")
        if self.coulomb_k:
            lines.append(f"  Coulomb level along the travel {self.q_lo:.4g} .. {self.q_hi:.4g} {q}: "
                         + ", ".join(f"{c:.4g}" for c in self.coulomb_pos) + f" {tau}")
        if len(self.error):
            lines.append(f"  robot-model error (kept apart from friction): offset {self.error[0]:.4g} {tau}"
                         + (f", {self.error_k} harmonics " + ", ".join(f"{c:.4g}" for c in self.error[1:]) + f" {tau}"
                            if self.error_k else ""))
        for i, (d, f) in enumerate(zip(self.deflection, self.force)):
            lines.append(f"  element {i + 1:<2} slips at {d:.4g} {q} with {f:.4g} {tau} (stiffness {f / d:.4g} {tau}/{q})")
        return "\n".join(lines)
