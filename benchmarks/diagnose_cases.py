"""The tables of docs/diagnose.md ("Measured") and the effect sizes of docs/simulator.md.

    PYTHONPATH=. python benchmarks/diagnose_cases.py            # both tables, Markdown on stdout

Diagnosis table: the LuGre model identified on a clean ``base`` log of joint 2 (seed 1) is
diagnosed on 60 s ``extended`` logs in the base friction state with the simulator effects at
their default strengths (seed 2), fixed, and checked on seed 3 with the same effects (the
cases of tests/test_diagnose.py). Sizes: MAE of the change of the friction target (same seed,
with against without the effect) over the MAE of the noise, joint 2 and 4, base and extended.
"""

from __future__ import annotations

import sys

import numpy as np

from fricli import sim
from fricli.core import logs, metrics
from fricli.fitting.diagnosis import diagnose
from fricli.fitting.diagnosis.fix import augment
from fricli.fitting.identify import identify

CASES = [("ripple",), ("temperature",), ("drift",), ("asymmetry",), ("inertia",), ("load",), ("velocity",),
         ("level",), ("offset",), ("column",), ("gravity",), ("quadrant",), ("temperature", "ripple"),
         ("hysteresis",), ("disturbance",), ()]


def _log(seed, effects, **kw):
    table = sim.simulate("extended", joint=2, seed=seed, effects=effects, duration=60.0, friction_state="base", **kw)
    return logs.from_table(table, name=f"seed {seed}")


def _mae(model, log):
    return metrics.errors(logs.friction_target(log.signals), model.predict(log.signals)[0])["mae"]


def diagnosis_table() -> str:
    base = identify(logs.from_table(sim.simulate("base", joint=2, seed=1), name="base")).model_
    rows = ["| simulator effects | added (in order) | their gain | cut, 95 % interval | unexplained share (where) "
            "| MAE on seed 3 before → after [Nm] | cut |", "|---|---|---|---|---|---|---|"]
    for effects in CASES:
        log2, log3 = _log(2, effects), _log(3, effects)
        d = diagnose(base, log2)
        fixed = augment(base, d, log2)
        before, after = _mae(base, log3), _mae(fixed, log3)
        u = d.unexplained
        view = u.views()[u.main]
        where = (f"{view.where['frequency_hz']:.2f} Hz" if u.main == "time" and view.where["frequency_hz"]
                 else f"{u.main} {view.where.get('range')}" if view.where.get("range") else u.main)
        if u.share < 0.1:
            where = "noise"
        added = ", ".join(f"{e.name}{' (model)' if e.part == 'model' else ''}" for e in d.effects if e.added)
        gains = " + ".join(f"{100 * e.gain:.1f} %" for e in d.effects if e.added) or "–"
        lo, hi = d.intervals["cut"]
        cut_ci = f"{100 * d.cut:.0f} % ({100 * lo:.0f} to {100 * hi:.0f} %)" if d.added else "–"
        rows.append(f"| {' + '.join(effects) or '(none)'} | {added or 'nothing'} | {gains} | {cut_ci} | "
                    f"{u.share:.2f} ({where}) | {before:.3f} → {after:.3f} | {100 * (1 - after / before):.0f} % |")
    return "\n".join(rows)


def size_table(names) -> str:
    rows = ["| effect | j2 base | j2 extended | j4 base | j4 extended |", "|---|---|---|---|---|"]
    for name in names:
        cells = []
        for joint in (2, 4):
            for scenario in ("base", "extended"):
                kw = {"seed": 3}
                clean = logs.from_table(sim.simulate(scenario, joint=joint, **kw), name="c").signals
                with_ = logs.from_table(sim.simulate(scenario, joint=joint, effects=[name], **kw), name="e").signals
                noise = np.abs(logs.friction_target(clean) - clean["tau_f_true"]).mean()
                change = np.abs(logs.friction_target(with_) - logs.friction_target(clean)).mean()
                cells.append(f"{change / noise:.1f}")
        rows.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(rows)


if __name__ == "__main__":
    which = sys.argv[1:] or ["diagnose", "sizes"]
    if "diagnose" in which:
        print(diagnosis_table())
    if "sizes" in which:
        print()
        print(size_table(["gravity", "quadrant", "load", "disturbance"]))
