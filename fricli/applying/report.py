"""Figures like the paper's, and an index.html that shows them with captions, for one model on
one log (matplotlib's object API on the Agg canvas: no pyplot state). The page is self-contained
(PNG files beside it, no external assets) and every number on it carries its unit."""

from __future__ import annotations

import contextlib
import dataclasses
import html
import io
import os
import shutil
import tempfile
from typing import Iterator

import numpy as np
from matplotlib.figure import Figure

from fricli import models
from fricli.core import logs, metrics
from fricli.core.atomic import atomic_write_bytes
from fricli.core.errors import OutputError
from fricli.core.envelope import share_outside
from fricli.models import coupled
from fricli.applying.evaluation import static_friction
from fricli.applying.predicting import external_estimate

MEASURED = "#9aa7b5"
MODEL = "#c0392b"
OTHER = "#1f5f99"


@dataclasses.dataclass
class Shown:
    """A figure written into the report folder (``file``) and the caption that explains it."""

    file: str
    caption: str


def save(fig: Figure, folder: str, name: str, caption: str) -> Shown:
    """Write ``fig`` as the PNG ``folder/name`` (atomically, the same bytes for the same figure)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    atomic_write_bytes(os.path.join(folder, name), buf.getvalue())
    return Shown(name, caption)


def _title(fig: Figure, label: str) -> None:
    """Name what the figure shows (the joint and the log) in the figure itself, so that a PNG copied
    out of the report still says what it is."""
    if label:
        fig.suptitle(label, fontsize=9, y=1.0)


def figure_label(log: logs.Log, model_path: str | None = None) -> str:
    """``joint J of LOG`` (with ``model MODEL`` when given), escaped to one line."""
    from fricli.core.errors import one_line

    who = f"joint {log.joint} of " if log.joint is not None else ""
    what = f"{who}{os.path.basename(log.name)}" + (f", model {os.path.basename(model_path)}" if model_path else "")
    return one_line(what)


def _networks(model, path: str = "") -> list[tuple[str, object]]:
    """(path in the model tree, node) of every node with loss histories."""
    own = [(path or model.kind, model)] if getattr(model, "history_train_", np.empty(0)).size else []
    return own + [item for name, child in model.children().items()
                  for item in _networks(child, f"{path}/{name}" if path else name)]


def fig_loss(model, folder: str, label: str = "") -> Shown | None:
    nets = _networks(model)
    if not nets:
        return None
    fig = Figure(figsize=(5.5 * len(nets), 3.6))
    axes = fig.subplots(1, len(nets), squeeze=False)[0]
    for ax, (where, net) in zip(axes, nets):
        every = max(int(getattr(net, "eval_every_", 0) or 1), 1)
        for curve, values, color in (("training", net.history_train_, OTHER),
                                     ("validation", getattr(net, "history_val_", np.empty(0)), MODEL)):
            if values.size:
                ax.semilogy(every * np.arange(1, values.size + 1), values, label=curve, color=color)
        ax.set_title(f"training loss of {where}", fontsize=10)
        ax.set_xlabel("training step [Adam steps]")
        ax.set_ylabel("MSE of the standardised friction [-]")
        ax.grid(alpha=0.3)
        ax.legend()
    _title(fig, label)
    return save(fig, folder, "loss.png",
                "Training of the model's networks: the mean squared error of the friction in standardised units "
                "(divided by its standard deviation on the training rows, so that a loss of one is no better than predicting the mean), "
                "on a log scale, against the Adam step. The training curve averages the steps since the previous "
                "point; the validation curve is the loss on held-out rows at that step. The two curves falling "
                "together means the network learned; a validation curve that rises again means it over-fitted "
                "(the saved weights are those of the lowest validation loss).")


def fig_velocity(model, sig, u, folder: str, rng, label: str = "") -> Shown:
    target = logs.friction_target(sig)
    qd = sig["qd"]
    idx = rng.choice(qd.size, size=min(qd.size, 6000), replace=False)
    vmax = float(np.max(np.abs(qd))) or 1.0
    v = np.linspace(-vmax, vmax, 401)
    g = logs.column(sig, "tau_g")
    gs = np.linspace(np.min(g), np.max(g), 9) if np.ptp(g) > 0 else np.array([float(g[0])])
    curve = np.mean([static_friction(model, v, np.full_like(v, gi), sig) for gi in gs], axis=0)
    fig = Figure(figsize=(6.5, 4.2))
    ax = fig.subplots()
    ax.scatter(qd[idx], target[idx], s=3, color=MEASURED, label="measured", rasterized=True)
    ax.plot(v, curve, color=MODEL, lw=2, label="model (mean over gravity torque)")
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"friction [{u['tau']}]")
    ax.grid(alpha=0.3)
    ax.legend()
    _title(fig, label)
    return save(fig, folder, "friction_velocity.png",
                f"Friction against velocity. Grey dots: the measured friction tau_m + tau_ext - tau_g - tau_dyn "
                f"[{u['tau']}] of up to 6,000 rows of the log; red line: the model's steady-state friction at "
                f"constant velocity, averaged over nine gravity torques spanning the log. Where the dots scatter "
                f"around the line the model fits; a vertical spread at one velocity is friction the velocity alone "
                f"does not explain (load, temperature, the motion before).")


def fig_heatmap(model, sig, u, folder: str, envelope=None, label: str = "") -> Shown:
    """Friction over (qd, tau_g); the region outside the model's training envelope is greyed and hatched."""
    qd, g = sig["qd"], logs.column(sig, "tau_g")
    vmax = float(np.max(np.abs(qd))) or 1.0
    gmax = float(np.max(np.abs(g))) or 1.0
    v = np.linspace(-vmax, vmax, 121)
    gg = np.linspace(-gmax, gmax, 81)
    V, G = np.meshgrid(v, gg)
    F = static_friction(model, V.ravel(), G.ravel(), sig).reshape(V.shape)
    fig = Figure(figsize=(6.5, 4.6))
    ax = fig.subplots()
    mesh = ax.pcolormesh(V, G, F, shading="auto", cmap="coolwarm")
    fig.colorbar(mesh, ax=ax, label=f"friction [{u['tau']}]")
    title = "model over velocity and gravity torque"
    outside = ""
    if envelope is not None:
        out = ~envelope.covered_grid("qd", v, "tau_g", gg)
        if out.any():
            ax.pcolormesh(V, G, np.ma.masked_where(~out, np.ones(out.shape)), shading="auto", cmap="Greys",
                          vmin=0, vmax=2.5, alpha=0.6)
            ax.contourf(V, G, out.astype(float), levels=[0.5, 1.5], colors="none", hatches=["//"])
        title += f"\n(hatched: outside the training envelope, {100 * out.mean():.0f} % of the map)"
        outside = (f" The hatched grey region ({100 * out.mean():.0f} % of the map) lies outside the rows the model "
                   "was trained on: there it extrapolates.")
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"gravity torque tau_g [{u['tau']}]")
    ax.set_title(title, fontsize=10)
    _title(fig, label)
    return save(fig, folder, "heatmap.png",
                f"The model's steady-state friction [{u['tau']}] (colour: red along positive velocity, blue along "
                f"negative) over velocity [{u['qd']}] and gravity torque [{u['tau']}]. Colour that changes along the "
                f"vertical axis shows friction that grows with the load on the gear." + outside)


