"""Time ``fricli import`` on a synthetic UR10e-shaped recording (31 columns, 100 Hz).

    python benchmarks/robot_import.py                 # 100,000 rows x 6 joints
    python benchmarks/robot_import.py --rows 20000 --bad 10

Prints the median over --repeats runs of: parsing the CSV (clean file: pyarrow; with --bad
malformed rows: the search for bad rows), the rigid-body terms with Pinocchio for all samples
(when the UR10e URDF is at ../shared/data/ur10e/ and pinocchio imports), the whole import in
the library, and the whole command (start-up included), each with and without --urdf.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from run import median_time  # noqa: E402  (benchmarks/run.py, beside this script)

URDF = ROOT.parent / "shared" / "data" / "ur10e" / "ur10e.urdf"
MAPPING = ROOT / "docs" / "ur10e-mapping.toml"


def recording(rows: int, bad: int, rng: np.random.Generator) -> bytes:
    """Sums of harmonics for q (rad), their derivative for qd, noise for the currents."""
    t = 838.0 + np.arange(rows) * 0.01
    freq = rng.uniform(0.05, 0.5, (6, 5))
    amp = rng.uniform(0.05, 0.3, (6, 5))
    phase = 2 * np.pi * freq[None] * t[:, None, None]
    q = (amp * np.sin(phase)).sum(axis=2)
    qd = (amp * 2 * np.pi * freq * np.cos(phase)).sum(axis=2)
    cur = rng.normal(0, 2, (rows, 12))
    data = np.column_stack([t, q, qd, cur, rng.normal(0, 20, (rows, 6))])
    lines = [",".join(f"{v:.4f}" for v in row) for row in data]
    for k in rng.choice(rows, size=bad, replace=False):
        lines[k] = lines[k][: len(lines[k]) // 2]
    return ("\n".join(lines) + "\n").encode()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=100_000)
    ap.add_argument("--bad", type=int, default=0, help="malformed rows to put in the file")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    from fricli.robot.importing import import_recording
    from fricli.robot.mapping import load_mapping
    from fricli.robot.recording import read_recording

    data = recording(args.rows, args.bad, np.random.default_rng(0))
    mapping = load_mapping(str(MAPPING))
    out = {"rows": args.rows, "joints": 6, "bad_rows": args.bad, "csv_megabytes": round(len(data) / 1e6, 1),
           "parse_s": median_time(lambda: read_recording(data, mapping, "bench.csv"), args.repeats)}
    out["import_library_s"] = median_time(lambda: import_recording(data, mapping, "bench.csv"), args.repeats)
    model = None
    try:
        from fricli.robot.dynamics import load_model

        if URDF.exists():
            model = load_model(str(URDF), mapping)
    except Exception as exc:  # no pinocchio: the URDF rows are skipped
        out["note"] = f"no URDF timing: {exc}"
    if model is not None:
        rng = np.random.default_rng(1)
        q, qd, qdd = (rng.normal(size=(args.rows, 6)) for _ in range(3))
        out["robot_terms_s"] = median_time(lambda: model.terms(q, qd, qdd, np.ones(6)), args.repeats)
        out["import_library_with_urdf_s"] = median_time(
            lambda: import_recording(data, mapping, "bench.csv", model=model), args.repeats)
    with tempfile.TemporaryDirectory() as tmp:
        csv = os.path.join(tmp, "bench.csv")
        with open(csv, "wb") as fh:
            fh.write(data)
        cmd = [sys.executable, "-m", "fricli", "import", csv, "--mapping", str(MAPPING), "-o",
               os.path.join(tmp, "out.parquet"), "-q"]
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        out["command_s"] = median_time(lambda: subprocess.run(cmd, check=True, env=env), args.repeats)
        if model is not None:
            out["command_with_urdf_s"] = median_time(
                lambda: subprocess.run(cmd + ["--urdf", str(URDF)], check=True, env=env), args.repeats)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in out.items()}, indent=2))


if __name__ == "__main__":
    main()
