"""Regressor terms: named columns built from a log's signals and a base model's prediction.

A term is a JSON-able dict ``{"name": str, "factors": [factor, ...]}``; its value (n,) is the
product of its factors. The diagnosis builds candidate effects from terms, and the augmented
model stores the terms it adds with their coefficients, so a term must be reproducible on
any later log from the constants it carries. Factors:

    {"f": "one"}                                   1
    {"f": "p"}                                     the base model's prediction [Nm]
    {"f": "signal", "name": S}                     signal S (e.g. qd, qdd)
    {"f": "dev", "name": S, "center": c}           S - c (temp, t, any extra column); with "low" and
                                                   "high", S is held within them first (a trend in
                                                   time does not run on beyond the log it was fitted on)
    {"f": "abs", "name": S}                        |S|
    {"f": "overload"}                              |tau_l| - |tau_g|, tau_l = tau_m - tau_dyn - p the load the
                                                   gear holds: what it carries beyond the robot model's gravity
    {"f": "sign"}                                  direction of motion, held at rest
    {"f": "moving"}                                |direction| (0 only before the first motion)
    {"f": "pos"}                                   1 where the direction is positive, else 0
    {"f": "heldgravity"}                           tau_g while moving, held through samples at rest at
                                                   its value when the motion stopped
    {"f": "sat", "scale": s}                       sign(qd) * (1 - exp(-|qd| / s))
    {"f": "sin" | "cos", "name": S, "w": w}        sin(w S), cos(w S)
    {"f": "slip", "d": d}                          z / d, z the deflection [rad or m] of a Maxwell-slip element
                                                   of deflection limit d (the stop operator of q):
                                                   z[k] = clip(z[k-1] + q[k] - q[k-1], -d, d), z = 0
                                                   before the first row (an element at rest); in [-1, 1],
                                                   its coefficient is the element's break-away force

The direction is sign(qd), held through samples at rest at the sign of the last motion: a
joint at rest holds the friction of the direction it last moved in (the bristles stay
deflected); a friction term in the gear torque is held the same way (0 before the first
motion); so is the gravity torque of ``heldgravity``. Both carry over from one batch of rows to
the next as the terms' state, and so do the slip elements' deflections (with the last position).

The load the gear holds is what the motor puts in minus what the motor-side friction and the
inertia take: tau_l = tau_m - tau_dyn - p, with the base model's friction p; that is gravity plus
any external load (tau_g - tau_ext where both are known) from what a controller has
(docs/diagnose.md). Terms read inputs only
(``fricli.core.logs.INPUTS``), never a reference column such as tau_ext; the factors ``gear``,
``absgear``, ``payloadgear`` and ``heldgear`` of older model files read tau_ext and are refused
(``check``).
"""

from __future__ import annotations

import numpy as np

from fricli.core import logs
from fricli.core.errors import DataError, ModelFileError
from fricli.numerics.physics import stop


def factor_inputs(factor: dict) -> set[str]:
    f = factor["f"]
    if f in ("one", "p"):
        return set()
    if f == "overload":
        return {"tau_m", "tau_dyn", "tau_g"}
    if f == "heldgravity":
        return {"qd", "tau_g"}
    if f in ("sign", "moving", "pos", "sat"):
        return {"qd"}
    if f == "slip":
        return {"q"}
    return {factor["name"]}


def inputs(terms: list[dict]) -> set[str]:
    """Signal names the terms read (the base prediction is not a signal)."""
    out: set[str] = set()
    for term in terms:
        for factor in term["factors"]:
            out |= factor_inputs(factor)
    return out


def _signal(sig: dict, name: str) -> np.ndarray:
    if name in logs.REFERENCES:
        raise DataError(f"a model term cannot read the reference column {name!r}")
    if name in sig:
        return sig[name]
    if name in logs.ROBOT_MODEL:
        return logs.column(sig, name)   # refuses with the fix
    raise DataError(f"the log has no column {name!r}, which the model's term needs")


def held_sign(qd: np.ndarray, s0: float = 0.0) -> np.ndarray:
    """sign(qd) (n,), held at the last nonzero value through zeros; s0 before the first motion."""
    return held(np.sign(qd), qd, s0)


def held(x: np.ndarray, qd: np.ndarray, x0: float = 0.0) -> np.ndarray:
    """x (n,) where qd != 0, else its value at the last moving sample; x0 before the first
    (x itself when every row moves)."""
    return hold(x, last_moving(qd), x0)