def fig_time(sig, pred, u, folder: str, label: str = "") -> Shown:
    t = sig["t"]
    fig = Figure(figsize=(9, 5.5))
    a1, a2 = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    a1.plot(t, logs.friction_target(sig), color=MEASURED, lw=0.8, label="measured")
    a1.plot(t, pred, color=MODEL, lw=1.2, label="predicted")
    a1.set_ylabel(f"friction [{u['tau']}]")
    a1.legend(loc="upper right")
    a1.grid(alpha=0.3)
    a2.plot(t, sig["qd"], color=OTHER, lw=1)
    a2.set_ylabel(f"qd [{u['qd']}]")
    a2.set_xlabel("time [s]")
    a2.grid(alpha=0.3)
    _title(fig, label)
    return save(fig, folder, "friction_time.png",
                f"Top: measured friction (grey) and the model's prediction (red) [{u['tau']}] over the log's time "
                f"[s]; bottom: the velocity [{u['qd']}]. The gap between the curves is the prediction error; look "
                f"at the velocity reversals, where friction changes sign and dynamic effects show.")


def fig_quadrants(sig, u, folder: str, label: str = "") -> Shown:
    qd, g = sig["qd"], logs.column(sig, "tau_g")
    same = np.sign(qd) == np.sign(g)
    fig = Figure(figsize=(5.5, 4.6))
    ax = fig.subplots()
    ax.axhline(0, color="k", lw=0.6)
    ax.axvline(0, color="k", lw=0.6)
    ax.scatter(qd[same], g[same], s=2, color=OTHER, label="quadrants I, III (same sign)", rasterized=True)
    ax.scatter(qd[~same], g[~same], s=2, color=MODEL, label="quadrants II, IV (opposite sign)", rasterized=True)
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"gravity torque tau_g [{u['tau']}]")
    share = 100.0 * same.mean()
    ax.set_title(f"four quadrants: {share:.0f} % of samples in I/III")
    ax.legend(loc="upper left", fontsize=8, markerscale=4)
    ax.grid(alpha=0.3)
    _title(fig, label)
    return save(fig, folder, "quadrants.png",
                f"Where the log's samples lie in velocity [{u['qd']}] and gravity torque [{u['tau']}]: blue where "
                f"the two have the same sign (quadrants I and III, the motor lifts the load), red where they differ "
                f"(II and IV, the load drives the motion); {share:.0f} % of the samples are blue. A gear's "
                f"friction differs between the two, so a log covering only some quadrants cannot show it.")


