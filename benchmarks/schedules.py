#!/usr/bin/env python
"""Accuracy of train-base's training schedules on the sample base log, measured on held-out logs.

    python benchmarks/schedules.py [--arch mlp]    the tables in docs/neural-models.md (several minutes)
    python benchmarks/schedules.py --steps-scale 0.01   a quick check that everything runs

Trains NN_base (--arch, default the default network; seed 0, every other default) on sample_data/joint2_base.parquet with each
schedule and prints the validation MAE and the friction MAE on the moving rows (|qd| > 2 % of
the top speed) of two base logs simulated with seeds 1 and 2, which the training never saw.
"""

from __future__ import annotations

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from fricli import learning, logs  # noqa: E402
from fricli.sim import simulator  # noqa: E402

RUNS = (("paper: constant 0.01", dict(schedule="paper", steps=50_000)),
        ("cosine", dict(schedule="cosine", steps=30_000)),
        ("cosine", dict(schedule="cosine", steps=25_000)),
        ("cosine", dict(schedule="cosine", steps=20_000)),
        ("cosine", dict(schedule="cosine", steps=15_000)),
        ("cosine", dict(schedule="cosine", steps=10_000)),
        ("constant, patience 5000", dict(schedule="paper", steps=50_000, patience=5000)))


def held_out_mae(model, log: logs.Log) -> float:
    sig = log.signals
    moving = np.abs(sig["qd"]) > 0.02 * np.abs(sig["qd"]).max()
    err = model.predict(sig)[0] - logs.friction_target(sig)
    return float(np.abs(err[moving]).mean())


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arch", default=learning.DEFAULT_ARCH, choices=sorted(learning.ARCHS))
    ap.add_argument("--steps-scale", type=float, default=1.0, help="scale every run's steps (quick checks)")
    args = ap.parse_args(argv)
    base = logs.load_log(os.path.join(ROOT, "sample_data", "joint2_base.parquet"))
    held = [logs.from_table(simulator.simulate(scenario="base", seed=seed), name=f"base seed {seed}")
            for seed in (1, 2)]
    print("| training | steps run | validation MAE | held-out seed 1 | held-out seed 2 |")
    print("|---|---:|---:|---:|---:|")
    for label, options in RUNS:
        options = dict(options, steps=max(10, int(options["steps"] * args.steps_scale)))
        model, summary = learning.train_base(base, arch=args.arch, **options)
        cells = [f"{label}, {options['steps']:,} steps", f"{summary['steps']:,}", f"{summary['val']['mae']:.4f}"]
        cells += [f"{held_out_mae(model, log):.4f}" for log in held]
        print("| " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
