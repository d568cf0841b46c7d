"""Make docs/studies/img/emps-diagnose.png and print the figures of docs/studies/case-study-emps.md.

Needs the EMPS data at ../shared/data/emps/emps.parquet (relative to the repository root;
not part of the repository). Run from the repository root:

    python studies/emps/make_emps_figure.py
"""

from __future__ import annotations

import pathlib
import sys
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from click.testing import CliRunner  # noqa: E402

from fricli import models
from fricli.applying import emps
from fricli.core import logs  # noqa: E402
from fricli.cli import cli  # noqa: E402
from fricli.fitting.diagnosis import diagnose  # noqa: E402
from fricli.fitting.diagnosis.fix import augment  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "emps" / "emps.parquet"
OUT = ROOT / "docs" / "studies" / "img" / "emps-diagnose.png"


def run(*args) -> str:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    if res.exit_code != 0:
        sys.exit(f"fricli {' '.join(map(str, args))} failed: {res.stderr}")
    return res.stdout


def main() -> None:
    if not DATA.exists():
        sys.exit(f"{DATA} is absent")
    log = logs.load_log(str(DATA), cutoff_hz=emps.CUTOFF_HZ, zero=("tau_g", "tau_dyn"))   # no robot model
    sig = log.signals
    sym = emps.idim_ls(sig["t"], sig["q"], sig["tau_m"])
    asym = emps.idim_ls(sig["t"], sig["q"], sig["tau_m"], asymmetric=True)
    print(f"IDIM-LS with scipy: symmetric {sym.rel_error:.2f} %, asymmetric {asym.rel_error:.2f} %")
    print("  symmetric:", {k: round(v, 2) for k, v in sym.params.items()})
    print("  asymmetric:", {k: round(v, 2) for k, v in asym.params.items()})

    with tempfile.TemporaryDirectory() as tmp:
        fixed = {}
        for refine in (False, True):
            base = f"{tmp}/emps{'-refine' if refine else ''}.npz"
            run("identify", DATA, "--cutoff", 100, "--no-gravity", "--no-dynamics", "-o", base, "-q", *(["--refine"] if refine else []))
            model, _ = models.load(base)
            d = diagnose(model, log)
            name = "identify --refine" if refine else "identify"
            print(f"\n{name}: {model.parameters()}")
            print(f"  LuGre alone: {emps.model_errors(model, log)}")
            print(f"  added: {d.added}")
            for e in d.effects:
                if e.added:
                    print(f"    {e.name}: gain {100 * e.gain:.2f} %, of rest {100 * e.step_gain:.1f} %, {e.summary}")
            for k in range(1, len(d.added) + 1):
                dk = diagnose(model, log, max_effects=k)
                ak = augment(model, dk, log)
                print(f"  fixed with {dk.added}: {emps.model_errors(ak, log)}")
            aug = augment(model, d, log)
            print(f"  fixed: carried {aug.carried}, refitted {aug.refitted}, {emps.model_errors(aug, log)}")
            print("  " + aug.describe().replace("\n", "\n  "))
            fixed[refine] = (model, aug, d)

    model, aug, d = fixed[False]
    y = sig["tau_m"]
    before = model.predict(sig)[0]
    after = aug.predict(sig)[0]
    err = emps.model_errors(aug, log)
    t = sig["t"]
    fig, axes = plt.subplots(3, 1, figsize=(10, 9), gridspec_kw={"height_ratios": [1.2, 1.0, 0.8]})
    ax = axes[0]
    win = t <= 6.5
    ax.plot(t[win], y[win], lw=1.6, color="0.15", label="measured motor force")
    ax.plot(t[win], before[win], lw=1.0, color="tab:red", label="identified LuGre model")
    ax.plot(t[win], after[win], lw=1.0, color="tab:cyan", ls="--", label="after diagnose --fix")
    ax.set_ylabel("force [N]")
    ax.set_xlabel("time [s] (first 6.5 s)")
    ax.legend(loc="lower left", fontsize=8, ncol=3)
    ax.set_title("EMPS: diagnose adds " + ", ".join(d.added) + " to the identified LuGre model", fontsize=10)
    ax = axes[1]
    ax.plot(t, y - before, lw=0.5, color="tab:red", alpha=0.6, label="residual of the identified LuGre model")
    ax.plot(t, y - after, lw=0.5, color="tab:blue", label="residual after the fix")
    ax.set_ylim(-120, 120)
    ax.set_ylabel("residual [N]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="upper right", fontsize=8, ncol=2)
    ax = axes[2]
    labels = ["IDIM-LS sym.\n(published)", "IDIM-LS asym.\n(published)", "IDIM-LS sym.\n(scipy)",
              "IDIM-LS asym.\n(scipy)", "fricli fixed\n(benchmark's way)", "fricli fixed\n(raw, 1 kHz)"]
    values = [emps.PUBLISHED["symmetric"]["rel_error"], emps.PUBLISHED["asymmetric"]["rel_error"],
              sym.rel_error, asym.rel_error, err["benchmark"], err["raw"]]
    colors = ["0.6", "0.6", "0.4", "0.4", "tab:blue", "tab:cyan"]
    bars = ax.bar(range(len(values)), values, color=colors)
    for bar, v in zip(bars, values):
        ax.text(bar.get_x() + bar.get_width() / 2, v + 0.05, f"{v:.2f} %", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(range(len(values)), labels, fontsize=8)
    ax.set_ylabel("relative error [%]")
    ax.set_ylim(0, max(values) * 1.25)
    fig.tight_layout()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=100)
    print(f"\nwrote {OUT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