def fig_external(sig, pred, u, folder: str, lowpass_hz, label: str = "") -> Shown | None:
    if "tau_ext" not in sig:
        return None
    est = external_estimate(sig, pred, lowpass_hz)
    fig = Figure(figsize=(9, 3.6))
    ax = fig.subplots()
    ax.plot(sig["t"], sig["tau_ext"], color=MEASURED, lw=1, label="sensor")
    ax.plot(sig["t"], est, color=MODEL, lw=1, label="estimated" + (f" (low-pass {lowpass_hz:g} Hz)" if lowpass_hz else ""))
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"external torque [{u['tau']}]")
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    low = f", low-passed at {lowpass_hz:g} Hz" if lowpass_hz else ""
    _title(fig, label)
    return save(fig, folder, "external_torque.png",
                f"The external torque [{u['tau']}] over time [s]: grey, the log's sensor; red, the estimate "
                f"tau_g + tau_dyn + predicted friction - tau_m{low}, which needs no sensor. Every error of the "
                f"friction model shows here as a false external torque.")


def fig_fits(named: dict, log: logs.Log, folder: str, name: str = "fits_velocity.png", seed: int = 0) -> Shown:
    """Several models' steady-state friction against velocity over the log they were fitted on."""
    sig, u = log.signals, log.units
    qd, target = sig["qd"], logs.friction_target(sig)
    idx = np.random.default_rng(seed).choice(qd.size, size=min(qd.size, 6000), replace=False)
    vmax = float(np.max(np.abs(qd))) or 1.0
    v = np.linspace(-vmax, vmax, 401)
    g = logs.column(sig, "tau_g")
    gs = np.linspace(np.min(g), np.max(g), 9) if np.ptp(g) > 0 else np.array([float(g[0])])
    fig = Figure(figsize=(7.5, 4.6))
    ax = fig.subplots()
    ax.scatter(qd[idx], target[idx], s=3, color=MEASURED, label="measured", rasterized=True)
    for label, model in named.items():
        curve = np.mean([static_friction(model, v, np.full_like(v, gi), sig) for gi in gs], axis=0)
        ax.plot(v, curve, lw=1.6, label=label)
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"friction [{u['tau']}]")
    ax.set_title(f"the fitted models on {os.path.basename(log.name)}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, folder, name,
                f"The fits: each model's steady-state friction [{u['tau']}] at constant velocity [{u['qd']}] "
                f"(averaged over nine gravity torques spanning the log), over the measured friction of up to "
                f"6,000 rows of {os.path.basename(log.name)}, the log they were fitted on (grey dots). A curve "
                f"through the middle of the dots fits the static friction; the models differ most near zero "
                f"velocity, where the friction changes sign.")


