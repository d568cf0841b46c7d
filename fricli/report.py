"""Figures like the paper's, and an index.html, for one model on one log (matplotlib, Agg)."""

from __future__ import annotations

import html
import io
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fricli import logs, metrics, models  # noqa: E402
from fricli.atomic import atomic_write_bytes  # noqa: E402
from fricli.errors import OutputError  # noqa: E402
from fricli.envelope import share_outside  # noqa: E402
from fricli.evaluation import static_friction  # noqa: E402
from fricli.predicting import external_estimate  # noqa: E402

MEASURED = "#9aa7b5"
MODEL = "#c0392b"
OTHER = "#1f5f99"


def _save(fig, folder: str, name: str) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    atomic_write_bytes(os.path.join(folder, name), buf.getvalue())
    return name


def _histories(model) -> dict[str, np.ndarray]:
    """Loss histories anywhere in the model tree, keyed by their array path."""
    _, arrays = models.to_parts(model)
    return {k: v for k, v in arrays.items() if k.rsplit("/", 1)[-1].startswith("history_") and v.size}


def fig_loss(model, folder: str) -> str | None:
    hist = _histories(model)
    if not hist:
        return None
    groups = sorted({k.rsplit("/", 1)[0] if "/" in k else "" for k in hist})
    fig, axes = plt.subplots(1, len(groups), figsize=(5.5 * len(groups), 3.6), squeeze=False)
    for ax, prefix in zip(axes[0], groups):
        for key, values in sorted(hist.items()):
            if (key.rsplit("/", 1)[0] if "/" in key else "") != prefix:
                continue
            label = key.rsplit("/", 1)[-1].replace("history_", "")
            ax.semilogy(np.arange(1, values.size + 1), values, label=label,
                        color=OTHER if "train" in label else MODEL)
        ax.set_title(f"loss ({prefix or 'model'})")
        ax.set_xlabel("recorded step")
        ax.set_ylabel("MSE loss (standardised)")
        ax.grid(alpha=0.3)
        ax.legend()
    return _save(fig, folder, "loss.png")


def fig_velocity(model, sig, u, folder: str, rng) -> str:
    target = logs.friction_target(sig)
    qd = sig["qd"]
    idx = rng.choice(qd.size, size=min(qd.size, 6000), replace=False)
    vmax = float(np.max(np.abs(qd))) or 1.0
    v = np.linspace(-vmax, vmax, 401)
    g = logs.column(sig, "tau_g")
    gs = np.linspace(np.min(g), np.max(g), 9) if np.ptp(g) > 0 else np.array([float(g[0])])
    curve = np.mean([static_friction(model, v, np.full_like(v, gi), sig) for gi in gs], axis=0)
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ax.scatter(qd[idx], target[idx], s=3, color=MEASURED, label="measured", rasterized=True)
    ax.plot(v, curve, color=MODEL, lw=2, label="model (mean over gravity torque)")
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"friction [{u['tau']}]")
    ax.grid(alpha=0.3)
    ax.legend()
    return _save(fig, folder, "friction_velocity.png")


def fig_heatmap(model, sig, u, folder: str, envelope=None) -> str:
    """Friction over (qd, tau_g); the region outside the model's training envelope is greyed and hatched."""
    qd, g = sig["qd"], logs.column(sig, "tau_g")
    vmax = float(np.max(np.abs(qd))) or 1.0
    gmax = float(np.max(np.abs(g))) or 1.0
    v = np.linspace(-vmax, vmax, 121)
    gg = np.linspace(-gmax, gmax, 81)
    V, G = np.meshgrid(v, gg)
    F = static_friction(model, V.ravel(), G.ravel(), sig).reshape(V.shape)
    fig, ax = plt.subplots(figsize=(6.5, 4.6))
    mesh = ax.pcolormesh(V, G, F, shading="auto", cmap="coolwarm")
    fig.colorbar(mesh, ax=ax, label=f"friction [{u['tau']}]")
    title = "model over velocity and gravity torque"
    if envelope is not None:
        out = ~envelope.covered_grid("qd", v, "tau_g", gg)
        if out.any():
            ax.pcolormesh(V, G, np.ma.masked_where(~out, np.ones(out.shape)), shading="auto", cmap="Greys",
                          vmin=0, vmax=2.5, alpha=0.6)
            ax.contourf(V, G, out.astype(float), levels=[0.5, 1.5], colors="none", hatches=["//"])
        title += f"\n(hatched: outside the training envelope, {100 * out.mean():.0f} % of the map)"
    ax.set_xlabel(f"velocity qd [{u['qd']}]")
    ax.set_ylabel(f"gravity torque tau_g [{u['tau']}]")
    ax.set_title(title, fontsize=10)
    return _save(fig, folder, "heatmap.png")


def fig_time(sig, pred, u, folder: str) -> str:
    t = sig["t"]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 5.5), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    a1.plot(t, logs.friction_target(sig), color=MEASURED, lw=0.8, label="measured")
    a1.plot(t, pred, color=MODEL, lw=1.2, label="predicted")
    a1.set_ylabel(f"friction [{u['tau']}]")
    a1.legend(loc="upper right")
    a1.grid(alpha=0.3)
    a2.plot(t, sig["qd"], color=OTHER, lw=1)
    a2.set_ylabel(f"qd [{u['qd']}]")
    a2.set_xlabel("time [s]")
    a2.grid(alpha=0.3)
    return _save(fig, folder, "friction_time.png")


def fig_quadrants(sig, u, folder: str) -> str:
    qd, g = sig["qd"], logs.column(sig, "tau_g")
    same = np.sign(qd) == np.sign(g)
    fig, ax = plt.subplots(figsize=(5.5, 4.6))
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
    return _save(fig, folder, "quadrants.png")


