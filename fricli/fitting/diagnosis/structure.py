"""Structure left in a residual that no candidate explains: over time, velocity and position.

The residual e (n,) [Nm] left after the selected effects (held-out) is tested three ways
against white noise that does not depend on the motion:

- time: the Hann-windowed periodogram of e over t. The noise floor is the median bin power
  divided by ln 2 (white noise gives exponentially distributed bin powers); bins above the
  floor times ln(bins / alpha) are structured, and their power above the floor is the
  structured share. Where: the frequency of the strongest such bin [Hz].
- velocity and position: e averaged in quantile bins of qd (or q); the between-bin sum of
  squares beyond what the within-bin variance explains by chance (a one-way analysis of
  variance, F test at alpha) is the structured share. Where: the range of the strongest bins.

Each share is a part of the residual's variance (0-1); the views overlap (a ripple in q is
also periodic in time at constant speed), so the overall share is the largest of the three.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

BINS = 40                 # quantile bins over velocity and position
MIN_BIN_ROWS = 30
SIGNIFICANT_Z = 3.0       # a bin mean this many standard errors from zero counts as where structure sits


@dataclasses.dataclass
class View:
    """Structure over one variable: share (0-1) of the residual variance, significant or not,
    and where it sits (a frequency [Hz] or a range [lo, hi] in the variable's unit)."""

    share: float
    significant: bool
    where: dict

    def to_json(self) -> dict:
        return {"share": self.share, "significant": self.significant, **self.where}


@dataclasses.dataclass
class Structure:
    time: View
    velocity: View
    position: View | None = None    # None for a log without q

    @property
    def share(self) -> float:
        return max(self.views().values(), key=lambda v: v.share).share

    @property
    def main(self) -> str:
        return max(self.views().items(), key=lambda kv: kv[1].share)[0]

    def views(self) -> dict[str, View]:
        views = {"time": self.time, "velocity": self.velocity, "position": self.position}
        return {k: v for k, v in views.items() if v is not None}

    def to_json(self) -> dict:
        return {"share": self.share, "main": self.main, **{k: v.to_json() for k, v in self.views().items()}}

    def line(self, tau_unit: str, v_unit: str, q_unit: str) -> str:
        """One line for people."""
        if self.share < SMALL_SHARE:
            return (f"what is left looks like noise: {100 * self.share:.0f} % of its variance is structured "
                    f"(over time, velocity or position)")
        view = self.views()[self.main]
        if self.main == "time":
            f = view.where["frequency_hz"]
            at = f"periodic in time at {f:.3g} Hz (period {1 / f:.3g} s)" if f > 0 else "a slow trend in time"
        else:
            lo, hi = view.where["range"]
            unit = v_unit if self.main == "velocity" else q_unit
            at = f"at rest (velocity 0 {unit})" if self.main == "velocity" and lo == hi == 0 else \
                f"over {self.main} {span(lo, hi)} {unit}"
            a, b = view.where.get("extent") or (lo, hi)
            if not (self.main == "velocity" and lo == hi == 0) and (hi - lo) < NARROW * (b - a):
                # quantile bins: a narrow range is where the joint dwells, not a feature of the travel
                at += (f" ({100 * view.where.get('rows', 0.0):.0f} % of the rows, where the joint dwells; its "
                       f"{self.main} spans {a:.3g} .. {b:.3g} {unit})")
        return (f"unexplained structure: {100 * self.share:.0f} % of what is left is not noise, {at}; "
                f"no candidate effect describes it")


SMALL_SHARE = 0.1
NARROW = 0.05     # a range narrower than this share of the variable's span is named with its rows


def span(lo: float, hi: float, digits: int = 2) -> str:
    """``"lo .. hi"`` with as many decimals as show the width hi - lo to ``digits`` significant
    digits (and each bound to at least ``digits + 1``): 0.01113 .. 0.01118, not 0.0111 .. 0.0112."""
    width = abs(hi - lo)
    big = max(abs(lo), abs(hi))
    if big == 0:
        return "0 .. 0"
    if width == 0:
        return f"{lo:.{digits + 1}g} .. {hi:.{digits + 1}g}"
    top = int(np.floor(np.log10(big)))
    sig = max(digits + 1, top - int(np.floor(np.log10(width))) + digits)
    return f"{lo:.{sig}g} .. {hi:.{sig}g}"


def over_time(e: np.ndarray, t: np.ndarray, alpha: float) -> View:
    n = len(e)
    dt = float(np.median(np.diff(t))) if n > 1 else 0.0
    if n < 16 or dt <= 0:
        return View(0.0, False, {"frequency_hz": None})
    x = (e - e.mean()) * np.hanning(n)
    power = np.abs(np.fft.rfft(x))[1:] ** 2
    freq = np.fft.rfftfreq(n, dt)[1:]
    total = float(power.sum())
    if total <= 0:
        return View(0.0, False, {"frequency_hz": None})
    floor = float(np.median(power)) / math.log(2.0)
    high = power > floor * math.log(len(power) / alpha)
    share = float((power[high] - floor).sum()) / total if high.any() else 0.0
    peak = float(freq[int(np.argmax(np.where(high, power, -1.0)))]) if high.any() else None
    return View(share, bool(high.any()), {"frequency_hz": peak})


def over_variable(e: np.ndarray, x: np.ndarray, alpha: float) -> View:
    n = len(e)
    bins = min(BINS, n // MIN_BIN_ROWS)
    if bins < 3 or np.ptp(x) <= 0:
        return View(0.0, False, {"range": None})
    order = np.argsort(x, kind="stable")
    groups = np.array_split(order, bins)
    counts = np.array([len(g) for g in groups], dtype=np.float64)
    means = np.array([e[g].mean() for g in groups])
    grand = float(e.mean())
    ssb = float(np.sum(counts * (means - grand) ** 2))
    ssw = float(sum(np.sum((e[g] - m) ** 2) for g, m in zip(groups, means)))
    sst = ssb + ssw
    if sst <= 0:
        return View(0.0, False, {"range": None})
    within = ssw / (n - bins)
    from scipy import special  # the F tail of scipy.stats.f.sf, without importing scipy.stats (a quarter second)

    f = (ssb / (bins - 1)) / within if within > 0 else math.inf
    significant = bool(special.fdtrc(bins - 1, n - bins, f) < alpha)
    share = max(0.0, ssb - (bins - 1) * within) / sst
    z = (means - grand) / np.sqrt(within / counts) if within > 0 else np.zeros(bins)
    k = int(np.argmax(counts * (means - grand) ** 2))
    lo = hi = k
    while lo > 0 and abs(z[lo - 1]) > SIGNIFICANT_Z and np.sign(z[lo - 1]) == np.sign(z[k]):
        lo -= 1
    while hi < bins - 1 and abs(z[hi + 1]) > SIGNIFICANT_Z and np.sign(z[hi + 1]) == np.sign(z[k]):
        hi += 1
    where = [float(x[groups[lo]].min()), float(x[groups[hi]].max())] if significant else None
    if where is None:
        return View(0.0, False, {"range": None})
    rows = float(counts[lo:hi + 1].sum()) / n
    return View(share, True, {"range": where, "rows": rows, "extent": [float(x.min()), float(x.max())]})


def analyse(e: np.ndarray, signals: dict[str, np.ndarray], alpha: float) -> Structure:
    """Structure of the residual e (n,) over t, qd and q (signals of the log; not over q when the
    log has no position)."""
    e = np.asarray(e, dtype=np.float64)
    return Structure(time=over_time(e, signals["t"], alpha),
                     velocity=over_variable(e, signals["qd"], alpha),
                     position=over_variable(e, signals["q"], alpha) if "q" in signals else None)
