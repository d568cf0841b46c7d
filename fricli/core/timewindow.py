"""A time window on a log: the rows whose time ``t`` lies in [from, until).

Each bound is either seconds on the log's own time axis (the values of its ``t`` column, in
seconds whatever unit the column is stored in: ``--from 12.5``) or a percentage of the log's
time span, from its first to its last ``t`` (``--from 60%``). ``from`` is inclusive and
``until`` exclusive, so ``--until 60%`` and ``--from 60%`` split a log into two parts with no
row in both. The rows are chosen before anything is derived from them: velocity and
acceleration derived from ``q`` are computed on the window's rows alone.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core import lazy, logs
from fricli.core.errors import DataError

pa = lazy.module("pyarrow")


def seconds_text(x: float) -> str:
    """A time [s] with its milliseconds however large it is (a Unix-epoch clock, 1.7e9 s, reads
    1714000059.9, not 1.714e+09), and as short as ``:g`` otherwise."""
    if not np.isfinite(x) or x == 0:
        return f"{x:g}"
    digits = max(6, int(np.floor(np.log10(abs(x)))) + 4)
    # beyond 17 digits (no clock reaches 1e14 s) only the binary expansion would be printed
    return f"{x:.{digits}g}" if digits <= 17 else repr(float(x))


@dataclasses.dataclass(frozen=True)
class Bound:
    """One end of a window: ``value`` seconds of ``t``, or ``value`` percent of the time span."""

    value: float
    percent: bool = False

    @classmethod
    def parse(cls, text: str) -> "Bound":
        """``"12.5"`` (seconds) or ``"60%"`` (of the time span, 0 to 100); ValueError otherwise."""
        s = text.strip()
        percent = s.endswith("%")
        try:
            value = float(s[:-1] if percent else s)
        except ValueError:
            raise ValueError(f"expected seconds (12.5) or a share of the log's time span (60%), got {text!r}") from None
        if not np.isfinite(value) or (percent and not 0.0 <= value <= 100.0):
            raise ValueError(f"{text!r} is not a finite time or a percentage from 0 to 100")
        return cls(value, percent)

    def seconds(self, first: float, last: float) -> float:
        """The bound in seconds of ``t`` for a log spanning ``first`` to ``last`` [s]."""
        return first + self.value / 100.0 * (last - first) if self.percent else self.value

    def __str__(self) -> str:
        return f"{self.value:g}%" if self.percent else f"{seconds_text(self.value)} s"


@dataclasses.dataclass(frozen=True)
class Window:
    """[start, stop) over ``t``; an absent bound leaves that end open."""

    start: Bound | None = None
    stop: Bound | None = None

    def __bool__(self) -> bool:
        return self.start is not None or self.stop is not None

    def to_json(self) -> dict:
        """As recorded in a model's provenance: the bounds as given ("60%", "12.5 s") or None."""
        return {"from": None if self.start is None else str(self.start),
                "until": None if self.stop is None else str(self.stop)}

    def cutting_nothing(self, t: np.ndarray) -> list[str]:
        """Notes on the bounds given in seconds that lie outside the span of ``t`` (n,) [s], so cut
        nothing: seconds counted from the log's start, on a log whose clock does not start at 0."""
        finite = t[np.isfinite(t)]
        if not finite.size:
            return []
        first, last = float(finite.min()), float(finite.max())
        notes = []
        for option, bound, outside, end, edge in (("--from", self.start, "before", "first", first),
                                                  ("--until", self.stop, "after", "last", last)):
            if bound is not None and not bound.percent and (bound.value < first if end == "first" else bound.value > last):
                notes.append(f"note: {option} {bound} lies {outside} the log's {end} time, t = {seconds_text(edge)} s, "
                             "and cuts nothing: bounds are seconds of the log's own t (from "
                             f"{seconds_text(first)} to {seconds_text(last)} s here) or a share of its span "
                             f"({option} 60%)")
        return notes

    def limits(self, t: np.ndarray) -> tuple[float, float]:
        """(lo, hi) [s] for a log whose times are ``t`` (n,) [s]: the rows lo <= t < hi."""
        finite = t[np.isfinite(t)]
        first, last = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 0.0)
        lo = -np.inf if self.start is None else self.start.seconds(first, last)
        hi = np.inf if self.stop is None else self.stop.seconds(first, last)
        if self.stop is not None and self.stop.percent and self.stop.value == 100.0:
            hi = np.inf   # --until 100% keeps the last row
        return lo, hi


def times(table: pa.Table) -> np.ndarray | None:
    """The ``t`` column [s] (n,) of a log table, NaN where missing; None when the table has no
    numeric ``t`` (the log check reports it)."""
    if "t" not in table.column_names:
        return None
    field, col = table.schema.field("t"), table.column("t")
    if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)):
        return None
    t = np.array(logs.float64_values(col), dtype=np.float64)
    if col.null_count:
        t[np.asarray(col.is_null())] = np.nan
    unit = logs.field_unit(field)
    return t * logs.column_unit("t", unit)[1] if unit is not None else t


def rows(t: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The rows (n,) bool in [lo, hi); rows without a finite time are kept, for the log check
    to report them."""
    return ~((t < lo) | (t >= hi))


def slice_table(table: pa.Table, window: Window | None, name: str = "log", warn=None) -> pa.Table:
    """The rows of a log table in ``window`` (the whole table for None or an open window).
    DataError when the window holds no row; ``warn(line)`` is told of a bound that cuts nothing."""
    if not window:
        return table
    t = times(table)
    if t is None:
        return table
    lo, hi = window.limits(t)
    keep = rows(t, lo, hi)
    if not (keep & np.isfinite(t)).any():
        span = (f"{seconds_text(np.nanmin(t))} to {seconds_text(np.nanmax(t))} s" if np.isfinite(t).any()
                else "no times")
        raise DataError(f"{name}: no rows from {window.start or 'the start'} until {window.stop or 'the end'} "
                        f"(the log's t runs {span})")
    for note in window.cutting_nothing(t) if warn else ():
        warn(note)
    return table if keep.all() else logs.take_rows(table, keep)


def limits_of_file(pf, window: Window, name: str = "log", warn=None) -> tuple[float, float]:
    """(lo, hi) [s] of ``window`` over a Parquet file read in batches (``pq.ParquetFile``): its
    ``t`` column alone is read for the time span. DataError when the window holds no row;
    ``warn(line)`` is told of a bound that cuts nothing."""
    t = times(pf.read(columns=["t"], use_threads=False)) if "t" in pf.schema_arrow.names else None
    if t is None:
        return -np.inf, np.inf
    lo, hi = window.limits(t)
    if not (rows(t, lo, hi) & np.isfinite(t)).any():
        slice_table(pa.table({"t": t}), window, name)   # raises the same DataError
    for note in window.cutting_nothing(t) if warn else ():
        warn(note)
    return lo, hi


def slice_batch(table: pa.Table, lo: float, hi: float) -> pa.Table:
    """The rows of one batch of a log in [lo, hi) (``limits_of_file``)."""
    t = times(table)
    if t is None or (lo == -np.inf and hi == np.inf):
        return table
    keep = rows(t, lo, hi)
    return table if keep.all() else logs.take_rows(table, keep)
