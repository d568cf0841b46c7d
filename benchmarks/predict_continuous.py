"""predict file to file with the default model of a log without velocity levels, on rows whose
measured velocities all differ, against plain pyarrow (read + append a column + write).

    python benchmarks/predict_continuous.py                  # 10 M rows, 3 repeats
    python benchmarks/predict_continuous.py --rows 200000 --steps 50 --repeats 1   # a quick check

The continuous-motion log of benchmarks/run.py (``harmonic_log``: three harmonics, no velocity
levels) is fitted by ``fricli train-base`` with its defaults (one network, with the prior and the
pre-sliding state when the held-out blocks choose them), with ``--ensemble 5`` and with
``--no-prior`` (the network alone, with the pre-sliding state). Predict leaves out a term of
weight 0: at a network share of 0 (the prior alone) the network is not evaluated, and the line
of each model says its share. The log is then repeated to ``--rows`` rows, time continuing, with
every velocity moved by a random 10 ppm (as measurement noise would), and written once.

Plain pyarrow is timed two ways (``benchmarks/plain_pyarrow.py``): as its own process, started as
the fricli command is (start-up, imports and first allocations included on both sides: the
like-for-like ratio), and called again and again in this warm process (its memory pool and
mapped pages reused, which a command never has). Each repeat times, one after the other so that
they see the same load: both plain pyarrow runs, then predict with one of the models, in turn.
Ratios: the median plain pyarrow time over the median predict time (above 1: faster than plain
pyarrow)."""

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
        baselines = ("plain pyarrow, a process", "plain pyarrow, warm")
        times = {**{b: [] for b in baselines}, **{name: [] for name in variants}}
        for _ in range(args.repeats):
            for name in variants:
                times[baselines[0]].append(run.plain_pyarrow_process_s(big, out))
                times[baselines[1]].append(run.plain_pyarrow_s(big, out))
                times[name].append(run.run_cli(["predict", models[name], big, "-o", out], 1))
    plain = {b: statistics.median(times[b]) for b in baselines}
    res = {"rows": args.rows, "times_s": times, "ratios": {}, "ratios_warm": {}, "train_base": summaries,
           "models": described}
    print(f"{args.rows:,} rows, velocities all different; plain pyarrow as a process {plain[baselines[0]]:.2f} s, "
          f"in a warm process {plain[baselines[1]]:.2f} s (medians of {len(times[baselines[0]])})")
    for name in variants:
        secs = statistics.median(times[name])
        res["ratios"][name], res["ratios_warm"][name] = plain[baselines[0]] / secs, plain[baselines[1]] / secs
        print(f"  predict, train-base {name} ({described[name]}): {secs:.2f} s = {plain[baselines[0]] / secs:.2f}x "
              f"plain pyarrow as a process ({plain[baselines[1]] / secs:.2f}x warm); runs "
              f"{', '.join(f'{v:.2f}' for v in times[name])} s")
    return res


if __name__ == "__main__":
    main()
