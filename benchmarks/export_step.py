"""The exported C step of the default model of the Franka slow file: ns per step and instructions.

    python benchmarks/export_step.py                       # train-base on the first 60 %, time on the rest
    python benchmarks/export_step.py --model M.npz --log L.parquet --header H.h --callgrind

The default ``fricli train-base --no-gravity --no-dynamics`` is fitted on the first 60 % of
joint2_slow.csv (``franka_split.split``) unless ``--model`` is given; its export (or ``--header``, a
header of the same model written by another version, to compare) is compiled with the driver of
tests/export_check.py (gcc -O2) and timed over the rows of the last 40 % (or ``--log``): CPU ns per
step, best of ``--repeats`` runs of 0.5 s. ``--callgrind``: instructions per step counted by
valgrind (the count of a run over all rows minus that over the first half, per row: the loading
and start-up cost taken off), which does not depend on the host's load.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests"))
sys.path.insert(0, HERE)

import export_check as check  # noqa: E402
import franka_split  # noqa: E402


def instructions(exe: str, x: np.ndarray, folder: str) -> float:
    """valgrind callgrind instructions per step of ``exe`` over the rows x (n, k)."""
    def count(rows: int) -> int:
        src = os.path.join(folder, "rows.bin")
        np.ascontiguousarray(x[:rows]).tofile(src)
        err = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={folder}/cg.out", exe, src,
                              os.path.join(folder, "out.bin")], capture_output=True, text=True).stderr
        return int(re.search(r"Collected : (\d+)", err).group(1))
    half = len(x) // 2
    return (count(len(x)) - count(half)) / (len(x) - half)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=None, help="a model file (default: train-base on the first 60 %%)")
    ap.add_argument("--log", default=None, help="the rows to step over (default: the last 40 %%)")
    ap.add_argument("--header", default=None, help="time this header of the model instead of its export")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--callgrind", action="store_true", help="also count instructions (valgrind)")
    args = ap.parse_args(argv)
    from fricli import models
    from fricli.core import logs
    from fricli.export import c

    with tempfile.TemporaryDirectory() as tmp:
        model_path, log_path = args.model, args.log
        if model_path is None or log_path is None:
            fit, test = franka_split.split(os.path.join(franka_split.DEFAULT_DATA, "joint2_slow.csv"), tmp, "slow")
            log_path = log_path or test
            if model_path is None:
                model_path = os.path.join(tmp, "slow.npz")
                franka_split.fricli("train-base", fit, "-o", model_path, "--no-gravity", "--no-dynamics", "-q")
        model, _ = models.load(model_path)
        header = args.header or os.path.join(tmp, "fr.h")
        if args.header is None:
            with open(header, "w") as fh:
                fh.write(c.export(model_path, "fr"))
        exe = os.path.join(tmp, "fr")
        check.build(header, "fr", exe)
        log = logs.load_log(log_path, zero=("tau_g", "tau_dyn"), warn=lambda *a: None)
        x = check.signal_matrix(log.signals, c.signals_of(model))
        ns = [check.time_step(exe, x, 0.5) for _ in range(args.repeats)]
        print(f"{len(x):,} rows: {min(ns):.1f} ns per step, best of {len(ns)} "
              f"({', '.join(f'{v:.0f}' for v in ns)}); load average {os.getloadavg()[0]:.2f}")
        if args.callgrind:
            print(f"callgrind: {instructions(exe, x, tmp):.0f} instructions per step")


if __name__ == "__main__":
    main()
