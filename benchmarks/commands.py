"""Whole-command times of each command's default on real recordings with continuous motion (the
Franka joint-2 files, the UR10e fitting run) and on the sample log (velocity sweeps).

    python benchmarks/commands.py                 # median of 3 runs per command, a markdown table
    python benchmarks/commands.py --repeats 1

Each command runs as a user types it (``python -m fricli ...``, start-up included), on:
- Franka slow / middle / high: the first 60 % of each file's time (benchmarks/franka_split.py's
  split; the friction target itself, so --no-gravity --no-dynamics), predict on the last 40 %;
- UR10e: the fitting run ur-20_02_12-50sec_12harm imported as benchmarks/ur10e_neural.py does
  (six joints in one log: every command fits or scores all six);
- sample: sample_data/joint2_base.parquet.
Commands: identify, identify --kind gms, train-base, predict (the train-base model), diagnose (the
identify model) and export (the train-base model to C). Data: ../shared/data (or --data); a data
set that is absent is skipped with a note.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import franka_split  # noqa: E402
import ur10e_neural  # noqa: E402

SHARED = os.path.join(os.path.dirname(ROOT), "shared", "data")


def timed(args: list[str], repeats: int) -> float:
    """Median wall time [s] of ``fricli args``."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "fricli", *args, "-q"], cwd=ROOT, capture_output=True,
                              text=True, env=dict(os.environ, PYTHONPATH=ROOT))
        times.append(time.perf_counter() - start)
        if done.returncode != 0:
            raise SystemExit(f"fricli {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()}")
    return statistics.median(times)


def datasets(data: str, work: str) -> list[tuple[str, str, str, list[str]]]:
    """(name, fit log, scored log, extra options) of every data set present."""
    out = []
    franka = os.path.join(data, "franka")
    for name in franka_split.FILES:
        csv = os.path.join(franka, f"joint2_{name}.csv")
        if os.path.exists(csv):
            fit, test = franka_split.split(csv, work, name)
            out.append((f"Franka {name}", fit, test, ["--no-gravity", "--no-dynamics"]))
        else:
            print(f"note: {csv} is absent: skipped", file=sys.stderr)
    ur = os.path.join(data, "ur10e")
    if os.path.isdir(ur):
        fit = ur10e_neural.import_run(ur, work, ur10e_neural.BASE_FIT)
        out.append(("UR10e (6 joints)", fit, fit, []))
    else:
        print(f"note: {ur} is absent: skipped", file=sys.stderr)
    sample = os.path.join(ROOT, "sample_data", "joint2_base.parquet")
    out.append(("sample", sample, sample, []))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=SHARED)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as work:
        for name, fit, test, extra in datasets(args.data, work):
            lugre, nn, gms = (os.path.join(work, f"{k}.npz") for k in ("lugre", "nn", "gms"))
            if name.startswith("UR10e"):
                lugre, nn, gms = (os.path.join(work, k) for k in ("lugre", "nn", "gms"))   # a folder per arm
            cells = {
                "identify": timed(["identify", fit, "-o", lugre, *extra], args.repeats),
                "identify --kind gms": timed(["identify", fit, "--kind", "gms", "-o", gms, *extra], args.repeats),
                "train-base": timed(["train-base", fit, "-o", nn, *extra], args.repeats),
                "predict": timed(["predict", nn, test, "-o", os.path.join(work, "pred.parquet"), *extra],
                                 args.repeats),
                "diagnose": timed(["diagnose", lugre, fit, *extra], args.repeats),
                "export": timed(["export", nn, "-o", os.path.join(work, "friction.h")], args.repeats),
            }
            rows.append((name, cells))
            print(name, {k: round(v, 2) for k, v in cells.items()}, file=sys.stderr, flush=True)
    names = list(rows[0][1])
    print("| data | " + " | ".join(names) + " |")
    print("|---|" + "---:|" * len(names))
    for name, cells in rows:
        print(f"| {name} | " + " | ".join(f"{cells[k]:.2f}" for k in names) + " |")


if __name__ == "__main__":
    main()
