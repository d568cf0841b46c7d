"""The stop operator of Maxwell-slip elements (``fricli.numerics.physics.stop``) against stepping
row by row in plain floats, on simulated positions, per element limit.

    python benchmarks/stop_operator.py            # 262,144 rows (one record batch of predict)

Positions: a slow sine of 0.5 rad with a random walk of 2 mrad a row ("noisy": an element of a
small limit slips at almost every row) and a sine of 0.3 rad under a slower one with a walk of
0.01 mrad ("smooth"). Prints ns a row of each and checks the two give the same bits."""

from __future__ import annotations

import argparse
import time

import numpy as np

from fricli.numerics import physics


def per_row_ns(f, rows: int, repeats: int = 3) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - start)
    return best / rows * 1e9


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=262_144)
    args = ap.parse_args(argv)
    n, rng = args.rows, np.random.default_rng(1)
    k = np.arange(n)
    positions = {"noisy": np.cumsum(rng.normal(0.0, 0.002, n)) + 0.5 * np.sin(0.005 * k),
                 "smooth": np.cumsum(rng.normal(0.0, 1e-5, n)) + 0.3 * np.sin(0.002 * k) * np.sin(1e-4 * k)}
    for name, q in positions.items():
        dq = np.diff(q, prepend=q[0])
        for d in (0.004, 0.05, 0.5, 10.0):
            rows = physics._stop_steps(dq, d, 0.0)
            same = np.array_equal(physics.stop(q, d, 0.0, q[0])[:, 0].view(np.int64), np.array(rows).view(np.int64))
            ref = per_row_ns(lambda: physics._stop_steps(dq, d, 0.0), n)
            new = per_row_ns(lambda: physics.stop(q, d, 0.0, q[0]), n)
            print(f"{name:6s} d = {d:<6g}: row by row {ref:6.1f} ns a row, in blocks {new:6.1f} ns a row"
                  f" ({ref / new:.1f}x), same bits: {same}")


if __name__ == "__main__":
    main()
