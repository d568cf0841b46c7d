"""The training envelope of a model: where its inputs were when it was fitted.

Every model file records, for the inputs the model reads among ENVELOPE_INPUTS (qd, tau_g,
temp), their ranges over the fitting log and a coarse coverage grid: BINS equal bins per input
between its minimum and maximum (for qd in asinh(qd / qd_scale), qd_scale = 1 % of the top
speed, so the slow speeds get bins of their own), a cell being covered when at least one row of
the fitting log falls into it. A row lies outside the envelope when one of its inputs is outside
its range (or not a number) or its cell is not covered: the model extrapolates there.

Stored in the model file's meta under "envelope" (JSON: inputs, min, max, bins, qd_scale and
the flat indices of the covered cells, C order). Files without it have no envelope and
nothing is reported for them.
"""

from __future__ import annotations

import numpy as np

ENVELOPE_INPUTS = ("qd", "tau_g", "temp")
BINS = 8
QD_SCALE_SHARE = 0.01


class Envelope:
    """Ranges (min, max) and covered grid cells of ``inputs``; ``fit`` or ``from_meta``."""

    def __init__(self, inputs, lo, hi, covered, *, bins: int = BINS, qd_scale: float = 1.0):
        self.inputs = tuple(inputs)
        self.lo, self.hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        self.bins, self.qd_scale = int(bins), float(qd_scale)
        self.covered = np.zeros(self.bins ** len(self.inputs), dtype=bool)
        self.covered[np.asarray(covered, dtype=np.int64)] = True

    @classmethod
    def fit(cls, signals: dict[str, np.ndarray], inputs, *, bins: int = BINS) -> "Envelope":
        """The envelope of ``signals`` (the fitting log's rows) over those of ``inputs`` in
        ENVELOPE_INPUTS that the log has."""
        names = [name for name in ENVELOPE_INPUTS if name in set(inputs) and name in signals]
        qd_scale = 1.0
        if "qd" in names:
            top = float(np.nanmax(np.abs(signals["qd"]))) if len(signals["qd"]) else 0.0
            qd_scale = QD_SCALE_SHARE * top if top > 0 else 1.0
        raw = [np.asarray(signals[name], dtype=np.float64) for name in names]
        finite = np.all([np.isfinite(x) for x in raw], axis=0) if raw else np.zeros(0, dtype=bool)
        lo = [float(x[finite].min()) if finite.any() else 0.0 for x in raw]
        hi = [float(x[finite].max()) if finite.any() else 0.0 for x in raw]
        env = cls(names, lo, hi, [], bins=bins, qd_scale=qd_scale)
        if names and finite.any():
            env.covered[np.unique(env._cells([x[finite] for x in raw]))] = True
        return env

    def _edges(self, i: int) -> np.ndarray:
        """The inner bin edges (bins - 1,) of input i in its own units: equal steps in
        asinh(qd / qd_scale) for qd, in the value for the others."""
        lo, hi = self.lo[i], self.hi[i]
        steps = np.arange(1, self.bins) / self.bins
        if self.inputs[i] != "qd":
            return lo + steps * (hi - lo)
        a, b = np.arcsinh(np.array([lo, hi]) / self.qd_scale)
        return self.qd_scale * np.sinh(a + steps * (b - a))

    def _cells(self, cols: list[np.ndarray]) -> np.ndarray:
        """Flat cell index (n,) of rows: each input's bin is the number of inner edges at or
        below the value (rows outside the ranges get the nearest cell, and NaN the last:
        ``outside`` flags them by their ranges)."""
        flat = np.zeros(len(cols[0]), dtype=np.int64)
        for i, x in enumerate(cols):
            flat *= self.bins
            if self.hi[i] > self.lo[i]:
                flat += np.searchsorted(self._edges(i), x, side="right")
        return flat

    def outside(self, signals: dict[str, np.ndarray]) -> np.ndarray:
        """(n,) bool: rows outside the envelope. A log without one of the inputs counts as 0 for
        it (as the models read it). The same cells as ``_cells``, counted by comparisons
        (number of inner edges <= x) in the smallest integer type that holds every cell: several
        times faster than searchsorted on a batch."""
        n = _rows(signals)
        if not self.inputs:
            return np.zeros(n, dtype=bool)
        kind = np.min_scalar_type(self.covered.size - 1)
        flat = np.zeros(n, dtype=kind)
        inside = np.ones(n, dtype=bool)
        hit = np.empty(n, dtype=bool)
        count = np.empty(n, dtype=kind)
        for i, name in enumerate(self.inputs):
            x = np.asarray(signals[name], dtype=np.float64) if name in signals else np.zeros(n)
            flat *= kind.type(self.bins)
            if self.hi[i] > self.lo[i]:
                count.fill(0)
                for edge in self._edges(i):
                    np.greater_equal(x, edge, out=hit)
                    np.add(count, hit, out=count, casting="unsafe")
                flat += count
            np.greater_equal(x, self.lo[i], out=hit)    # False for NaN
            inside &= hit
            np.less_equal(x, self.hi[i], out=hit)
            inside &= hit
        inside &= np.take(self.covered, flat)
        return np.logical_not(inside, out=inside)

    def covered_grid(self, name: str, values: np.ndarray, other: str, other_values: np.ndarray) -> np.ndarray:
        """(len(other_values), len(values)) bool: points (values of ``name``, values of ``other``)
        inside the envelope, the remaining inputs anywhere in their ranges."""
        x, y = np.meshgrid(values, other_values)
        mask = np.zeros(x.shape, dtype=bool)
        rest = [i for i, n in enumerate(self.inputs) if n not in (name, other)]
        probes = [np.linspace(self.lo[i], self.hi[i], 2 * self.bins + 1) for i in rest] or [np.zeros(1)]
        for combo in np.stack(np.meshgrid(*probes), -1).reshape(-1, len(probes)):
            sig = {name: x.ravel(), other: y.ravel()}
            for j, i in enumerate(rest):
                sig[self.inputs[i]] = np.full(x.size, combo[j])
            mask |= ~self.outside(sig).reshape(x.shape)
        return mask

    def to_meta(self) -> dict:
        return {"inputs": list(self.inputs), "min": self.lo.tolist(), "max": self.hi.tolist(), "bins": self.bins,
                "qd_scale": self.qd_scale, "covered": np.flatnonzero(self.covered).tolist()}

    @classmethod
    def from_meta(cls, meta: dict | None) -> "Envelope | None":
        """The envelope in a model file's meta, None if it has none; ValueError if damaged."""
        if meta is None:
            return None
        try:
            inputs = [str(name) for name in meta["inputs"]]
            bins, covered = int(meta["bins"]), [int(k) for k in meta["covered"]]
            lo = np.asarray(meta["min"], dtype=np.float64)
            hi = np.asarray(meta["max"], dtype=np.float64)
            qd_scale = float(meta.get("qd_scale", 1.0))
        except (KeyError, TypeError, ValueError):
            raise ValueError("damaged training envelope") from None
        if (not 1 <= bins <= 64 or lo.shape != (len(inputs),) or hi.shape != lo.shape
                or not np.isfinite(lo).all() or not np.isfinite(hi).all() or (hi < lo).any()
                or any(k < 0 or k >= bins ** len(inputs) for k in covered) or not qd_scale > 0
                or any(name not in ENVELOPE_INPUTS for name in inputs)):
            raise ValueError("damaged training envelope")
        return cls(inputs, lo, hi, covered, bins=bins, qd_scale=qd_scale)

    def describe(self, units: dict | None = None) -> str:
        units = units or {}
        parts = [f"{name} {a:.4g}..{b:.4g} {units.get(name, '')}".rstrip()
                 for name, a, b in zip(self.inputs, self.lo, self.hi)]
        return (f"{', '.join(parts)}; {int(self.covered.sum())} of {self.covered.size} grid cells covered"
                if parts else "no inputs")


def _rows(signals: dict[str, np.ndarray]) -> int:
    for value in signals.values():
        return len(value)
    return 0


def share_outside(env: Envelope | None, signals: dict[str, np.ndarray]) -> dict | None:
    """{"rows": rows outside, "of": rows, "share": their share} or None without an envelope."""
    if env is None:
        return None
    out = env.outside(signals)
    return {"rows": int(out.sum()), "of": int(out.size), "share": float(out.mean()) if out.size else 0.0}
