"""The whole method on the bundled sample data, end to end (the paper's Table 2 for one joint)."""

from __future__ import annotations

import json
import os
from typing import Callable

from fricli import models
from fricli.applying import evaluation, report
from fricli.core import logs
from fricli.fitting import learning, plan
from fricli.core.atomic import atomic_write_bytes
from fricli.applying.predicting import external_estimate
from fricli.sim.samples import sample_path

ROWS = (("LuGre", "lugre"), ("NN_base", "nn_base"), ("Selmic", "selmic"), ("NNACM", "nnacm"),
        ("NN_base + NN_add", "adapted"), ("LuGre + NN_add", "lugre_adapted"))
SUBSETS = (("moving", "rows in motion (|qd| > 2 % of the top speed)"), ("all", "all rows, standstill included"))
LOADS = (("asymmetric load", "extended_asym"), ("symmetric load", "extended_sym"), ("no load", "extended_none"))
LOWPASS_HZ = 5.0


def run(out: str, *, data: str | None = None, joint: int = 2, steps: int | None = None, seed: int = 0,
        say: Callable[[str], None] = lambda s: None) -> dict:
    """Identify, train, adapt, evaluate and report into folder ``out``; returns the results.
    Each model is the file the command of the same name writes (``fricli.fitting.plan``).

    data: folder with the sample logs (missing ones are simulated into ``out/data``); steps:
    Adam steps of the base networks (None: train-base's default).
    """
    os.makedirs(out, exist_ok=True)
    folder = data if data and os.path.isdir(data) else os.path.join(out, "data")

    def log_path(name: str) -> str:
        return sample_path(folder, f"joint{joint}_{name}")

    def load(name: str) -> logs.Log:
        return logs.load_log(log_path(name))

    def make(pipeline: str, log: str, key: str, base: str | None = None, **options) -> None:
        """The model ``fricli PIPELINE LOG -o KEY.npz`` writes with these options."""
        plan.fit_log(pipeline, log, paths[key], options, inputs=base)

    base_log, adapt_log = load("base"), load("adapt")
    paths = {key: os.path.join(out, f"{key}.npz") for _, key in ROWS}

    say(f"identify: extended LuGre on {os.path.basename(base_log.name)}")
    make("identify", log_path("base"), "lugre")
    for arch, key in ((learning.DEFAULT_ARCH, "nn_base"), ("selmic", "selmic"), ("nnacm", "nnacm")):
        say(f"train-base: {arch}, {steps or learning.default_steps(arch):,} full-batch Adam steps")
        make("train-base", log_path("base"), key, arch=arch, steps=steps, seed=seed)
    say(f"adapt: NN_add on the residual of NN_base over {os.path.basename(adapt_log.name)} "
        f"({adapt_log.signals['t'][-1] - adapt_log.signals['t'][0]:.1f} s, no external load)")
    for base_key, key in (("nn_base", "adapted"), ("lugre", "lugre_adapted")):
        make("adapt", log_path("adapt"), key, base=paths[base_key], seed=seed)

    say("evaluate: friction and external torque on the extended logs")
    loaded = {key: models.load(path) for key, path in paths.items()}
    results: dict = {}
    eval_logs = {}
    for _, lkey in LOADS:
        eval_logs[lkey] = load(lkey)
        for _, mkey in ROWS:
            model, meta = loaded[mkey]
            r = evaluation.evaluate_one(model, meta, eval_logs[lkey], lowpass_hz=LOWPASS_HZ)
            results.setdefault(mkey, {})[lkey] = {
                "all": {"friction_mae": r.friction["mae"], "external_mae": r.external["mae"] if r.external else None},
                "moving": {"friction_mae": r.friction_moving["mae"],
                           "external_mae": r.external_moving["mae"] if r.external_moving else None}}

    asym = eval_logs["extended_asym"]
    model, _ = loaded["adapted"]
    pred = model.predict(asym.signals)[0]
    table = logs.with_column(asym.table, "tau_f_pred", pred, asym.units["tau"])
    table = logs.with_column(table, "tau_ext_pred", external_estimate(asym.signals, pred, LOWPASS_HZ),
                             asym.units["tau"])
    logs.write_table(table, os.path.join(out, "extended_asym_estimate.parquet"))

    improvement = {sub: {lkey: {kind: 100.0 * (1.0 - results["adapted"][lkey][sub][kind]
                                               / results["lugre"][lkey][sub][kind])
                                for kind in ("friction_mae", "external_mae") if results["lugre"][lkey][sub][kind]}
                         for _, lkey in LOADS} for sub, _ in SUBSETS}
    summary = {"joint": joint, "steps": {"nn_base": steps or learning.default_steps(learning.DEFAULT_ARCH),
                                     "baselines": steps or learning.default_steps("selmic")}, "seed": seed, "lowpass_hz": LOWPASS_HZ,
               "adapt_seconds": float(adapt_log.signals["t"][-1] - adapt_log.signals["t"][0]),
               "results": results, "improvement_over_lugre_percent": improvement}
    atomic_write_bytes(os.path.join(out, "results.json"),
                       (json.dumps(summary, indent=2, sort_keys=True) + "\n").encode())
    text = format_table(summary)
    atomic_write_bytes(os.path.join(out, "table.md"), (text + "\n").encode())
    say("report: figures of NN_base + NN_add on the asymmetric-load log")
    folder = os.path.join(out, "report")
    report.make_folder(folder)
    fits = {label: loaded[key][0] for label, key in ROWS if key in ("lugre", "nn_base", "selmic", "nnacm")}
    sections = [report.Section("Comparison (the paper's Table 2)", html_tables(summary),
                               [_bars(summary, folder)]),
                report.Section("The fits", "", [report.fig_fits(fits, base_log, folder, seed=seed)])]
    report.write_report(paths["adapted"], asym, folder, lowpass_hz=LOWPASS_HZ, seed=seed, sections=sections)
    return summary


