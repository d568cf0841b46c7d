"""Whether two processes get two cores' worth of work done on this host: each measurement alone,
then two copies at once.

    python benchmarks/cores.py

Two workloads: a C loop of independent AVX2 multiply-adds (throughput-bound, the vector units
the network's products and activations use) and a latency-bound scalar C loop; each prints its
seconds alone and the slower of two copies run at once. On two real cores both run as fast
twice over; on two hardware threads of one core (what a cloud host may sell as 2 vCPUs) the
vector loop slows down and the scalar one does not. fricli's trainings run two at a time
(`fricli.numerics.forked`), so on such a host they gain far less than twice.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import time

SOURCE = r"""
#include <immintrin.h>
#include <stdio.h>
int main(int argc, char **argv) {
    long i, n = 200000000L;
    if (argv[1][0] == 'v') {   /* 8 independent chains of AVX2 FMAs: the vector units' throughput */
        __m256 a[8], m = _mm256_set1_ps(0.9999999f), c = _mm256_set1_ps(1e-7f);
        float out[8], s = 0.0f;
        int k;
        for (k = 0; k < 8; ++k) a[k] = _mm256_set1_ps(1.0f + k * 1e-3f);
        for (i = 0; i < n; ++i)
            for (k = 0; k < 8; ++k) a[k] = _mm256_fmadd_ps(a[k], m, c);
        for (k = 0; k < 8; ++k) { _mm256_storeu_ps(out, a[k]); s += out[0]; }
        printf("%f\n", s);
    } else {                   /* one chain of dependent scalar operations: latency, not throughput */
        volatile double x = 1.0;
        for (i = 0; i < 2 * n; ++i) x = x * 1.0000001 + 1e-9;
        printf("%f\n", x);
    }
    (void)argc;
    return 0;
}
"""


def timed(exe: str, mode: str, copies: int) -> float:
    """Wall seconds of the slowest of ``copies`` runs of ``exe mode`` started at once."""
    start = time.perf_counter()
    procs = [subprocess.Popen([exe, mode], stdout=subprocess.DEVNULL) for _ in range(copies)]
    ends = []
    for p in procs:
        p.wait()
        ends.append(time.perf_counter() - start)
    return max(ends)


def measure() -> dict[str, tuple[float, float]]:
    """{"vector": (alone, two), "scalar": (alone, two)}: wall seconds of each loop alone and the
    slower of two copies at once (gcc compiles the loops)."""
    with tempfile.TemporaryDirectory() as tmp:
        src, exe = os.path.join(tmp, "loop.c"), os.path.join(tmp, "loop")
        with open(src, "w") as fh:
            fh.write(SOURCE)
        subprocess.run(["gcc", "-O2", "-mavx2", "-mfma", "-o", exe, src], check=True)
        return {what: (timed(exe, mode, 1), timed(exe, mode, 2)) for what, mode in (("vector", "v"), ("scalar", "s"))}


def main() -> None:
    print(f"{os.cpu_count()} CPUs; seconds alone / two copies at once (the slower)")
    for what, (alone, two) in measure().items():
        label = "AVX2 multiply-adds (throughput)" if what == "vector" else "scalar chain (latency)"
        print(f"{label}: {alone:.2f} / {two:.2f} s ({two / alone:.2f}x)")


if __name__ == "__main__":
    main()