def fig_external(sig, pred, u, folder: str, lowpass_hz) -> str | None:
    if "tau_ext" not in sig:
        return None
    est = external_estimate(sig, pred, lowpass_hz)
    fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.plot(sig["t"], sig["tau_ext"], color=MEASURED, lw=1, label="sensor")
    ax.plot(sig["t"], est, color=MODEL, lw=1, label="estimated" + (f" (low-pass {lowpass_hz:g} Hz)" if lowpass_hz else ""))
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"external torque [{u['tau']}]")
    ax.legend(loc="upper right")
    ax.grid(alpha=0.3)
    return _save(fig, folder, "external_torque.png")


def write_report(model_path: str, log: logs.Log, folder: str, *, lowpass_hz: float | None = 5.0,
                 seed: int = 0) -> dict:
    """Write the figures and index.html into ``folder``; returns the figures and error figures."""
    model, meta = models.load(model_path)
    models.check_log(meta, log, model_path)
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {folder}: {exc.strerror}") from None
    sig, u = log.signals, log.units
    pred = model.predict(sig)[0]
    env = models.envelope(meta, model_path)
    rng = np.random.default_rng(seed)
    figures = [f for f in (
        fig_loss(model, folder),
        fig_velocity(model, sig, u, folder, rng),
        fig_heatmap(model, sig, u, folder, env),
        fig_time(sig, pred, u, folder),
        fig_quadrants(sig, u, folder),
        fig_external(sig, pred, u, folder, lowpass_hz),
    ) if f]
    summary = {"model": os.path.basename(model_path), "kind": meta.get("kind"), "log": os.path.basename(log.name),
               "friction": metrics.errors(logs.friction_target(sig), pred)}
    if env is not None:
        summary["extrapolation"] = share_outside(env, sig)
    if "tau_ext" in sig:
        summary["external"] = metrics.errors(sig["tau_ext"], external_estimate(sig, pred, lowpass_hz))
    atomic_write_bytes(os.path.join(folder, "index.html"), _html(summary, figures, u).encode())
    return {"figures": figures, **summary}


def write_reports(runs: list[tuple[str, logs.Log]], folder: str, *, lowpass_hz: float | None = 5.0,
                  seed: int = 0) -> dict:
    """One report per (model file, joint's log) in ``folder/joint_<name>/`` and an index.html
    linking them with each joint's errors; a single run is written into ``folder`` itself."""
    from fricli.modelset import file_name

    if len(runs) == 1:
        return {str(runs[0][1].joint): write_report(runs[0][0], runs[0][1], folder, lowpass_hz=lowpass_hz, seed=seed)}
    out = {}
    for model_path, log in runs:
        sub = file_name(log.joint)[:-len(".npz")]
        out[str(log.joint)] = dict(write_report(model_path, log, os.path.join(folder, sub), lowpass_hz=lowpass_hz,
                                                seed=seed), folder=sub)
    rows = []
    for j, r in out.items():
        ext = f"{r['external']['mae']:.3f}" if "external" in r else "–"
        rows.append(f'<tr><td><a href="{html.escape(r["folder"])}/index.html">joint {html.escape(j)}</a></td>'
                    f'<td>{html.escape(r["model"])}</td><td>{r["friction"]["mae"]:.3f}</td>'
                    f'<td>{r["friction"]["rmse"]:.3f}</td><td>{ext}</td></tr>')
    rows = "\n".join(rows)
    u = runs[0][1].units
    page = f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>fricli report: {html.escape(os.path.basename(runs[0][1].name))}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 10px;text-align:right}}</style></head>
<body><h1>fricli report</h1><p>{html.escape(os.path.basename(runs[0][1].name))}: {len(out)} joints</p>
<table><tr><th>joint</th><th>model</th><th>friction MAE [{u['tau']}]</th><th>friction RMSE [{u['tau']}]</th>
<th>external torque MAE [{u['tau']}]</th></tr>
{rows}</table>
</body></html>
"""
    atomic_write_bytes(os.path.join(folder, "index.html"), page.encode())
    return out


def _html(summary: dict, figures: list[str], u: dict) -> str:
    rows = [f"<tr><td>friction</td><td>{summary['friction']['mae']:.3f}</td><td>{summary['friction']['rmse']:.3f}</td>"
            f"<td>{summary['friction']['max']:.3f}</td></tr>"]
    if "external" in summary:
        e = summary["external"]
        rows.append(f"<tr><td>external torque</td><td>{e['mae']:.3f}</td><td>{e['rmse']:.3f}</td><td>{e['max']:.3f}</td></tr>")
    imgs = "\n".join(f'<figure><img src="{html.escape(f)}" alt="{html.escape(f)}"><figcaption>{html.escape(f)}</figcaption></figure>'
                     for f in figures)
    title = html.escape(f"{summary['model']} ({summary['kind']}) on {summary['log']}")
    out = summary.get("extrapolation")
    extra = "" if out is None else (f"<p>{100 * out['share']:.1f} % of the rows ({out['rows']:,} of {out['of']:,}) lie "
                                    "outside the model's training envelope.</p>")
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>fricli report: {title}</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}img{{max-width:100%}}
table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:4px 10px;text-align:right}}</style></head>
<body><h1>fricli report</h1><p>{title}</p>
<table><tr><th></th><th>MAE [{u['tau']}]</th><th>RMSE [{u['tau']}]</th><th>max [{u['tau']}]</th></tr>
{''.join(rows)}</table>
{extra}
{imgs}
</body></html>
"""