def last_moving(qd: np.ndarray) -> np.ndarray | None:
    """Index (n,) of each row's last sample with qd != 0 (-1 before the first); None when all move."""
    moving = qd != 0
    if moving.all():
        return None
    idx = np.where(moving, np.arange(len(qd)), -1)
    np.maximum.accumulate(idx, out=idx)
    return idx


def hold(x: np.ndarray, last: np.ndarray | None, x0: float) -> np.ndarray:
    """x (n,) taken at ``last`` (``last_moving``), x0 where it is -1; x itself when ``last`` is None."""
    return x if last is None else np.where(last >= 0, x[np.maximum(last, 0)], x0)


class Columns:
    """Evaluates terms on one batch of signals (n,) with the base prediction p (n,).

    ``state`` is what is held from the previous batch: (direction, gravity torque[, slip]) or a
    direction alone (None: no motion seen yet); slip = (last position, {limit d: deflection z})
    of the slip elements (None: no row seen yet).
    """

    def __init__(self, sig: dict, p: np.ndarray | None = None, state=None):
        self.sig, self.p = sig, p
        self._dir = self._gear = self._last = None
        if state is None or np.isscalar(state):
            s0, g0, slip0 = state, 0.0, None
        else:
            s0, g0, slip0 = (tuple(state) + (None,))[:3]
        self._s0 = 0.0 if s0 is None else float(s0)
        self._g0 = float(g0)
        self._q0, self._z0 = (None, {}) if slip0 is None else (float(slip0[0]), dict(slip0[1]))
        self._z: dict[float, np.ndarray] = {}

    def deflection(self, d: float) -> np.ndarray:
        """z (n,) of the slip element of limit d, from the previous batch's state."""
        d = float(d)
        if d not in self._z:
            q = _signal(self.sig, "q")
            self._z[d] = stop(q, d, self._z0.get(d, 0.0), q[0] if self._q0 is None and len(q) else self._q0)[:, 0]
        return self._z[d]

    def _held(self, x: np.ndarray, x0: float) -> np.ndarray:
        """``held(x, qd, x0)``, with the rows' last moving samples found once."""
        if self._last is None:
            self._last = (last_moving(self.sig["qd"]),)
        return hold(x, self._last[0], x0)

    @property
    def direction(self) -> np.ndarray:
        if self._dir is None:
            self._dir = self._held(np.sign(self.sig["qd"]), self._s0)
        return self._dir

    @property
    def gear(self) -> np.ndarray:
        """tau_l = tau_m - tau_dyn - p (n,) [Nm]: the load the gear holds."""
        if self.p is None:
            raise ValueError("the gear torque needs the base prediction")
        return _signal(self.sig, "tau_m") - _signal(self.sig, "tau_dyn") - self.p

    @property
    def held_gravity(self) -> np.ndarray:
        if self._gear is None:
            self._gear = self._held(_signal(self.sig, "tau_g"), self._g0)
        return self._gear

    @property
    def state(self) -> tuple:
        """(held direction, held gravity torque, slip) after the last row; the gravity torque and
        the slip elements only move on when a term read them."""
        d = self.direction
        zs = {**self._z0, **{k: float(z[-1]) for k, z in self._z.items() if len(z)}}
        q_last = float(self.sig["q"][-1]) if self._z and len(d) else self._q0
        slip_state = None if q_last is None else (q_last, zs)
        if not len(d):
            return self._s0, self._g0, slip_state
        return float(d[-1]), (self._g0 if self._gear is None else float(self._gear[-1])), slip_state

    def factor(self, factor: dict) -> np.ndarray | float:
        f = factor["f"]
        sig = self.sig
        if f == "one":
            return 1.0
        if f == "p":
            if self.p is None:
                raise ValueError("term needs the base prediction")
            return self.p
        if f == "signal":
            return _signal(sig, factor["name"])
        if f == "dev":
            x = _signal(sig, factor["name"])
            if "low" in factor:
                x = np.clip(x, float(factor["low"]), float(factor["high"]))
            return x - float(factor["center"])
        if f == "abs":
            return np.abs(_signal(sig, factor["name"]))
        if f == "overload":
            return np.abs(self.gear) - np.abs(_signal(sig, "tau_g"))
        if f == "sign":
            return self.direction
        if f == "moving":
            return np.abs(self.direction)
        if f == "pos":
            return (self.direction > 0).astype(np.float64)
        if f == "heldgravity":
            return self.held_gravity
        if f == "sat":
            v = sig["qd"]
            return np.sign(v) * -np.expm1(-np.abs(v) / float(factor["scale"]))
        if f == "slip":
            return self.deflection(factor["d"]) / float(factor["d"])
        if f == "sin":
            return np.sin(float(factor["w"]) * _signal(sig, factor["name"]))
        if f == "cos":
            return np.cos(float(factor["w"]) * _signal(sig, factor["name"]))
        raise ValueError(f"unknown term factor {f!r}")

    def value(self, term: dict) -> np.ndarray:
        """The term's column (n,): the product of its factors, in their order (a new array)."""
        n = len(self.sig["t"])
        out = None
        for factor in term["factors"]:
            x = self.factor(factor)
            if out is None:
                out = np.array(np.broadcast_to(x, (n,)), dtype=np.float64)   # 1 x = x: no pass over ones
            else:
                out *= x
        return np.ones(n) if out is None else out

    def combination(self, terms: list[dict], coef: np.ndarray) -> np.ndarray:
        """``matrix(terms) @ coef`` (n,), one column at a time."""
        out = np.zeros(len(self.sig["t"]))
        for term, c in zip(terms, coef):
            column = self.value(term)
            column *= c
            out += column
        return out

    def matrix(self, terms: list[dict]) -> np.ndarray:
        """Columns of all terms, shape (n, len(terms))."""
        n = len(self.sig["t"])
        if not terms:
            return np.zeros((n, 0))
        return np.column_stack([self.value(term) for term in terms])


