"""The spread of one file-to-file prediction ratio: alternating pairs of plain pyarrow and fricli.

    python benchmarks/predict_pairs.py                          # dissipative, predict, 9 pairs
    python benchmarks/predict_pairs.py --kind mlp --command estimate-ext --pairs 5

``benchmarks/run.py`` reports each kind's ratio as the median of 3 such pairs; on a shared
machine single pairs move a lot, and this script shows by how much. Each pair times plain
pyarrow's read + append-one-column + write of a 10-million-row log, then the fricli command
on the same file (whole command, start-up included). Prints every pair and their median,
minimum and maximum.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import run as bench  # noqa: E402

from fricli.core import logs  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", choices=bench.KINDS, default="dissipative")
    ap.add_argument("--command", choices=("predict", "estimate-ext"), default="predict")
    ap.add_argument("--pairs", type=int, default=9)
    ap.add_argument("--rows", type=int, default=10_000_000)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        paths = bench.build_models(tmp, logs.load_log(bench.BASE_LOG), quick=False)
        ext = logs.load_log(bench.EXT_LOG)
        src, dst = os.path.join(tmp, "big.parquet"), os.path.join(tmp, "out.parquet")
        bench.write_log(bench.tiled_signals(ext, args.rows), ext.units, src)
        ratios = []
        for i in range(args.pairs):
            plain = bench.plain_pyarrow_s(src, dst)
            secs = bench.run_cli([args.command, paths[args.kind], src, "-o", dst], 1)
            ratios.append(plain / secs)
            print(f"pair {i + 1}: plain pyarrow {plain:.2f} s, {args.kind} {args.command} {secs:.2f} s, "
                  f"ratio {plain / secs:.3f}", flush=True)
    print(f"{args.kind} {args.command} / plain pyarrow over {args.pairs} pairs, {args.rows:,} rows: median "
          f"{statistics.median(ratios):.3f}, min {min(ratios):.3f}, max {max(ratios):.3f}")


if __name__ == "__main__":
    main()
