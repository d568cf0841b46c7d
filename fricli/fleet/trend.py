"""Wear trends from the fleet history: per joint, friction parameters and fit errors over the days,
relative to the joint's own first days, and a wear flag.

For each joint and parameter p (Coulomb fc and viscous fv by default), with the baseline b the
median of p over the first ``baseline_days`` days of data:

    level  = median(p over the last ``recent`` days) / b - 1            [-]
    growth = Theil-Sen slope of p / b over the last ``window_days`` days  [1/day]

A joint is flagged when, for any parameter, level > ``max_level`` or growth > ``max_growth``.
Friction rises as a gear wears, so only increases are flagged. Medians and the Theil-Sen slope
(median of pairwise slopes) keep one bad day from raising a flag.
"""

from __future__ import annotations

import dataclasses
import datetime as dt

import numpy as np

MIN_BASELINE_DAYS = 3   # days of data (one value a day) a baseline is the median of, at least

DEFAULT_PARAMS = ("fc", "fv")


@dataclasses.dataclass
class WearRule:
    """Thresholds of the wear flag (see the module docstring)."""

    params: tuple = DEFAULT_PARAMS
    baseline_days: int = 7
    window_days: int = 14
    recent: int = 3
    max_level: float = 0.15
    max_growth: float = 0.01


@dataclasses.dataclass
class JointTrend:
    robot: str
    joint: str
    dates: list            # ISO dates with data (one value per day: the latest run)
    series: dict           # name -> values per date (the parameters and "mae")
    baseline: dict         # parameter -> baseline value
    level: dict            # parameter -> level [-]
    growth: dict           # parameter -> growth [1/day]
    flagged: bool
    reasons: list
    note: str = ""

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def theil_sen(days: np.ndarray, y: np.ndarray) -> float:
    """Median of the pairwise slopes of y over days (n,) [y per day]; NaN below 2 distinct days."""
    i, j = np.triu_indices(len(days), k=1)
    dd = days[j] - days[i]
    keep = dd != 0
    return float(np.median((y[j] - y[i])[keep] / dd[keep])) if keep.any() else float("nan")


def _daily(rows: list[dict], names: tuple) -> tuple[list, dict]:
    """One value per date: the latest run's row of that date."""
    latest: dict = {}
    for r in rows:
        if r["date"] not in latest or r["run_time"] >= latest[r["date"]]["run_time"]:
            latest[r["date"]] = r
    dates = sorted(latest)
    return dates, {n: np.array([latest[d][n] for d in dates], dtype=float) for n in names}


def joint_trend(robot: str, joint: str, rows: list[dict], rule: WearRule) -> JointTrend:
    """The trend of one joint from its history rows (status ok)."""
    dates, series = _daily(rows, tuple(rule.params) + ("mae",))
    out = JointTrend(robot=robot, joint=joint, dates=[d.isoformat() for d in dates],
                     series={k: v.tolist() for k, v in series.items()}, baseline={}, level={}, growth={},
                     flagged=False, reasons=[])
    if not dates:
        out.note = "no successful job"
        return out
    day = np.array([(d - dates[0]).days for d in dates], dtype=float)
    base_rows = day < rule.baseline_days
    if day[-1] < rule.baseline_days or base_rows.sum() < MIN_BASELINE_DAYS:
        out.note = f"too little data: {len(dates)} days over {int(day[-1]) + 1}, needs {rule.baseline_days} " \
                   f"days of baseline ({MIN_BASELINE_DAYS} logs at least) and later data"
        return out
    recent_window = day > day[-1] - rule.window_days
    for p in rule.params:
        x = series[p]
        good = np.isfinite(x)
        b = float(np.median(x[base_rows & good])) if (base_rows & good).any() else float("nan")
        if not (np.isfinite(b) and b > 0):
            continue
        later = good & ~base_rows
        if not later.any():
            continue
        level = float(np.median(x[later][-rule.recent:]) / b - 1.0)
        w = recent_window & good
        growth = theil_sen(day[w], x[w] / b) if w.sum() >= 5 else float("nan")
        out.baseline[p], out.level[p], out.growth[p] = b, level, growth
        if level > rule.max_level:
            out.reasons.append(f"{p} {100 * level:+.0f} % over its first {rule.baseline_days} days "
                               f"(limit {100 * rule.max_level:g} %)")
        if growth > rule.max_growth:
            span = int(day[w][-1] - day[w][0]) + 1        # the days the slope was measured over
            out.reasons.append(f"{p} growing {100 * growth:.3g} %/day over the last {span} days "
                               f"(limit {100 * rule.max_growth:g} %/day)")
    out.flagged = bool(out.reasons)
    return out


