"""predict file to file with the default model of a log without velocity levels, on rows whose
measured velocities all differ, against plain pyarrow (read + append a column + write).

    python benchmarks/predict_continuous.py                  # 10 M rows, 3 repeats
    python benchmarks/predict_continuous.py --rows 200000 --steps 50 --repeats 1   # a quick check

The continuous-motion log of benchmarks/run.py (``harmonic_log``: three harmonics, no velocity
levels) is fitted by ``fricli train-base`` with its defaults (one network, with the prior and the
pre-sliding state when the held-out blocks choose them), with ``--ensemble 5`` and with
``--no-prior`` (the network alone, with the pre-sliding state). On this simulated log the held-out
blocks give the prior the whole share (blend 0), and predict then leaves the network out: the
default's figure is the prior's and the pre-sliding state's cost, and ``--no-prior``'s is that of a
model whose network counts, as on the real joints (blend 0.23-1.00 there). The log is then
repeated to ``--rows`` rows, time continuing, with every velocity moved by a random 10 ppm (as
measurement noise would), and written once. Each repeat times, one after the other so that they
see the same load: plain pyarrow, predict with the default model, plain pyarrow, predict with the
mean of five, plain pyarrow, predict with the network alone. Ratios: the median plain pyarrow time over the median predict time (above 1: faster
than plain pyarrow)."""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
_spec = importlib.util.spec_from_file_location("fricli_benchmarks", os.path.join(HERE, "run.py"))
run = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(run)

from fricli.core import logs  # noqa: E402


def train(log_path: str, model_path: str, extra: list[str]) -> dict:
    cmd = [sys.executable, "-m", "fricli", "train-base", log_path, "-o", model_path, "--json", "--quiet", *extra]
    proc = subprocess.run(cmd, cwd=run.ROOT, capture_output=True, text=True, check=True)
    return json.loads(proc.stdout)


def big_file(log_path: str, rows: int, path: str, seed: int = 0) -> None:
    log = logs.load_log(log_path)
    sig = run.tiled_signals(log, rows)
    sig["qd"] = sig["qd"] * (1.0 + 1e-5 * np.random.default_rng(seed).standard_normal(rows))
    run.write_log(sig, log.units, path)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=10_000_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=None, help="train-base --steps (default: its own)")
    args = ap.parse_args(argv)
    steps = ["--steps", str(args.steps)] if args.steps else []
    with tempfile.TemporaryDirectory() as tmp:
        log_path = run.harmonic_log(tmp)
        variants = {"default": [], "--ensemble 5": ["--ensemble", "5"], "--no-prior": ["--no-prior"]}
        models = {name: os.path.join(tmp, f"model{k}.npz") for k, name in enumerate(variants)}
        summaries = {name: train(log_path, models[name], [*steps, *extra]) for name, extra in variants.items()}
        from fricli import models as fricli_models
        described = {}
        for name in variants:
            model, _ = fricli_models.load(models[name])
            parts = [f"{len(model.nets_)} network{'s' * (len(model.nets_) > 1)}"]
            if getattr(model, "prior_", None) is not None:
                parts.append(f"prior share {1.0 - model.blend_:.3g}")
            if getattr(model, "sigma0_", None) is not None:
                parts.append("pre-sliding state")
            described[name] = ", ".join(parts)
        big, out = os.path.join(tmp, "big.parquet"), os.path.join(tmp, "out.parquet")
        big_file(log_path, args.rows, big)
        times = {"plain pyarrow": [], **{name: [] for name in variants}}
        for _ in range(args.repeats):
            for name in variants:
                times["plain pyarrow"].append(run.plain_pyarrow_s(big, out))
                times[name].append(run.run_cli(["predict", models[name], big, "-o", out], 1))
    plain = statistics.median(times["plain pyarrow"])
    res = {"rows": args.rows, "times_s": times, "ratios": {}, "train_base": summaries, "models": described}
    print(f"{args.rows:,} rows, velocities all different; plain pyarrow {plain:.2f} s (median of "
          f"{len(times['plain pyarrow'])})")
    for name in variants:
        secs = statistics.median(times[name])
        res["ratios"][name] = plain / secs
        print(f"  predict, train-base {name} ({described[name]}): {secs:.2f} s = {plain / secs:.2f}x plain "
              f"pyarrow; runs {', '.join(f'{v:.2f}' for v in times[name])} s")
    return res


if __name__ == "__main__":
    main()