def fig_bars(values: dict, groups: list[str], unit: str, folder: str, name: str, ylabel: str, caption: str) -> Shown:
    """Grouped bars: ``values`` {label: [one value per group]} (NaN: no bar)."""
    fig = Figure(figsize=(8, 4))
    ax = fig.subplots()
    width = 0.8 / max(len(values), 1)
    x = np.arange(len(groups))
    for i, (label, vals) in enumerate(values.items()):
        ax.bar(x + (i - (len(values) - 1) / 2) * width, vals, width, label=label)
    ax.set_xticks(x, groups)
    ax.set_xlabel("evaluation log")
    ax.set_ylabel(f"{ylabel} [{unit}]")
    ax.set_ylim(0, 1.3 * np.nanmax([np.nanmax(v) for v in values.values()]))
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8, ncols=3, loc="upper center")
    return save(fig, folder, name, caption)


@dataclasses.dataclass
class Section:
    """A part of a report page before the model's own figures: a heading, an HTML block (tables,
    text) and figures already written into the report folder."""

    title: str
    body: str = ""
    figures: list = dataclasses.field(default_factory=list)


def write_report(model_path: str, log: logs.Log, folder: str, *, lowpass_hz: float | None = 5.0,
                 seed: int = 0, sections: list[Section] = ()) -> dict:
    """Write the figures and index.html into ``folder`` (``sections`` first); returns the figure
    files and the error figures [Nm]. A coupled group's model is applied as its member of
    ``log``'s joint (the partners' velocities in ``log.signals``: ``coupled.add_partners``)."""
    model, meta = models.load(model_path)
    model = coupled.view(model, log.joint)
    models.check_log(meta, log, model_path)
    make_folder(folder)
    sig, u = log.signals, log.units
    pred = model.predict(sig)[0]
    env = models.envelope(meta, model_path)
    rng = np.random.default_rng(seed)
    label = figure_label(log, model_path)
    shown = [f for f in (
        fig_loss(model, folder, label=label),
        fig_velocity(model, sig, u, folder, rng, label=label),
        fig_heatmap(model, sig, u, folder, env, label=label),
        fig_time(sig, pred, u, folder, label=label),
        fig_quadrants(sig, u, folder, label=label),
        fig_external(sig, pred, u, folder, lowpass_hz, label=label),
    ) if f]
    summary = {"model": os.path.basename(model_path), "kind": meta.get("kind"), "log": os.path.basename(log.name),
               "unit": u["tau"], "friction": metrics.errors(logs.friction_target(sig), pred)}
    if env is not None:
        summary["extrapolation"] = share_outside(env, sig)
    if "tau_ext" in sig:
        summary["external"] = metrics.errors(sig["tau_ext"], external_estimate(sig, pred, lowpass_hz))
    atomic_write_bytes(os.path.join(folder, "index.html"), _html(summary, shown, u, list(sections)).encode())
    return {"figures": [f.file for f in shown], **summary}


def make_folder(folder: str) -> None:
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {folder}: {exc.strerror}") from None


@contextlib.contextmanager
def staged(folder: str) -> Iterator[str]:
    """A fresh hidden folder inside ``folder`` to write a report into; when the block succeeds its
    files are moved into ``folder`` (each index.html after its figures), so an interrupted or
    failed report leaves the previous one whole, never a mix of two."""
    make_folder(folder)
    try:
        stage = tempfile.mkdtemp(prefix=".report.", suffix=".tmp", dir=folder)
    except OSError as exc:
        raise OutputError(f"cannot write {folder}: {exc.strerror}") from None
    try:
        yield stage
        files = [os.path.relpath(os.path.join(d, f), stage) for d, _, names in os.walk(stage) for f in names]
        for rel in sorted(files, key=lambda r: (os.path.basename(r) == "index.html", -r.count(os.sep), r)):
            os.makedirs(os.path.join(folder, os.path.dirname(rel)), exist_ok=True)
            os.replace(os.path.join(stage, rel), os.path.join(folder, rel))
    except OSError as exc:
        raise OutputError(f"cannot write {folder}: {exc.strerror}") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def write_reports(runs: list[tuple[str, logs.Log]], folder: str, *, lowpass_hz: float | None = 5.0,
                  seed: int = 0) -> dict:
    """One report per (model file, joint's log) in ``folder/joint_<name>/`` and an index.html
    linking them with each joint's errors; a single run is written into ``folder`` itself."""
    with staged(folder) as stage:
        return _write_reports(runs, stage, lowpass_hz=lowpass_hz, seed=seed)