def html_tables(summary: dict) -> str:
    """``format_table``'s tables as HTML, with their units, for the report page."""
    import html

    res, parts = summary["results"], []
    head = ["method"] + [f"{label}: {what} MAE [Nm]" for label, _ in LOADS for what in ("friction", "ext. torque")]
    for sub, title in SUBSETS:
        rows = [[html.escape(label)] + [cell for _, lkey in LOADS for cell in (
            f"{res[key][lkey][sub]['friction_mae']:.2f}",
            "–" if res[key][lkey][sub]["external_mae"] is None else f"{res[key][lkey][sub]['external_mae']:.2f}")]
            for label, key in ROWS]
        parts.append(report.html_table(head, rows, html.escape(
            f"Joint {summary['joint']}, {title}: mean absolute error on the extended logs (external torque "
            f"low-passed at {summary['lowpass_hz']:g} Hz); lower is better.")))
    steps = summary["steps"]
    parts.append(f"<p>NN_base trained for {steps['nn_base']:,} steps, the baselines for {steps['baselines']:,} steps "
                 f"(seed {summary['seed']}); NN_add adapted on {summary['adapt_seconds']:.1f} s of load-free data.</p>")
    return "\n".join(parts)


def _bars(summary: dict, folder: str):
    res = summary["results"]
    values = {label: [res[key][lkey]["moving"]["friction_mae"] for _, lkey in LOADS] for label, key in ROWS}
    return report.fig_bars(values, [label for label, _ in LOADS], "Nm", folder, "comparison.png",
                           "friction MAE, rows in motion",
                           "The table's friction errors [Nm] over the rows in motion as bars: one group per "
                           "evaluation log (its load case), one bar per method; lower is better. NN_base + NN_add "
                           "and LuGre + NN_add are the adapted models.")


def format_table(summary: dict) -> str:
    """The comparison in the layout of the paper's Table 2 (MAE in Nm), over the rows in motion
    and over all rows."""
    res = summary["results"]
    head = ["method"]
    for label, _ in LOADS:
        head += [f"{label}: friction", f"{label}: ext. torque"]
    lines = [f"Joint {summary['joint']}: mean absolute error [Nm] on the extended logs "
             f"(external torque low-passed at {summary['lowpass_hz']:g} Hz)"]
    for sub, title in SUBSETS:
        lines += ["", f"{title}:", "", "| " + " | ".join(head) + " |", "|---" * len(head) + "|"]
        for label, key in ROWS:
            cells = [label]
            for _, lkey in LOADS:
                r = res[key][lkey][sub]
                cells += [f"{r['friction_mae']:.2f}", "–" if r["external_mae"] is None else f"{r['external_mae']:.2f}"]
            lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    for sub, _ in SUBSETS:
        for label, lkey in LOADS:
            imp = summary["improvement_over_lugre_percent"][sub][lkey]
            parts = [f"friction {imp['friction_mae']:.0f} %"]
            if "external_mae" in imp:
                parts.append(f"external torque {imp['external_mae']:.0f} %")
            lines.append(f"NN_base + NN_add vs LuGre, {label}, {sub} rows: " + ", ".join(parts) + " lower error")
    steps = summary["steps"]
    lines.append(f"(NN_base trained for {steps['nn_base']:,} steps, the baselines for {steps['baselines']:,}, "
                 f"seed {summary['seed']}; "
                 f"NN_add adapted on {summary['adapt_seconds']:.1f} s of load-free data)")
    return "\n".join(lines)


class DemoRun(dict):
    """``run_demo``'s result: the figures of ``run`` (a dict) and ``table()``, the comparison the
    command prints."""

    def table(self) -> str:
        return format_table(self)


def run_demo(output: str = "demo-out", *, data: str = "sample_data", joint: int = 2, steps: int | None = None,
             seed: int = 0, say: Callable[[str], None] | None = None) -> DemoRun:
    """``fricli demo -o OUTPUT``: ``run`` into the folder ``output`` on the sample logs of ``joint``
    (2 or 4) in the folder ``data`` (missing ones simulated), ``steps`` Adam steps per base network
    (>= 1; None: train-base's default), ``seed`` of every network's training; ``say(line)`` gets the
    progress lines. OptionError naming a wrong option."""
    from fricli.fitting.optionspec import Option, OptionError, check_values

    if str(joint) not in ("2", "4") or isinstance(joint, bool):
        raise OptionError(f"demo option joint: expected 2 or 4, got {joint!r}", "joint")
    check_values({"steps": steps, "seed": seed},
                 {"steps": Option("steps", "int", low=1), "seed": Option("seed", "int", default=0, low=0)}, "demo")
    return DemoRun(run(os.fspath(output), data=os.fspath(data), joint=int(joint), steps=steps, seed=seed,
                       say=say or (lambda s: None)))
