"""Compile an exported header with a small driver and run it over signals: what the tests and the
benchmark (benchmarks/run.py) use to compare the C code with ``fricli predict`` and to time its
step function. Not part of the installed package.

The driver (C99 and C++) reads rows of doubles (PREFIX_N_SIGNALS per row, in the step
function's order, native byte order) and writes one double per row, or times the step function.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile

import numpy as np

C_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2")
CXX_FLAGS = ("-x", "c++", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2")

DRIVER = r"""#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "HEADER"

/* driver IN OUT: predictions for the rows of IN into OUT; driver IN OUT --parts: friction and model
   error per row; driver IN --bench SECONDS: ns per sample */
int main(int argc, char **argv) {
    const int k = PREFIX_N_SIGNALS;
    FILE *f;
    long size;
    size_t n, i;
    double *x, *y, acc = 0.0;
    PREFIX_state s;
    if (argc != 3 && argc != 4) return 2;
    f = fopen(argv[1], "rb");
    if (!f || fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) return 3;
    n = (size_t)size / (sizeof(double) * (size_t)k);
    x = (double *)malloc(sizeof(double) * (n * (size_t)k + 1));
    y = (double *)malloc(sizeof(double) * (n + 1));
    if (!x || !y || fread(x, sizeof(double), n * (size_t)k, f) != n * (size_t)k) return 3;
    fclose(f);
    if (argc == 4 && strcmp(argv[2], "--bench") == 0) {
        const double seconds = atof(argv[3]);
        struct timespec t0, t1;
        double elapsed = 0.0;
        long passes = 0;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t0);
        while (elapsed < seconds || passes == 0) {
            PREFIX_init(&s);
            for (i = 0; i < n; ++i) acc += PREFIX_step_array(&s, x + i * (size_t)k);
            ++passes;
            clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t1);
            elapsed = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
        }
        printf("%.6g %.17g\n", 1e9 * elapsed / ((double)passes * (double)n), acc);
        return 0;
    }
    if (argc == 4 && strcmp(argv[3], "--parts") == 0) {   /* friction and model error per row */
        double *pe = (double *)malloc(sizeof(double) * (2 * n + 1));
        if (!pe) return 3;
        PREFIX_init(&s);
        for (i = 0; i < n; ++i) pe[2 * i] = PREFIX_step_parts_array(&s, x + i * (size_t)k, pe + 2 * i + 1);
        f = fopen(argv[2], "wb");
        if (!f || fwrite(pe, sizeof(double), 2 * n, f) != 2 * n || fclose(f) != 0) return 4;
        free(pe);
        free(x);
        free(y);
        return 0;
    }
    PREFIX_init(&s);
    for (i = 0; i < n; ++i) y[i] = PREFIX_step_array(&s, x + i * (size_t)k);
    f = fopen(argv[2], "wb");
    if (!f || fwrite(y, sizeof(double), n, f) != n || fclose(f) != 0) return 4;
    free(x);
    free(y);
    return 0;
}
"""


def compiler(cxx: bool = False) -> str | None:
    """The system C (or C++) compiler ($CC / $CXX, else cc / c++), or None when there is none."""
    name = os.environ.get("CXX" if cxx else "CC") or ("c++" if cxx else "cc")
    return shutil.which(name)


def build(header_path: str, prefix: str, exe: str, *, cxx: bool = False, flags: tuple[str, ...] = ()) -> str:
    """Compile the driver for ``header_path`` into ``exe`` with warnings as errors (and ``flags``
    after the standard ones); returns the compiler's messages. Raises RuntimeError when the
    compile fails."""
    cc = compiler(cxx)
    if cc is None:
        raise RuntimeError("no C compiler")
    src = os.path.join(os.path.dirname(os.path.abspath(exe)), f"{os.path.basename(exe)}_driver.c")
    with open(src, "w") as fh:
        fh.write(DRIVER.replace("HEADER", os.path.abspath(header_path)).replace("PREFIX", prefix))
    cmd = [cc, *(CXX_FLAGS if cxx else C_FLAGS), *flags, src, "-o", exe, "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    return proc.stderr


def _write_rows(x: np.ndarray, folder: str) -> str:
    path = os.path.join(folder, "signals.bin")
    np.ascontiguousarray(x, dtype=np.float64).tofile(path)
    return path


def run(exe: str, x: np.ndarray) -> np.ndarray:
    """Step the exported model over the rows of ``x`` (n, N_SIGNALS); returns tau_f (n,)."""
    with tempfile.TemporaryDirectory() as tmp:
        src = _write_rows(x, tmp)
        out = os.path.join(tmp, "out.bin")
        subprocess.run([exe, src, out], check=True)
        return np.fromfile(out, dtype=np.float64)


def run_parts(exe: str, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``PREFIX_step_parts`` over the rows of ``x``: (friction (n,), model error (n,))."""
    with tempfile.TemporaryDirectory() as tmp:
        src = _write_rows(x, tmp)
        out = os.path.join(tmp, "out.bin")
        subprocess.run([exe, src, out, "--parts"], check=True)
        pe = np.fromfile(out, dtype=np.float64).reshape(-1, 2)
        return pe[:, 0], pe[:, 1]


def time_step(exe: str, x: np.ndarray, seconds: float = 0.2) -> float:
    """Nanoseconds of CPU time per call of the step function over the rows of ``x`` (repeated for
    ``seconds`` of CPU time: other work on the machine does not count, but still slows it)."""
    with tempfile.TemporaryDirectory() as tmp:
        src = _write_rows(x, tmp)
        out = subprocess.run([exe, src, "--bench", str(seconds)], check=True, capture_output=True, text=True)
        return float(out.stdout.split()[0])


def signal_matrix(signals: dict[str, np.ndarray], names: list[str]) -> np.ndarray:
    """Rows (n, len(names)) of the signals a step function takes; a torque the log lacks is 0
    (as the models read it)."""
    n = len(signals["t"])
    cols = [signals[name] if name in signals else np.zeros(n) for name in names]
    return np.column_stack(cols) if cols else np.zeros((n, 0))