def value(term: dict, sig: dict, p: np.ndarray | None = None) -> np.ndarray:
    """The term's column (n,) over a whole log."""
    return Columns(sig, p).value(term)


def matrix(terms: list[dict], sig: dict, p: np.ndarray | None = None) -> np.ndarray:
    """Columns of all terms over a whole log, shape (n, len(terms))."""
    return Columns(sig, p).matrix(terms)


def check(term: dict) -> None:
    """Raise ValueError for a malformed term (used when loading model files)."""
    if not isinstance(term, dict) or not isinstance(term.get("name"), str) or not isinstance(term.get("factors"), list):
        raise ValueError("malformed term")
    for factor in term["factors"]:
        if isinstance(factor, dict) and factor.get("f") in READS_REFERENCE:
            raise ModelFileError(f"the term {term['name']!r} reads the reference column tau_ext (factor "
                                 f"{factor['f']!r}, written by an older fricli): refit the model with "
                                 "'fricli diagnose MODEL LOG --fix'")
        if isinstance(factor, dict) and factor.get("name") in logs.REFERENCES:
            raise ModelFileError(f"the term {term['name']!r} reads the reference column {factor['name']!r}: "
                                 "refit the model with 'fricli diagnose MODEL LOG --fix'")
        if not isinstance(factor, dict) or factor.get("f") not in _KNOWN:
            raise ValueError(f"unknown term factor in {term.get('name')!r}")
        need = _KNOWN[factor["f"]]
        missing = [k for k in need if k not in factor]
        if missing:
            raise ValueError(f"term {term['name']!r}: factor {factor['f']!r} lacks {', '.join(missing)}")
        if factor["f"] == "slip" and not (isinstance(factor["d"], (int, float)) and 0 < factor["d"] < np.inf):
            raise ValueError(f"term {term['name']!r}: a slip element's limit d must be a number > 0")


# factors of older model files that read the reference tau_ext (the gear torque as tau_g - tau_ext)
READS_REFERENCE = ("gear", "absgear", "payloadgear", "heldgear")
_KNOWN = {"one": (), "p": (), "signal": ("name",), "dev": ("name", "center"), "abs": ("name",),
          "overload": (), "sign": (), "moving": (), "pos": (), "heldgravity": (),
          "sat": ("scale",), "slip": ("d",),
          "sin": ("name", "w"), "cos": ("name", "w")}


def term(name: str, *factors: dict) -> dict:
    return {"name": name, "factors": list(factors)}


# factor shorthands
ONE = {"f": "one"}
P = {"f": "p"}
SIGN = {"f": "sign"}
MOVING = {"f": "moving"}
POS = {"f": "pos"}
HELDGRAVITY = {"f": "heldgravity"}
OVERLOAD = {"f": "overload"}


def slip_(d: float) -> dict:
    """A Maxwell-slip element of deflection limit d > 0 [rad or m]."""
    return {"f": "slip", "d": float(d)}


def sig_(name: str) -> dict:
    return {"f": "signal", "name": name}


def dev(name: str, center: float, low: float | None = None, high: float | None = None) -> dict:
    out = {"f": "dev", "name": name, "center": float(center)}
    if low is not None:
        out.update(low=float(low), high=float(high))
    return out


def abs_(name: str) -> dict:
    return {"f": "abs", "name": name}