def _write_reports(runs: list[tuple[str, logs.Log]], folder: str, *, lowpass_hz: float | None, seed: int) -> dict:
    from fricli.core.modelset import file_name

    if len(runs) == 1:
        return {str(runs[0][1].joint): write_report(runs[0][0], runs[0][1], folder, lowpass_hz=lowpass_hz, seed=seed)}
    out = {}
    for model_path, log in runs:
        sub = file_name(log.joint)[:-len(".npz")]
        out[str(log.joint)] = dict(write_report(model_path, log, os.path.join(folder, sub), lowpass_hz=lowpass_hz,
                                                seed=seed), folder=sub)
    u = runs[0][1].units
    rows = [[f'<a href="{html.escape(r["folder"])}/index.html">joint {html.escape(j)}</a>', html.escape(r["model"]),
             f"{r['friction']['mae']:.3f}", f"{r['friction']['rmse']:.3f}",
             f"{r['external']['mae']:.3f}" if "external" in r else "–"] for j, r in out.items()]
    table = html_table(["joint", "model", f"friction MAE [{u['tau']}]", f"friction RMS [{u['tau']}]",
                        f"external torque MAE [{u['tau']}]"], rows)
    name = html.escape(os.path.basename(runs[0][1].name))
    body = (f"<p>{name}: one report per joint ({len(out)} joints); the errors are over all the log's rows of each "
            f"joint (MAE: mean absolute error, RMS: root mean square).</p>\n{table}")
    atomic_write_bytes(os.path.join(folder, "index.html"), _page(f"fricli report: {name}", body).encode())
    return out


def html_table(head: list[str], rows: list[list[str]], caption: str = "") -> str:
    """An HTML table; ``head`` is escaped, the cells are HTML already."""
    cap = f"<caption>{caption}</caption>" if caption else ""
    return (f"<table>{cap}<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>\n"
            + "\n".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows) + "</table>")


def _figure(f: Shown) -> str:
    alt = f.caption.split(". ")[0].split(": ")[0]
    return (f'<figure><img src="{html.escape(f.file)}" alt="{html.escape(alt)}">'
            f"<figcaption>{html.escape(f.caption)}</figcaption></figure>")


STYLE = """body{font-family:sans-serif;max-width:1000px;margin:2em auto;line-height:1.4}img{max-width:100%}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:4px 10px;text-align:right}
caption{text-align:left;padding:4px 0}figure{margin:2em 0}figcaption{color:#333;font-size:0.95em}"""


def _page(title: str, body: str) -> str:
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>{STYLE}</style></head>
<body><h1>fricli report</h1>
{body}
</body></html>
"""


def _html(summary: dict, figures: list[Shown], u: dict, sections: list[Section]) -> str:
    tau = u["tau"]
    rows = [["friction"] + [f"{summary['friction'][k]:.3f}" for k in ("mae", "rmse", "max")]]
    if "external" in summary:
        rows.append(["external torque"] + [f"{summary['external'][k]:.3f}" for k in ("mae", "rmse", "max")])
    title = html.escape(f"{summary['model']} ({summary['kind']}) on {summary['log']}")
    errors = html_table(["", f"MAE [{tau}]", f"RMS [{tau}]", f"max [{tau}]"], rows,
                        f"Errors of the model over the log's {summary['friction']['n']:,} rows: friction against "
                        "the target tau_m + tau_ext - tau_g - tau_dyn, external torque against the sensor "
                        "(MAE: mean absolute error, RMS: root mean square, max: largest absolute error).")
    out = summary.get("extrapolation")
    extra = "" if out is None else (f"<p>{100 * out['share']:.1f} % of the rows ({out['rows']:,} of {out['of']:,} rows) "
                                    "lie outside the model's training envelope.</p>")
    parts = [f"<p>{title}</p>"]
    for sec in sections:
        parts += [f"<h2>{html.escape(sec.title)}</h2>", sec.body, *map(_figure, sec.figures)]
    if sections:
        parts.append(f"<h2>{title}</h2>")
    parts += [errors, extra, *map(_figure, figures)]
    return _page(f"fricli report: {title}", "\n".join(p for p in parts if p))
