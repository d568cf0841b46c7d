#!/usr/bin/env python
"""Accuracy of train-base's training schedules on the sample base log, measured on held-out logs.

    python benchmarks/schedules.py [--arch mlp] [--thin]   the table in docs/neural-models.md (minutes)
    python benchmarks/schedules.py --seeds 6            the default schedule with seeds 0..5
    python benchmarks/schedules.py --steps-scale 0.01   a quick check that everything runs

Trains NN_base (--arch, default the default network; seed 0, every other default) on sample_data/joint2_base.parquet with each
schedule and prints the validation MAE and the friction MAE on the moving rows (|qd| > 2 % of
the top speed) of two base logs simulated with seeds 1 and 2, which the training never saw.
With --thin, also the thin-data case (docs/neural-models.md): trained on thin base logs of seeds
1, 2, 3 with each schedule, the MAE on the thin log of the next seed (rows with |qd| > 0.002 rad/s)
as a multiple of that log's noise MAE. With --seeds N, instead: the default schedule trained
with seeds 0..N-1 (which rows train and validate, and the initial weights), the same errors.
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from fricli.core import logs
from fricli.fitting import learning  # noqa: E402
from fricli.sim import simulator  # noqa: E402

RUNS = (("paper: constant 0.01", dict(schedule="paper", steps=50_000)),
        ("cosine", dict(schedule="cosine", steps=30_000)),
        ("cosine", dict(schedule="cosine", steps=20_000)),
        ("cosine", dict(schedule="cosine", steps=15_000)),
        ("cosine", dict(schedule="cosine", steps=10_000)),
        ("cosine", dict(schedule="cosine", steps=7_000)),
        ("cosine", dict(schedule="cosine", steps=5_000)),
        ("constant, patience 5000", dict(schedule="paper", steps=50_000, patience=5000)))


def held_out_mae(model, log: logs.Log) -> float:
    sig = log.signals
    moving = np.abs(sig["qd"]) > 0.02 * np.abs(sig["qd"]).max()
    err = model.predict(sig)[0] - logs.friction_target(sig)
    return float(np.abs(err[moving]).mean())


def thin_ratio(model, log: logs.Log) -> float:
    sig = log.signals
    moving = np.abs(sig["qd"]) > 0.002
    target = logs.friction_target(sig)
    noise = float(np.mean(np.abs(target - sig["tau_f_true"])[moving]))
    return float(np.mean(np.abs(model.predict(sig)[0] - target)[moving])) / noise


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default=learning.DEFAULT_ARCH, choices=sorted(learning.ARCHS))
    ap.add_argument("--steps-scale", type=float, default=1.0, help="scale every run's steps (quick checks)")
    ap.add_argument("--thin", action="store_true", help="also the thin-data case (four times as long)")
    ap.add_argument("--seeds", type=int, default=0, help="instead: the default schedule with seeds 0..N-1")
    args = ap.parse_args(argv)
    base = logs.load_log(os.path.join(ROOT, "sample_data", "joint2_base.parquet"))
    held = [logs.from_table(simulator.simulate(scenario="base", seed=seed), name=f"base seed {seed}")
            for seed in (1, 2)]
    thin = {seed: [logs.from_table(simulator.simulate("base", 2, seed=s, thin=True), name=f"thin seed {s}")
                   for s in (seed, seed + 1)] for seed in (1, 2, 3)} if args.thin else {}
    if args.seeds:
        print("| seed | steps run | validation MAE | held-out seed 1 | held-out seed 2 |")
        print("|---:|---:|---:|---:|---:|")
        for seed in range(args.seeds):
            model, summary = learning.train_base(base, arch=args.arch, seed=seed)
            cells = [str(seed), f"{summary['steps']:,}", f"{summary['val']['mae']:.4f}"]
            print("| " + " | ".join(cells + [f"{held_out_mae(model, log):.4f}" for log in held]) + " |", flush=True)
        return
    head = ["training", "steps run", "validation MAE", "held-out seed 1", "held-out seed 2"]
    head += [f"thin {seed} -> {seed + 1}" for seed in thin]
    print("| " + " | ".join(head) + " |")
    print("|---|" + "---:|" * (len(head) - 1))
    for label, options in RUNS:
        options = dict(options, steps=max(10, int(options["steps"] * args.steps_scale)))
        model, summary = learning.train_base(base, arch=args.arch, **options)
        cells = [f"{label}, {options['steps']:,} steps", f"{summary['steps']:,}", f"{summary['val']['mae']:.4f}"]
        cells += [f"{held_out_mae(model, log):.4f}" for log in held]
        for train, test in thin.values():
            cells.append(f"{thin_ratio(learning.train_base(train, arch=args.arch, **options)[0], test):.3f}x")
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