def trends(table, rule: WearRule | None = None) -> list[JointTrend]:
    """Trends of every joint in a history table (``fricli.fleet.history.read``), sorted by robot, joint."""
    rule = rule or WearRule()
    status = table.column("status").to_pylist()
    cols = {n: table.column(n).to_pylist() for n in ("robot", "joint", "date", "run_time", "mae", *rule.params)}
    groups: dict = {}
    for i, s in enumerate(status):
        key = (cols["robot"][i], cols["joint"][i])
        groups.setdefault(key, [])
        if s == "ok":
            groups[key].append({n: (np.nan if v[i] is None else v[i]) if n not in ("date", "run_time", "robot",
                                                                                  "joint") else v[i]
                                for n, v in cols.items()})
    return [joint_trend(robot, joint, rows, rule) for (robot, joint), rows in sorted(groups.items())]


PARAM_NAMES = {"fc": "Coulomb friction Fc", "fs": "static friction Fs", "fv": "viscous friction Fv",
               "mae": "fit MAE"}


def figure(t: JointTrend, rule: WearRule, path: str) -> None:
    """A PNG of one joint's parameters, each divided by its baseline, over the days, with the
    level limit (matplotlib's object API: no pyplot state)."""
    from matplotlib.figure import Figure

    from fricli.core import atomic

    dates = [dt.date.fromisoformat(d) for d in t.dates]
    fig = Figure(figsize=(7, 3.8), layout="constrained")
    ax = fig.add_subplot()
    for p, b in t.baseline.items():
        ax.plot(dates, np.asarray(t.series[p], dtype=float) / b, marker=".",
                label=f"{PARAM_NAMES.get(p, p)} (baseline {b:.4g})")
    ax.axhline(1 + rule.max_level, color="0.4", ls="--", lw=1, label=f"level limit +{100 * rule.max_level:g} %")
    ax.axhline(1.0, color="0.7", lw=1)
    ax.set_xlabel("date of the run [day]")
    ax.set_ylabel(f"value / median of the first {rule.baseline_days} days [-]")
    ax.set_title(f"{t.robot} joint {t.joint}: {'; '.join(t.reasons) or 'not flagged'}\n"
                 "1.0 = as new; above the dashed line the joint is flagged for wear", fontsize=8)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.autofmt_xdate()
    atomic.atomic_write_with(path, lambda fh: fig.savefig(fh, format="png", dpi=90, metadata={"Software": None}))


def figures(result: list[JointTrend], rule: WearRule, folder: str) -> list[str]:
    """``figure`` of every flagged joint into ``folder`` (created when missing) as
    ``<robot>-joint<joint>.png``; returns the paths written."""
    import os

    from fricli.core.errors import OutputError

    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write figures: cannot create the folder {folder} ({exc.strerror})") from None
    paths = [os.path.join(folder, f"{t.robot}-joint{t.joint}.png") for t in result if t.flagged]
    for t, path in zip([t for t in result if t.flagged], paths):
        figure(t, rule, path)
    return paths


_write_figures = figures   # fleet_trend's keyword ``figures`` is the folder


