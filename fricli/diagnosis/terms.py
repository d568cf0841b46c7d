"""Regressor terms: named columns built from a log's signals and a base model's prediction.

A term is a JSON-able dict ``{"name": str, "factors": [factor, ...]}``; its value (n,) is the
product of its factors. The diagnosis builds candidate effects from terms, and the augmented
model stores the terms it adds with their coefficients, so a term must be reproducible on
any later log from the constants it carries. Factors:

    {"f": "one"}                                   1
    {"f": "p"}                                     the base model's prediction [Nm]
    {"f": "signal", "name": S}                     signal S (e.g. qd, qdd)
    {"f": "dev", "name": S, "center": c}           S - c (temp, t, any extra column)
    {"f": "abs", "name": S}                        |S|
    {"f": "sign"}                                  sign(qd)
    {"f": "moving"}                                |sign(qd)|
    {"f": "pos"}                                   1 where qd > 0, else 0
    {"f": "sat", "scale": s}                       sign(qd) * (1 - exp(-|qd| / s))
    {"f": "sin" | "cos", "name": S, "w": w}        sin(w S), cos(w S)
"""

from __future__ import annotations

import numpy as np

from fricli.errors import DataError


def factor_inputs(factor: dict) -> set[str]:
    f = factor["f"]
    if f in ("one", "p"):
        return set()
    if f in ("sign", "moving", "pos", "sat"):
        return {"qd"}
    return {factor["name"]}


def inputs(terms: list[dict]) -> set[str]:
    """Signal names the terms read (the base prediction is not a signal)."""
    out: set[str] = set()
    for term in terms:
        for factor in term["factors"]:
            out |= factor_inputs(factor)
    return out


def _signal(sig: dict, name: str) -> np.ndarray:
    if name in sig:
        return sig[name]
    if name in ("tau_g", "tau_dyn", "tau_ext"):
        return np.zeros_like(sig["t"])
    raise DataError(f"the log has no column {name!r}, which the model's term needs")


def factor_value(factor: dict, sig: dict, p: np.ndarray | None) -> np.ndarray | float:
    f = factor["f"]
    if f == "one":
        return 1.0
    if f == "p":
        if p is None:
            raise ValueError("term needs the base prediction")
        return p
    if f == "signal":
        return _signal(sig, factor["name"])
    if f == "dev":
        return _signal(sig, factor["name"]) - float(factor["center"])
    if f == "abs":
        return np.abs(_signal(sig, factor["name"]))
    if f == "sign":
        return np.sign(sig["qd"])
    if f == "moving":
        return (sig["qd"] != 0).astype(np.float64)
    if f == "pos":
        return (sig["qd"] > 0).astype(np.float64)
    if f == "sat":
        v = sig["qd"]
        return np.sign(v) * -np.expm1(-np.abs(v) / float(factor["scale"]))
    if f == "sin":
        return np.sin(float(factor["w"]) * _signal(sig, factor["name"]))
    if f == "cos":
        return np.cos(float(factor["w"]) * _signal(sig, factor["name"]))
    raise ValueError(f"unknown term factor {f!r}")


def value(term: dict, sig: dict, p: np.ndarray | None = None) -> np.ndarray:
    """The term's column (n,)."""
    n = len(sig["t"])
    out = np.ones(n)
    for factor in term["factors"]:
        out = out * factor_value(factor, sig, p)
    return out


def matrix(terms: list[dict], sig: dict, p: np.ndarray | None = None) -> np.ndarray:
    """Columns of all terms, shape (n, len(terms))."""
    n = len(sig["t"])
    if not terms:
        return np.zeros((n, 0))
    return np.column_stack([value(term, sig, p) for term in terms])


def check(term: dict) -> None:
    """Raise ValueError for a malformed term (used when loading model files)."""
    if not isinstance(term, dict) or not isinstance(term.get("name"), str) or not isinstance(term.get("factors"), list):
        raise ValueError("malformed term")
    for factor in term["factors"]:
        if not isinstance(factor, dict) or factor.get("f") not in _KNOWN:
            raise ValueError(f"unknown term factor in {term.get('name')!r}")
        need = _KNOWN[factor["f"]]
        missing = [k for k in need if k not in factor]
        if missing:
            raise ValueError(f"term {term['name']!r}: factor {factor['f']!r} lacks {', '.join(missing)}")


_KNOWN = {"one": (), "p": (), "signal": ("name",), "dev": ("name", "center"), "abs": ("name",),
          "sign": (), "moving": (), "pos": (), "sat": ("scale",), "sin": ("name", "w"), "cos": ("name", "w")}


def term(name: str, *factors: dict) -> dict:
    return {"name": name, "factors": list(factors)}


# factor shorthands
ONE = {"f": "one"}
P = {"f": "p"}
SIGN = {"f": "sign"}
MOVING = {"f": "moving"}
POS = {"f": "pos"}


def sig_(name: str) -> dict:
    return {"f": "signal", "name": name}


def dev(name: str, center: float) -> dict:
    return {"f": "dev", "name": name, "center": float(center)}


def abs_(name: str) -> dict:
    return {"f": "abs", "name": name}
