"""Make docs/img/drives-coupled-wrist.png and print the figures of docs/drives.md.

The simulated arm of ``fricli.sim.coupled`` (coupled wrist, friction in the motors): a training
and a held-out run; on the wrist joints 5 and 6, the coupled model (identify --coupling) and a
per-joint LuGre and linear model each (identify --joint J [--kind linear]), scored on the held-out run against the friction
target tau_m - tau_g - tau_dyn and the simulation's noise floor. Run from the repository root:

    python tools/docs/make_drives_figure.py
"""

from __future__ import annotations

import pathlib
import sys
import tempfile

import numpy as np
import pyarrow.parquet as pq
from click.testing import CliRunner
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fricli.core import logs
from fricli.cli import cli
from fricli.sim.coupled import default_arm, simulate_coupled

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "img" / "drives-coupled-wrist.png"
WRIST = (5, 6)


def run(*args) -> None:
    res = CliRunner().invoke(cli, [str(a) for a in args])
    if res.exit_code != 0:
        sys.exit(f"fricli {' '.join(map(str, args))} failed: {res.output}")


def joint_rows(path, joint) -> dict[str, np.ndarray]:
    table = pq.read_table(path)
    rows = table.column("joint").to_numpy() == joint
    return {c: table.column(c).to_numpy()[rows] for c in ("t", "tau_m", "tau_g", "tau_dyn", "tau_f_pred")}


def main() -> None:
    arm = default_arm()
    floor = dict(zip(arm.transmission.joints, arm.noise_floor()))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        for name, seed in (("train", 1), ("test", 2)):
            r = simulate_coupled(arm, duration=20.0, rate_hz=2000.0, rng=np.random.default_rng(seed))
            logs.write_table(r.table, str(tmp / f"{name}.parquet"))
        run("identify", tmp / "train.parquet", "--coupling", "--joint", 5, "-o", tmp / "wrist.npz", "-q")
        run("predict", tmp / "wrist.npz", tmp / "test.parquet", "-o", tmp / "coupled.parquet", "-q")
        per_joint, linear = {}, {}
        for joint in WRIST:
            for kind, store in (("lugre", per_joint), ("linear", linear)):
                run("identify", tmp / "train.parquet", "--joint", joint, "--kind", kind, "-o", tmp / f"{kind}{joint}.npz",
                    "-q")
                run("predict", tmp / f"{kind}{joint}.npz", tmp / "test.parquet", "-o", tmp / f"{kind}{joint}.parquet",
                    "-q")
                store[joint] = joint_rows(tmp / f"{kind}{joint}.parquet", joint)
        coupled = {joint: joint_rows(tmp / "coupled.parquet", joint) for joint in WRIST}
        run("identify", tmp / "train.parquet", "--coupling", "-o", tmp / "arm", "-q")
        run("predict", tmp / "arm", tmp / "test.parquet", "-o", tmp / "arm.parquet", "-q")
        whole = {joint: joint_rows(tmp / "arm.parquet", joint) for joint in arm.transmission.joints}
    print("the whole arm, identify --coupling (the group's model for joints 5 and 6, LuGre for the others):")
    print("  held-out RMSE / noise floor: " + ", ".join(
        f"joint {j} {np.sqrt(np.mean((m['tau_f_pred'] - (m['tau_m'] - m['tau_g'] - m['tau_dyn'])) ** 2)) / floor[j]:.2f}x"
        for j, m in whole.items()))

    fig = Figure(figsize=(11, 6.5), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplot_mosaic([["5", "5", "bars"], ["6", "6", "bars"]])
    rmse = {}
    print("held-out friction error (RMSE against tau_m - tau_g - tau_dyn), simulated arm, 20 s at 2 kHz:")
    print(f"{'joint':>5}  {'noise floor':>11}  {'coupled':>17}  {'per-joint LuGre':>18}  {'per-joint linear':>18}")
    for joint in WRIST:
        c, lg = coupled[joint], per_joint[joint]
        target = c["tau_m"] - c["tau_g"] - c["tau_dyn"]
        rmse[joint] = [float(np.sqrt(np.mean((m["tau_f_pred"] - target) ** 2))) for m in (c, lg, linear[joint])]
        print(f"{joint:>5}  {floor[joint]:>8.4f} Nm" + "".join(f"  {e:>8.4f} Nm ({e / floor[joint]:5.2f}x)"
                                                            for e in rmse[joint]))
        ax = axes[str(joint)]
        window = (c["t"] >= 4.0) & (c["t"] < 10.0)
        t = c["t"][window]
        ax.plot(t, target[window], color="0.75", lw=0.6, label="friction target (tau_m - tau_g - tau_dyn)")
        ax.plot(t, lg["tau_f_pred"][window], color="tab:red", lw=1.2, label="per-joint LuGre model")
        ax.plot(t, c["tau_f_pred"][window], color="tab:blue", lw=1.2, label="coupled model (friction per motor)")
        ax.set_ylabel(f"joint {joint} friction [Nm]")
        ax.set_title(f"joint {joint}, held-out run", loc="left", fontsize=10)
    axes["6"].set_xlabel("t [s]")
    axes["5"].legend(loc="upper right", fontsize=8)
    ax = axes["bars"]
    x = np.arange(len(WRIST))
    for i, (label, color) in enumerate((("coupled", "tab:blue"), ("per-joint LuGre", "tab:red"),
                                        ("per-joint linear", "tab:orange"))):
        ax.bar(x + (i - 1) * 0.27, [rmse[j][i] / floor[j] for j in WRIST], 0.27, color=color, label=label)
    ax.axhline(1.0, color="k", lw=0.8, ls="--", label="noise floor")
    ax.set_xticks(x, [f"joint {j}" for j in WRIST])
    ax.set_ylabel("held-out RMSE / noise floor")
    ax.legend(fontsize=8)
    fig.suptitle("Coupled wrist (R = [[-50, 0], [30, 40]]): friction lives in the motors", fontsize=11)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT.relative_to(ROOT)}")
    stribeck_table()


def stribeck_table() -> None:
    """The coupled model with and without the Stribeck curve per motor on the arm whose motors have
    a Stribeck bump (20 s at 1 kHz; training seed 11, held-out seed 12)."""
    from fricli.models.coupled import CoupledModel

    arm = default_arm(stribeck=True)
    wrist = [arm.transmission.joints.index(j) for j in WRIST]
    tr = arm.transmission.sub(wrist)
    train, test = (simulate_coupled(arm, duration=20.0, rate_hz=1000.0, rng=np.random.default_rng(s)) for s in (11, 12))
    target = {name: (r.tau_m - r.tau_g - r.tau_dyn)[:, wrist] for name, r in (("train", train), ("test", test))}
    print("motors with a Stribeck bump: held-out RMSE / noise floor of the coupled model")
    for stribeck in (False, True):
        model, _ = CoupledModel.fit(tr.joints, tr.ratio, train.qd[:, wrist], target["train"], stribeck=stribeck)
        err = model.predict_group(test.qd[:, wrist]) - target["test"]
        ratio = np.sqrt(np.mean(err ** 2, axis=0)) / arm.noise_floor()[wrist]
        what = "with the Stribeck curve" if stribeck else "Coulomb + viscous     "
        print(f"  {what}: " + ", ".join(f"joint {j} {r:.2f}x" for j, r in zip(WRIST, ratio)))


if __name__ == "__main__":
    main()
