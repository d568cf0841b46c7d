"""Compile an arm header of ``fricli export --observer`` with a small driver and run it over a
replayed log (``fricli.robot.replay.Arm``): what the tests and studies/ur10e/run_contact_detection.py use to
compare the C code with ``fricli replay`` and to time its step. Not part of the installed package.

Input rows (native doubles): t, each joint's friction signals in its step function's order, then
tau_m, qd, p, w per joint. Output rows: tau_f, tau_ext, contact per joint.
"""

from __future__ import annotations

import os
import subprocess

import numpy as np

from fricli import models
from fricli.export import c

C_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2")
CXX_FLAGS = ("-x", "c++", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2")

DRIVER = r"""#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "HEADER"

/* driver IN OUT [--bench SECONDS] */
int main(int argc, char **argv) {
    static const int widths[J] = {WIDTHS};
    const double *xs[J];
    int per = 1, j, c[J];
    long size;
    size_t n, i;
    double *in, *out;
    FILE *f;
    PREFIX_arm_state s;
    for (j = 0; j < J; ++j) per += widths[j];
    per += 4 * J;
    f = fopen(argv[1], "rb");
    if (!f || fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) return 3;
    n = (size_t)size / (sizeof(double) * (size_t)per);
    in = (double *)malloc((size_t)size + 1);
    out = (double *)malloc(sizeof(double) * 3 * J * (n + 1));
    if (!in || !out || fread(in, sizeof(double), n * (size_t)per, f) != n * (size_t)per) return 4;
    fclose(f);
    if (argc == 4) {   /* --bench SECONDS: ns per step over the rows, repeated */
        double seconds = atof(argv[3]), elapsed = 0.0, acc = 0.0;
        long steps = 0;
        struct timespec a, b;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
        while (elapsed < seconds) {
            PREFIX_arm_init(&s);
            for (i = 0; i < n; ++i) {
                const double *row = in + i * (size_t)per, *rest;
                int off = 1;
                for (j = 0; j < J; ++j) { xs[j] = row + off; off += widths[j]; }
                rest = row + off;
                PREFIX_arm_step(&s, row[0], xs, rest, rest + J, rest + 2 * J, rest + 3 * J, out, out + J, c);
                acc += out[J];
            }
            steps += (long)n;
            clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
            elapsed = (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec);
        }
        printf("%.3f %g\n", 1e9 * elapsed / (double)steps, acc);
        return 0;
    }
    PREFIX_arm_init(&s);
    for (i = 0; i < n; ++i) {
        const double *row = in + i * (size_t)per, *rest;
        double *o = out + i * 3 * J;
        int off = 1;
        for (j = 0; j < J; ++j) { xs[j] = row + off; off += widths[j]; }
        rest = row + off;
        PREFIX_arm_step(&s, row[0], xs, rest, rest + J, rest + 2 * J, rest + 3 * J, o, o + J, c);
        for (j = 0; j < J; ++j) o[2 * J + j] = (double)c[j];
    }
    f = fopen(argv[2], "wb");
    if (!f || fwrite(out, sizeof(double), 3 * J * n, f) != 3 * J * n) return 5;
    fclose(f);
    return 0;
}
"""


def rows(arm, model_paths: list[str]) -> np.ndarray:
    """The driver's input rows for ``arm``; ``model_paths``: each joint's model file, in the
    header's joint order, which must be the arm's."""
    cols = [arm.t[:, None]]
    for j, path in enumerate(model_paths):
        model, _ = models.load(path)
        sig = arm.signals[j]
        cols.append(np.column_stack([sig[s] for s in c.signals_of(model)]))
    cols += [arm.tau_m, arm.qd, arm.p, arm.w]
    return np.ascontiguousarray(np.hstack(cols), dtype=np.float64)


def build(header_path: str, prefix: str, model_paths: list[str], folder: str, cxx: bool = False,
          compiler: str | None = None) -> str:
    """Compile the driver for the header; returns the program's path."""
    widths = [len(c.signals_of(models.load(p)[0])) for p in model_paths]
    src = (DRIVER.replace("HEADER", os.path.basename(header_path)).replace("PREFIX", prefix)
           .replace("WIDTHS", ", ".join(map(str, widths))))
    src = f"#define J {len(widths)}\n" + src
    path = os.path.join(folder, f"driver{'_cpp' if cxx else ''}.c")
    with open(path, "w") as fh:
        fh.write(src)
    exe = path[:-2]
    flags = CXX_FLAGS if cxx else C_FLAGS
    cc = compiler or ("g++" if cxx else "cc")
    subprocess.run([cc, *flags, "-I", os.path.dirname(os.path.abspath(header_path)), path, "-o", exe, "-lm"],
                   check=True, capture_output=True, text=True)
    return exe


def run(exe: str, data: np.ndarray, joints: int, folder: str) -> np.ndarray:
    """(n, 3 J): tau_f, tau_ext, contact per row."""
    src, dst = os.path.join(folder, "in.bin"), os.path.join(folder, "out.bin")
    data.tofile(src)
    subprocess.run([exe, src, dst], check=True)
    return np.fromfile(dst).reshape(-1, 3 * joints)


def bench(exe: str, data: np.ndarray, folder: str, seconds: float = 1.0) -> float:
    """ns per arm step (CPU time of the driver)."""
    src = os.path.join(folder, "in.bin")
    data.tofile(src)
    done = subprocess.run([exe, src, os.devnull, str(seconds)], check=True, capture_output=True, text=True)
    return float(done.stdout.split()[0])
