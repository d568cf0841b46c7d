"""train-base on the Franka joint friction files (joint 2 by default): fitted on the first 60 % of each file's time,
scored on the last 40 % (RMS of the published friction target minus the prediction, every row).

    python benchmarks/franka_split.py                          # the default against --ensemble 5
    python benchmarks/franka_split.py --option=--bristles=off  # add options to every train-base
    python benchmarks/franka_split.py --memory                 # --memory off against --memory auto

For each file (slow, middle, high) the default ``fricli train-base`` (one network) and
``--ensemble 5`` (the mean of five) run one after the other on the same log, with their whole
command's wall time; with --memory, ``--memory off`` (the network alone) and ``--memory auto``
(Maxwell-slip elements where held-out blocks choose them) instead. The last 40 % is predicted
with the state (pre-sliding deflection, slip elements) that the first 60 % leaves. The files hold the joint's
friction torque as their authors extracted it (no gravity or dynamics left: --no-gravity
--no-dynamics). Data: ../shared/data/franka (see ../shared/data/README.md), or --data; the files
``jointN_SPEED.csv`` of joint N = 2, or ``--joint N``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_DATA = os.path.join(ROOT, "..", "shared", "data", "franka")
FILES = ("slow", "middle", "high")
FIT_SHARE = 0.6
UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "tau_m": "Nm"}


def split(csv: str, folder: str, name: str, joint: int = 2) -> tuple[str, str]:
    """The file's first FIT_SHARE of time and the rest, as fricli logs (tau_m the friction)."""
    d = np.genfromtxt(csv, delimiter=",", names=True)
    t = d["time"]
    cut = t[0] + FIT_SHARE * (t[-1] - t[0])
    paths = []
    for part, rows in (("fit", t <= cut), ("test", t > cut)):
        cols = {"t": t[rows], "q": d[f"q{joint}"][rows], "qd": d[f"dq{joint}"][rows],
                "tau_m": d[f"q{joint}_tau_J_compensate"][rows]}
        schema = pa.schema([pa.field(k, pa.float64(), metadata={"unit": UNITS[k]}) for k in cols])
        path = os.path.join(folder, f"{name}_{part}.parquet")
        pq.write_table(pa.table([pa.array(v) for v in cols.values()], schema=schema), path)
        paths.append(path)
    return paths[0], paths[1]


def fricli(*args: str) -> tuple[float, str]:
    """Wall time [s] of one fricli command and its stdout."""
    print("$ fricli " + " ".join(args), file=sys.stderr)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "fricli", *args], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(proc.stderr)
    return time.perf_counter() - start, proc.stdout


def rms_on(model_path: str, fit: str, test: str) -> float:
    """RMS [Nm] on ``test`` of the model, its state carried over from a prediction of ``fit``."""
    from fricli import models
    from fricli.core import logs

    def read(path):
        return logs.load_log(path, zero=("tau_g", "tau_dyn"), warn=lambda *a: None)

    log = read(test)
    model, _ = models.load(model_path)
    _, state = model.predict(read(fit).signals)
    pred = model.predict(log.signals, state)[0]
    return float(np.sqrt(np.mean((logs.friction_target(log.signals) - pred) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--joint", type=int, default=2, help="the joint whose files (jointN_SPEED.csv) to read")
    ap.add_argument("--option", action="append", default=[], help="add to every train-base (repeatable)")
    ap.add_argument("--memory", action="store_true", help="--memory off against --memory auto")
    ap.add_argument("--json", default=None, help="also write the figures to this file")
    args = ap.parse_args()
    if not os.path.exists(os.path.join(args.data, f"joint{args.joint}_slow.csv")):
        raise SystemExit(f"no Franka data at {args.data}")
    flags = ["--no-gravity", "--no-dynamics", "-q"]
    variants = ({"--memory off": ["--memory", "off"], "--memory auto": ["--memory", "auto"]} if args.memory else
                {"default (one network)": [], "--ensemble 5": ["--ensemble", "5"]})
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in FILES:
            fit, test = split(os.path.join(args.data, f"joint{args.joint}_{name}.csv"), tmp, name, args.joint)
            row = {}
            for label, extra in variants.items():
                path = os.path.join(tmp, "nn.npz")
                wall, stdout = fricli("train-base", fit, "-o", path, "--json", *flags, *extra, *args.option)
                made = json.loads(stdout)
                row[label] = {"rmse": rms_on(path, fit, test), "wall_s": wall, "seconds": made["seconds"],
                              "kind": made["kind"] if "memory" not in made else
                              ("network + slip elements" if made["memory"]["chosen"] else "network"),
                              "memory": made.get("memory")}
            out[name] = row
    labels = list(next(iter(out.values())))
    first, second = labels
    print("| file | " + " | ".join(f"{k}: RMS [Nm]" for k in labels) + f" | ratio | train-base wall [s]: "
          f"{first} / {second} |" + (" --memory auto chose |" if args.memory else ""))
    print("|---" * (len(labels) + 3 + args.memory) + "|")
    for name, row in out.items():
        one, two = row[first], row[second]
        print(f"| {name} | " + " | ".join(f"{row[k]['rmse']:.4f}" for k in labels)
              + f" | {one['rmse'] / two['rmse']:.3f} | {one['wall_s']:.1f} / {two['wall_s']:.1f} |"
              + (f" {two['kind']} |" if args.memory else ""))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
