"""Make docs/img/neural-thin.png and print the thin-data figures of docs/neural-models.md.

The thin-data case: `fricli simulate --thin` base logs (each slow level one short stretch at a
random position). For training seeds 1, 2, 3 the default network (`dissipative`) and the paper's
MLP (`mlp`) are trained with the defaults of `fricli train-base` and predict an independent thin
log of the next seed; the MAE over the moving rows (|qd| > 0.002 rad/s) is printed as a
multiple of the noise MAE (target against tau_f_true over the same rows), together with the
same ratio for the exact steady-state friction of the simulator (the best any model without a
bristle state can do), and violations of tau_f qd >= 0. Run from the repository root
(a few minutes on two cores; --steps 2000 for a quick look):

    python tools/docs/make_neural_figure.py [--steps N]
"""

from __future__ import annotations

import argparse
import pathlib

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from fricli.core import logs
from fricli.fitting import learning
from fricli.numerics import physics  # noqa: E402
from fricli.sim import simulator  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
OUT = ROOT / "docs" / "img" / "neural-thin.png"
MOVING = 0.002   # rad/s


def thin(seed: int) -> logs.Log:
    return logs.from_table(simulator.simulate("base", 2, seed=seed, thin=True), name=f"thin seed {seed}")


def steady_state(sig: dict) -> np.ndarray:
    """The simulator's exact friction without the bristle transients (base state, joint 2)."""
    p = simulator.true_params(2)
    load = np.abs(sig["tau_g"])
    g = physics.stribeck(sig["qd"], p["fc"] + p["kc"] * load, p["fs"] + p["ks"] * load, p["vs"], p["delta"])
    return np.sign(sig["qd"]) * g + p["fv"] * sig["qd"]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=None, help="Adam steps (default: train-base's)")
    steps = parser.parse_args().steps
    shown = {}
    print(f"| train seed | test seed | noise MAE [Nm] | dissipative | mlp | steady state | "
          f"wrong-sign rows (dissipative / mlp) |")
    print("|---|---|---|---|---|---|---|")
    for seed in (1, 2, 3):
        train, test = thin(seed), thin(seed + 1)
        sig = test.signals
        moving = np.abs(sig["qd"]) > MOVING
        target = logs.friction_target(sig)
        noise = float(np.mean(np.abs(target - sig["tau_f_true"])[moving]))
        ratio, wrong = {}, {}
        for arch in ("dissipative", "mlp"):
            model, _ = learning.train_base(train, arch=arch, steps=steps, seed=0)
            pred = model.predict(sig)[0]
            ratio[arch] = float(np.mean(np.abs(pred - target)[moving])) / noise
            wrong[arch] = int(np.count_nonzero((pred * sig["qd"] < 0) & moving))
            if seed == 1:
                shown[arch] = pred
        best = float(np.mean(np.abs(steady_state(sig) - target)[moving])) / noise
        print(f"| {seed} | {seed + 1} | {noise:.3f} | {ratio['dissipative']:.2f}x | {ratio['mlp']:.2f}x | "
              f"{best:.2f}x | {wrong['dissipative']} / {wrong['mlp']} |")
        if seed == 1:
            shown_sig = sig

    sig = shown_sig
    slow = (np.abs(sig["qd"]) > MOVING) & (np.abs(sig["qd"]) < 0.12)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharey=True)
    for ax, (arch, title) in zip(axes, (("mlp", "paper's MLP, NN(tau_g, qd)"),
                                        ("dissipative", "dissipative network (default)"))):
        ax.scatter(sig["qd"][slow], sig["tau_f_true"][slow], s=3, color="0.6", label="true friction",
                   rasterized=True)
        sc = ax.scatter(sig["qd"][slow], shown[arch][slow], s=3, c=sig["tau_g"][slow], cmap="coolwarm",
                        label="predicted", rasterized=True)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_xscale("symlog", linthresh=0.005)
        ax.set_xlabel("velocity qd [rad/s]")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("friction [Nm]")
    axes[0].legend(loc="upper left", fontsize=8, markerscale=4)
    fig.colorbar(sc, ax=axes, label="gravity torque tau_g [Nm]")
    fig.suptitle("thin base log (slow levels at one position each): independent log of another seed", fontsize=10)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