@dataclasses.dataclass
class Trend:
    """``fleet_trend``'s result: the ``rule``, every joint's ``JointTrend`` (``joints``, sorted by
    robot and joint) and the figure files written."""

    rule: WearRule
    joints: list
    figures: list = dataclasses.field(default_factory=list)

    @property
    def flagged(self) -> list:
        """The flagged joints as "robot/joint"."""
        return [f"{t.robot}/{t.joint}" for t in self.joints if t.flagged]

    @property
    def exit_code(self) -> int:
        """The command's: WEAR when a joint is flagged, else OK."""
        from fricli.core import errors

        return errors.WEAR if self.flagged else errors.OK

    def as_json(self) -> dict:
        """What ``fricli trend --json`` prints."""
        return {"rule": {k: list(v) if isinstance(v, tuple) else v for k, v in vars(self.rule).items()},
                "flagged": self.flagged, "joints": [t.as_dict() for t in self.joints]}

    def table(self) -> str:
        """The table ``fricli trend`` prints: per joint the level and growth of each parameter, the flag."""
        from fricli.core.errors import one_line as name

        result, rule = self.joints, self.rule
        rw = max([12] + [len(name(str(t.robot))) for t in result])
        jw = max([6] + [len(name(str(t.joint))) for t in result])
        head = f"{'robot':<{rw}} {'joint':<{jw}} {'days':>4}  " + "  ".join(f"{p + ' level':>9} {p + ' /day':>8}"
                                                                       for p in rule.params) + "  flag"
        lines = [head]
        for t in result:
            cells = []
            for p in rule.params:
                lv, gr = t.level.get(p), t.growth.get(p)
                cells.append(f"{'-' if lv is None else f'{100 * lv:+.1f}%':>9} "
                             f"{'-' if gr is None or gr != gr else f'{100 * gr:+.2f}%':>8}")
            flag = "WEAR: " + "; ".join(t.reasons) if t.flagged else t.note
            lines.append(f"{name(str(t.robot)):<{rw}} {name(str(t.joint)):<{jw}} {len(t.dates):>4}  "
                         + "  ".join(cells) + f"  {name(flag)}".rstrip())
        return "\n".join(lines)


def _spec() -> dict:
    from fricli.fitting.optionspec import Option

    return {o.name: o for o in (Option("baseline_days", "int", 7, low=MIN_BASELINE_DAYS), Option("window_days", "int", 14, low=2),
                                Option("max_level", "float", 0.15, low=0.0, low_open=True),
                                Option("max_growth", "float", 0.01, low=0.0, low_open=True))}


def fleet_trend(history: str, *, params=DEFAULT_PARAMS, baseline_days: int = 7, window_days: int = 14,
                max_level: float = 0.15, max_growth: float = 0.01, figures: str | None = None) -> Trend:
    """``fricli trend HISTORY``: every joint's friction over the days of the fleet history folder
    ``history`` and its wear flag (see the module docstring): ``params`` the parameters watched
    (fc, fs, fv, ...), ``baseline_days`` [days] (>= 1), ``window_days`` [days] (>= 2), ``max_level``
    [-] and ``max_growth`` [1/day] (> 0); with ``figures`` a PNG per flagged joint written into that
    folder. Returns a ``Trend`` (``as_json()`` what --json prints, ``table()`` what the command
    prints, ``exit_code``). OptionError naming a wrong option."""
    from fricli.fitting.optionspec import OptionError, check_values
    from fricli.fleet import history as hist

    params = (params,) if isinstance(params, str) else tuple(params)
    bad = [p for p in params if p not in hist.PARAMETERS]
    if bad:
        raise OptionError(f"unknown parameter {bad[0]!r} (choose from {', '.join(hist.PARAMETERS)})", "params")
    checked = check_values({"baseline_days": baseline_days, "window_days": window_days, "max_level": max_level,
                            "max_growth": max_growth}, _spec(), "trend")
    rule = WearRule(params=params, **checked)
    result = Trend(rule, trends(hist.read(history, partitioned=True), rule))
    if figures:
        result.figures = _write_figures(result.joints, rule, figures)
    return result
