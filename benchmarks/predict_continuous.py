"""predict file to file with the default model of a log without velocity levels, on rows whose
measured velocities all differ, against plain pyarrow (read + append a column + write).

    python benchmarks/predict_continuous.py                  # 10 M rows, 3 repeats
    python benchmarks/predict_continuous.py --rows 200000 --steps 50 --repeats 1   # a quick check

The continuous-motion log of benchmarks/run.py (``harmonic_log``: three harmonics, no velocity
levels) is fitted by ``fricli train-base`` with its defaults (one network, with the prior and the
pre-sliding state when the held-out blocks choose them) and with ``--ensemble 5``. The log is then
repeated to ``--rows`` rows, time continuing, with every velocity moved by a random 10 ppm (as
measurement noise would), and written once. Each repeat times, one after the other so that they
see the same load: plain pyarrow, predict with the default model, plain pyarrow, predict with the
mean of five. Ratios: the median plain pyarrow time over the median predict time (above 1: faster
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
        models = {"default": os.path.join(tmp, "one.npz"), "--ensemble 5": os.path.join(tmp, "five.npz")}
        summaries = {"default": train(log_path, models["default"], steps),
                     "--ensemble 5": train(log_path, models["--ensemble 5"], [*steps, "--ensemble", "5"])}
        from fricli import models as fricli_models
        default, _ = fricli_models.load(models["default"])
        parts = [f"{len(default.nets_)} network"]
        if getattr(default, "prior_", None) is not None:
            parts.append(f"prior share {1.0 - default.blend_:.3g}")
        if getattr(default, "sigma0_", None) is not None:
            parts.append("pre-sliding state")
        res_model = ", ".join(parts)
        big, out = os.path.join(tmp, "big.parquet"), os.path.join(tmp, "out.parquet")
        big_file(log_path, args.rows, big)
        times = {"plain pyarrow": [], "default": [], "--ensemble 5": []}
        for _ in range(args.repeats):
            for name in ("default", "--ensemble 5"):
                times["plain pyarrow"].append(run.plain_pyarrow_s(big, out))
                times[name].append(run.run_cli(["predict", models[name], big, "-o", out], 1))
    plain = statistics.median(times["plain pyarrow"])
    res = {"rows": args.rows, "times_s": times, "ratios": {}, "train_base": summaries, "default_model": res_model}
    print(f"{args.rows:,} rows, velocities all different; plain pyarrow {plain:.2f} s (median of "
          f"{len(times['plain pyarrow'])}); the default model: {res_model}")
    for name in ("default", "--ensemble 5"):
        secs = statistics.median(times[name])
        res["ratios"][name] = plain / secs
        print(f"  predict, train-base {name}: {secs:.2f} s = {plain / secs:.2f}x plain pyarrow; "
              f"runs {', '.join(f'{v:.2f}' for v in times[name])} s")
    return res


if __name__ == "__main__":
    main()
