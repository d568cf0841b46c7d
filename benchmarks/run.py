#!/usr/bin/env python
"""fricli benchmarks: training, identification, simulation, prediction and diagnosis, in one run.

    python benchmarks/run.py                   full sizes (several minutes on 2 cores)
    python benchmarks/run.py --quick           tiny sizes, about 15 s (what the tests run)
    python benchmarks/run.py --json            the figures as JSON on stdout
    python benchmarks/run.py --only identify   only identify on 100,000 rows (library and command)
    python benchmarks/run.py --plot docs/studies/img/performance-scaling.png
                                               also measure how cost grows with log length and
                                               network size, and plot it

Every figure is the median over ``--repeats`` runs. PyTorch is measured on the same data, the
same network (2-30-30-1, ELU), the same optimiser (Adam, lr 0.01) and the same thread count
when it can be imported; it is not a dependency of fricli, and its rows are skipped with a note
otherwise. Whole commands are run as ``python -m fricli ...`` in a subprocess (file in, file
out, including start-up); library figures time the computation on data already in memory.
The table goes to stderr and, without --json, to stdout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for _path in (ROOT, HERE):
    if _path not in sys.path:
        sys.path.insert(0, _path)

import numpy as np  # noqa: E402

import cores  # noqa: E402
import plain_pyarrow  # noqa: E402

from fricli.core import logs  # noqa: E402
from fricli.fitting import heldout, learning
from fricli.numerics import forked, physics  # noqa: E402
from fricli.models.lugre import LuGreModel  # noqa: E402
from fricli.numerics.nn import activations as acts  # noqa: E402
from fricli.numerics.threads import blas_threads, single_threaded  # noqa: E402
from fricli.numerics.nn.network import Network  # noqa: E402
from fricli.numerics.nn.training import Standardizer, Trainer  # noqa: E402

SAMPLE = os.path.join(ROOT, "sample_data")
BASE_LOG = os.path.join(SAMPLE, "joint2_base.parquet")
ADAPT_LOG = os.path.join(SAMPLE, "joint2_adapt.parquet")
EXT_LOG = os.path.join(SAMPLE, "joint2_extended_asym.parquet")
KINDS = ("lugre", "dissipative", "mlp", "selmic", "nnacm", "residual", "augmented")

FULL = {"steps": 2000, "mini_steps": 3000, "train_base_steps": None, "identify_rows": 100_000,
        "predict_rows": 10_000_000, "diagnose_rows": 100_000, "lugre_rows": 100_000, "loop_rows": 100_000,
        "repeats": 3, "scale_n": (1_000, 2_000, 5_000, 10_000, 20_000, 50_000, 100_000),
        "scale_rows": (10_000, 100_000, 1_000_000, 10_000_000), "scale_width": (10, 20, 30, 50, 100, 200)}
QUICK = {"steps": 50, "mini_steps": 50, "train_base_steps": 100, "identify_rows": None,
         "predict_rows": 20_000, "diagnose_rows": None, "lugre_rows": 20_000, "loop_rows": 2_000,
         "repeats": 1, "scale_n": (500, 2_000), "scale_rows": (1_000, 20_000), "scale_width": (10, 30)}


# ---------------------------------------------------------------------------- helpers


def median_time(fn, repeats: int) -> float:
    """Median wall time [s] of ``fn()`` over ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def run_cli(args: list[str], repeats: int, quiet: bool = True) -> float:
    """Median wall time [s] of ``python -m fricli ARGS`` (quiet), start-up included."""
    return run_cli_times(args, repeats, quiet)[0]


def run_cli_times(args: list[str], repeats: int, quiet: bool = True) -> tuple[float, float]:
    """Median wall time and median CPU time (user + system) [s] of ``python -m fricli ARGS``
    (quiet), start-up included. The CPU time moves less with the host's load than the wall time."""
    cmd = [sys.executable, "-m", "fricli", *args, *(["--quiet"] if quiet else [])]
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    walls, cpus = [], []
    for _ in range(repeats):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
        walls.append(time.perf_counter() - start)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed ({proc.returncode}): {proc.stderr.strip()}")
    return statistics.median(walls), statistics.median(cpus)


def say(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------- data


def training_arrays(log: logs.Log, seed: int = 0):
    """Standardised float32 inputs (2, n) and targets (1, n) of the rows train-base trains on."""
    sig = log.signals
    target = logs.friction_target(sig)
    rows = _train_rows(log, seed)
    if rows is None:   # the selection's interface changed: as many rows, drawn at random
        rows = np.random.default_rng(seed).choice(len(target), size=2000, replace=False)
    x = np.stack([sig["tau_g"][rows], sig["qd"][rows]])
    y = target[rows][None, :]
    return Standardizer().fit(x).transform(x), Standardizer().fit(y).transform(y)


def _train_rows(log: logs.Log, seed: int):
    try:
        from fricli.fitting import training_data
        sig = log.signals
        speed = np.abs(sig["qd"])
        moving = speed > training_data.LOW * float(speed.max())
        sel = training_data.select(sig["qd"], val_fraction=0.2, max_samples=learning.DEFAULT_MAX_SAMPLES,
                                   balance=True, rng=np.random.default_rng(seed), keep=moving)
        return sel.train
    except Exception:
        return None


def resample(x: np.ndarray, t: np.ndarray, n: int, seed: int = 0):
    """n columns drawn from (x, t) (with replacement when n exceeds their count), the inputs moved
    by a random 1e-4 (of their unit scale) so that no two columns repeat: the trainer computes
    repeated inputs once, and these figures are the cost of n distinct samples."""
    rng = np.random.default_rng(seed)
    idx = rng.choice(x.shape[1], size=n, replace=n > x.shape[1])
    xs = x[:, idx] + (1e-4 * rng.standard_normal((x.shape[0], n))).astype(x.dtype)
    return np.ascontiguousarray(xs), np.ascontiguousarray(t[:, idx])


def tiled_signals(log: logs.Log, n: int) -> dict[str, np.ndarray]:
    """The log's signals repeated to n rows, with t continuing at the log's sample interval."""
    sig = log.signals
    dt = float(np.median(np.diff(sig["t"])))
    out = {k: np.resize(np.asarray(v, dtype=np.float64), n) for k, v in sig.items() if k != "t"}
    out["t"] = np.arange(n) * dt
    return out


def write_log(sig: dict[str, np.ndarray], units: dict[str, str], path: str) -> None:
    cols = {k: sig[k] for k in ("t", "q", "qd", "qdd", "tau_m", "tau_g", "tau_dyn", "tau_ext", "temp") if k in sig}
    table = logs.table_from_arrays(cols, {k: units[k] for k in cols if k in units})
    logs.write_table(table, path)


def simulate(path: str, args: list[str]) -> None:
    cmd = [sys.executable, "-m", "fricli", "simulate", *args, "-o", path, "--quiet"]
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    subprocess.run(cmd, cwd=ROOT, env=env, check=True, capture_output=True)


# ---------------------------------------------------------------------------- training


def mlp(width: int = 30) -> Network:
    return Network(2, [(width, acts.ELU()), (width, acts.ELU())]).init(np.random.default_rng(0))


def fricli_steps_per_s(x, t, steps: int, batch: int, repeats: int, width: int = 30) -> float:
    """Adam steps per second of ``Trainer`` (full batch for batch 0), loss record only at the end."""
    def once():
        Trainer(steps=steps, batch_size=batch, eval_every=steps).fit(mlp(width), x, t,
                                                                     rng=np.random.default_rng(0))
    return steps / median_time(once, repeats)


def torch_steps_per_s(x, t, steps: int, batch: int, repeats: int, threads: int, width: int = 30) -> float:
    """The same network, loss and optimiser in PyTorch (float32), in a separate process: PyTorch's
    OpenMP threads keep spinning after its work and would slow down what is measured next."""
    with tempfile.TemporaryDirectory() as tmp:
        np.save(os.path.join(tmp, "x.npy"), x)
        np.save(os.path.join(tmp, "t.npy"), t)
        cmd = [sys.executable, os.path.abspath(__file__), "--torch-worker", tmp, str(steps), str(batch), str(repeats),
               str(threads), str(width)]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"the PyTorch measurement failed: {proc.stderr.strip()}")
        return float(proc.stdout.split()[-1])


def torch_steps(steps: int) -> int:
    """Fewer steps for PyTorch (a rate needs no more), at least 5."""
    return max(5, steps // 4)


def torch_worker(folder: str, steps: int, batch: int, repeats: int, threads: int, width: int,
                 whole: int = 0, arch: str = "mlp") -> None:
    """Print the PyTorch steps per second (median over repeats) of the usual training loop.

    whole = k > 0: instead, print the wall time [s] of one whole training as train-base runs it:
    Adam with a cosine learning rate from 0.01 to 0 over ``steps`` full-batch steps, the
    validation loss (xv.npy, tv.npy) every k steps and a copy of the best weights; ``arch`` mlp
    (inputs tau_g, qd) or dissipative (rows u, sign qd, c, g: y = c (softplus(r0) + softplus(b1) g),
    r0 the network's output, b1 one more parameter, as fricli.numerics.nn.heads)."""
    import torch

    torch.set_num_threads(threads)
    X = torch.from_numpy(np.ascontiguousarray(np.load(os.path.join(folder, "x.npy")).T))
    T = torch.from_numpy(np.ascontiguousarray(np.load(os.path.join(folder, "t.npy")).T))
    n = X.shape[0]
    if whole:
        XV = torch.from_numpy(np.ascontiguousarray(np.load(os.path.join(folder, "xv.npy")).T))
        TV = torch.from_numpy(np.ascontiguousarray(np.load(os.path.join(folder, "tv.npy")).T))

        def network():
            nn = torch.nn
            body = nn.Sequential(nn.Linear(2, width), nn.ELU(), nn.Linear(width, width), nn.ELU(), nn.Linear(width, 1))
            if arch == "mlp":
                return body

            class Dissipative(nn.Module):
                def __init__(self):
                    super().__init__()
                    self.body, self.b1 = body, nn.Parameter(torch.zeros(1))

                def forward(self, x):
                    r0 = self.body(x[:, :2])
                    sp = nn.functional.softplus
                    return x[:, 2:3] * (sp(r0) + sp(self.b1) * x[:, 3:4])
            return Dissipative()

        def train():
            torch.manual_seed(0)
            nn = torch.nn
            net = network()
            opt = torch.optim.Adam(net.parameters(), lr=0.01)
            loss_fn = nn.MSELoss()
            best, best_state = math.inf, None
            for step in range(steps):
                for group in opt.param_groups:
                    group["lr"] = 0.5 * 0.01 * (1.0 + math.cos(math.pi * step / steps))
                opt.zero_grad(set_to_none=True)
                loss = loss_fn(net(X), T)
                loss.backward()
                opt.step()
                if (step + 1) % whole == 0:
                    with torch.no_grad():
                        val = float(loss_fn(net(XV), TV))
                    if val < best:
                        best, best_state = val, [p.detach().clone() for p in net.parameters()]
            return best_state

        train_short = steps
        steps = min(steps, 20)
        train()                 # warm-up
        steps = train_short
        start = time.perf_counter()
        train()
        print(time.perf_counter() - start)
        return

    def once(steps=steps):
        torch.manual_seed(0)
        nn = torch.nn
        net = nn.Sequential(nn.Linear(2, width), nn.ELU(), nn.Linear(width, width), nn.ELU(), nn.Linear(width, 1))
        opt = torch.optim.Adam(net.parameters(), lr=0.01)
        loss_fn = nn.MSELoss()
        gen = torch.Generator().manual_seed(0)
        per_epoch = max(1, n // batch) if batch else 1
        perm = torch.randperm(n, generator=gen)
        for step in range(steps):
            if batch:
                j = step % per_epoch
                if j == 0 and step:
                    perm = torch.randperm(n, generator=gen)
                idx = perm[j * batch:(j + 1) * batch]
                xb, tb = X[idx], T[idx]
            else:
                xb, tb = X, T
            opt.zero_grad(set_to_none=True)
            loss = loss_fn(net(xb), tb)
            loss.backward()
            opt.step()
    once(min(steps, 20))   # warm-up: PyTorch's first steps set up its thread pool and kernels
    print(steps / median_time(once, repeats))


def torch_version() -> str | None:
    import importlib.metadata
    import importlib.util

    if importlib.util.find_spec("torch") is None:
        return None
    try:
        return importlib.metadata.version("torch")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def matmul_flops(net: Network, n: int) -> float:
    """Floating-point operations of the matrix products of one training step on n samples:
    forward W a, weight gradients g a^T and back-propagation W^T g (not into the inputs)."""
    fwd = sum(2.0 * r * c * n for r, c in net.shapes)
    back = sum(2.0 * r * (c - 1) * n for r, c in net.shapes[1:])
    return 2 * fwd + back


def gflops(dtype, size: int, threads: int | None, repeats: int) -> float:
    """GFLOP/s of a (size x size) @ (size x size) product, BLAS on ``threads`` (None: default)."""
    a = np.random.default_rng(0).standard_normal((size, size)).astype(dtype)
    b = a.copy()
    c = np.empty_like(a)
    np.matmul(a, b, out=c)

    def once():
        np.matmul(a, b, out=c)
    if threads == 1:
        with single_threaded():
            secs = median_time(once, repeats)
    else:
        secs = median_time(once, repeats)
    return 2.0 * size ** 3 / secs / 1e9


def layer_gflops(n: int, repeats: int) -> float:
    """GFLOP/s of the MLP's middle-layer product (30 x 31) @ (31 x n), float32, one BLAS thread."""
    rng = np.random.default_rng(0)
    w = rng.standard_normal((30, 31)).astype(np.float32)
    a = rng.standard_normal((31, n)).astype(np.float32)
    h = np.empty((30, n), dtype=np.float32)
    reps = max(1, int(2e8 / (2 * 30 * 31 * n)))

    def once():
        for _ in range(reps):
            np.matmul(w, a, out=h)
    with single_threaded():
        secs = median_time(once, repeats)
    return 2.0 * 30 * 31 * n * reps / secs / 1e9


# ---------------------------------------------------------------------------- LuGre


def lugre_loop(v, g, fv, sigma0, sigma1, dt, z0):
    """The per-sample Python loop a user would write for the same exact update (reference)."""
    out = np.empty(len(v))
    z = z0
    for k in range(len(v)):
        vk, gk = float(v[k]), float(g[k])
        rate = sigma0 * abs(vk) / gk
        a = math.exp(-min(rate * float(dt[k]), 700.0))
        zss = math.copysign(gk / sigma0, vk) if vk != 0 else 0.0
        z = zss + (z - zss) * a
        out[k] = sigma0 * z + sigma1 * (vk - rate * z) + fv * vk
    return out


# ---------------------------------------------------------------------------- whole jobs against references


def torch_whole_training_s(x, t, xv, tv, steps: int, every: int, threads: int, arch: str) -> float:
    """Wall time [s] of one whole train-base-like training in PyTorch (see ``torch_worker``)."""
    with tempfile.TemporaryDirectory() as tmp:
        for name, arr in (("x", x), ("t", t), ("xv", xv), ("tv", tv)):
            np.save(os.path.join(tmp, f"{name}.npy"), np.asarray(arr, dtype=np.float32))
        cmd = [sys.executable, os.path.abspath(__file__), "--torch-worker", tmp, str(steps), "0", "1", str(threads),
               "30", str(every), arch]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"the PyTorch measurement failed: {proc.stderr.strip()}")
        return float(proc.stdout.split()[-1])


def training_rows(log: logs.Log, arch: str, steps: int) -> tuple[np.ndarray, ...]:
    """(x, t, x_val, t_val): the arrays ``train-base --arch arch`` hands its trainer for ``log``
    (same row selection, scaling and inputs), caught at the trainer's door. On a log without
    velocity levels the default trains two networks at once (the model's on every row, a probe
    on the rest validated on the held-out blocks): x, t are the larger training set, x_val, t_val
    the held-out rows."""

    caught = {}
    lock = threading.Lock()

    class Caught(Exception):
        pass

    def catch(self, net, x, t, x_val=None, t_val=None, rng=None):
        with lock:
            if "x" not in caught or x.shape[1] > caught["x"].shape[1]:
                caught.update(x=net_input(x), t=t)
            if x_val is not None and "xv" not in caught:
                caught.update(xv=net_input(x_val), tv=t_val)
        raise Caught

    def net_input(x):
        return np.ascontiguousarray(x, dtype=np.float32)

    def one_by_one(tasks, stop=None):   # every trainer reaches the catch, whichever is caught first
        for task in tasks:
            try:
                task()
            except Caught:
                pass
        raise Caught

    original, apart, parallel = Trainer.fit, forked.AVAILABLE, heldout.run_parallel
    # both trainers in this process, where the catch is, one after the other
    Trainer.fit, forked.AVAILABLE, heldout.run_parallel = catch, False, one_by_one
    try:
        learning.train_base(log, arch=arch, steps=steps)
    except Caught:
        pass
    finally:
        Trainer.fit, forked.AVAILABLE, heldout.run_parallel = original, apart, parallel
    return caught["x"], caught["t"], caught.get("xv"), caught.get("tv")


def harmonic_log(tmp: str, seed: int = 0, seconds: float = 60.0, rate: float = 100.0) -> str:
    """A log without velocity levels: a sum of three harmonics (0.11, 0.23, 0.41 Hz), a gravity
    torque of the position, load-dependent Stribeck and viscous friction and 0.2 Nm of noise, at
    ``rate`` for ``seconds`` (6,000 rows; train-base keeps 2,500 of them)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    qd = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in
             zip((0.4, 0.25, 0.15), (0.11, 0.23, 0.41), rng.uniform(0, 2 * np.pi, 3)))
    q = np.cumsum(qd) / rate
    g = 30 * np.sin(2 * q + 0.3)
    fc, fs = 5 + 0.04 * np.abs(g), 7 + 0.05 * np.abs(g)
    f = np.sign(qd) * (fc + (fs - fc) * np.exp(-np.abs(qd / 0.04))) + 10 * qd
    sig = {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_m": g + f + rng.normal(0, 0.2, t.size),
           "tau_g": g, "tau_dyn": np.zeros_like(t)}
    path = os.path.join(tmp, "harmonic.parquet")
    write_log(sig, {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm",
                    "tau_dyn": "Nm"}, path)
    return path


def distinct_velocities_log(tmp: str, seed: int = 0) -> str:
    """The base log with every velocity moved by a random 10 ppm, as measurement noise would: the
    trainer finds too few repeated network inputs to group and computes every sample."""
    log = logs.load_log(BASE_LOG)
    sig = dict(log.signals)
    sig["qd"] = sig["qd"] * (1.0 + 1e-5 * np.random.default_rng(seed).standard_normal(sig["qd"].size))
    path = os.path.join(tmp, "base_distinct_qd.parquet")
    write_log(sig, log.units, path)
    return path


def host_cores(add) -> None:
    """``benchmarks/cores.py``'s AVX2 loop alone and as two copies at once, before the figures: on a
    host whose two vCPUs are at times one core's two hardware threads, every figure that runs two
    trainings or threads at once moves with it (docs/performance.md)."""
    try:
        alone, two = cores.measure()["vector"]
    except (OSError, subprocess.CalledProcessError) as exc:
        add("host", "two copies of an AVX2 loop / one", None, "", f"skipped: {exc}")
        return
    add("host", "two copies of an AVX2 loop / one (1: two cores)", two / alone, "x")


def bench_train_base(add, tmp: str, size: dict, reps: int, torch, threads: int) -> None:
    """The default ``fricli train-base`` (training time as the command reports it, and the wall
    time of the whole command), against the same training in PyTorch: the same training and
    validation rows, network, head, steps actually run, full batch, learning-rate schedule,
    validation checks; PyTorch on 1 and on ``threads`` threads (fricli runs one thread at this size).
    The dissipative network's pre-sliding state and its blend with the LuGre static curve are
    fitted around its training: the ratio compares the training alone (``--bristles off
    --no-prior``), and the default command's time is reported beside it.
    Also on the base log with distinct velocities (``distinct_velocities_log``) and with --arch mlp."""
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))

    def train(path, *extra):
        args = ["train-base", path, "-o", os.path.join(tmp, "tb.npz"), "--json", *extra]
        if size["train_base_steps"]:
            args += ["--steps", str(size["train_base_steps"])]
        runs = []
        for _ in range(reps):
            start = time.perf_counter()
            proc = subprocess.run([sys.executable, "-m", "fricli", *args, "--quiet"], cwd=ROOT, env=env,
                                  capture_output=True, text=True, check=True)
            runs.append((time.perf_counter() - start, json.loads(proc.stdout)))
        wall = statistics.median(r[0] for r in runs)
        return wall, sorted((r[1] for r in runs), key=lambda s: s["seconds"])[len(runs) // 2]

    harmonic = harmonic_log(tmp)
    cases = ((BASE_LOG, "", ()), (distinct_velocities_log(tmp), ", distinct velocities", ()),
             (harmonic, ", continuous motion", ()), (harmonic, ", continuous motion", ("--ensemble", "5")),
             (BASE_LOG, "", ("--arch", "mlp")))
    for path, what, extra in cases:
        default = not extra and what in ("", ", continuous motion")
        log = logs.load_log(path)
        wall, summary = train(path, *extra)
        arch, steps, train_s = summary["arch"], summary["steps"], summary["seconds"]
        label = (f"train-base{' ' + ' '.join(extra) if extra else ' default'}{what} "
                 f"({arch}, {summary['schedule']}, {steps:,} steps)")
        add("train", f"{label}, training time", train_s, "s",
            ("target <= 3" if what else "target <= 10") if default else "")
        if not extra or extra[0] == "--ensemble":
            add("train", f"{label}, whole command (wall)", wall, "s")
            held = summary.get("held_out_choice") or summary.get("cross_validation")
            if held is not None:
                add("train", f"{label}, held-out RMS", held["held_out_rmse"], log.units["tau"])
            else:
                add("train", f"{label}, validation MAE", summary["val"]["mae"], log.units["tau"])
        if arch == "dissipative":   # the state's sigma0 is fitted after the training PyTorch repeats
            _, plain = train(path, *extra, "--bristles", "off", "--no-prior")
            add("train", f"{label}, training time with --bristles off --no-prior (the network alone)",
                plain["seconds"], "s")
            train_s = plain["seconds"]
        if torch is None:
            continue
        x, t, xv, tv = training_rows(log, arch, steps)
        every = max(1, math.ceil(steps / 2000))
        best = math.inf
        for n_threads in dict.fromkeys((1, threads)):
            secs = statistics.median(torch_whole_training_s(x, t, xv, tv, steps, every, n_threads, arch)
                                     for _ in range(reps))
            add("train", f"same training in PyTorch, {arch}{what} ({n_threads} thread{'s' * (n_threads > 1)}, "
                f"{x.shape[1]} rows, {steps:,} steps)", secs, "s")
            best = min(best, secs)
        if what == ", continuous motion":   # the default command against one network's training
            add("train", f"ratio PyTorch (faster thread count) / fricli command's training time, "
                f"{arch}{what}{' ' + ' '.join(extra) if extra else ''}", best / summary["seconds"], "x",
                "target >= 3" if default else "")
        add("train", f"ratio PyTorch (faster thread count) / fricli, {arch}{what}"
            + (" (the network alone)" if arch == "dissipative" else ""), best / train_s, "x",
            "target >= 6" if default and not what else "")


def bench_startup(add, reps: int) -> None:
    """Start-up: ``fricli --version`` and ``fricli COMMAND --help``, median of at least 5 runs."""
    for args in (["--version"], ["train-base", "--help"], ["predict", "--help"]):
        secs = run_cli(args, max(5, reps), quiet=False)
        add("startup", f"fricli {' '.join(args)} (wall)", secs, "s", "target <= 0.3")


def plain_pyarrow_s(src: str, dst: str, batch_rows: int = 1 << 20, fricli_options: bool = False) -> float:
    """Read ``src`` in record batches, append one float64 column, write with zstd (pyarrow's
    defaults, or with ``fricli_options`` as fricli writes logs, ``logs.parquet_options``): the
    Parquet I/O a file-to-file prediction cannot avoid (``benchmarks/plain_pyarrow.py``), in this
    warm process. Wall time [s]."""
    start = time.perf_counter()
    plain_pyarrow.copy_with_column(src, dst, batch_rows, logs.parquet_options if fricli_options else None)
    return time.perf_counter() - start


def plain_pyarrow_process_s(src: str, dst: str) -> float:
    """The same as its own process, ``python benchmarks/plain_pyarrow.py SRC DST``, started as a
    fricli command is (``run_cli``): wall time [s], start-up included."""
    start = time.perf_counter()
    subprocess.run([sys.executable, os.path.join(HERE, "plain_pyarrow.py"), src, dst], check=True)
    return time.perf_counter() - start


def bench_predict_files(add, tmp: str, paths: dict, big_path: str, rows: int, reps: int, kinds) -> None:
    """File-to-file ``predict`` and ``estimate-ext`` of every kind against plain pyarrow
    read + append-one-column + write of the same file, in this warm process and as a process of
    its own. Each ratio pairs the command's runs with plain pyarrow runs made alternately with
    them, so that both see the same load on the machine."""
    out = os.path.join(tmp, "pred.parquet")
    plain_all = [plain_pyarrow_s(big_path, out) for _ in range(reps)]
    same = statistics.median(plain_pyarrow_s(big_path, out, fricli_options=True) for _ in range(reps))
    add("predict", f"the same, written with fricli's options (no dictionaries, floats split), {rows:,} rows",
        rows / same, "rows/s")
    for command in ("predict", "estimate-ext"):
        for kind in kinds:
            plain, process, secs = [], [], []
            for _ in range(reps):
                plain.append(plain_pyarrow_s(big_path, out))
                process.append(plain_pyarrow_process_s(big_path, out))
                secs.append(run_cli([command, paths[kind], big_path, "-o", out], 1))
            plain_all += plain
            plain_s, secs_s = statistics.median(plain), statistics.median(secs)
            add("predict", f"{kind}: {command} file to file (wall), {rows:,} rows", rows / secs_s, "rows/s")
            add("predict", f"{kind}: {command} / plain pyarrow", plain_s / secs_s, "x", "target >= 0.7")
            add("predict", f"{kind}: {command} / plain pyarrow as a process (start-up included, as the command's)",
                statistics.median(process) / secs_s, "x")
            add("predict", f"{kind}: {command} / plain pyarrow with fricli's options", same / secs_s, "x")
    add("predict", f"plain pyarrow read + append a column + write (zstd), {rows:,} rows, all runs",
        rows / statistics.median(plain_all), "rows/s")


# ---------------------------------------------------------------------------- main


def build_models(tmp: str, base_log: logs.Log, quick: bool) -> dict[str, str]:
    """One model file per kind, trained briefly (prediction cost does not depend on the fit)."""
    from fricli import models
    from fricli.fitting import identify
    from fricli.fitting.diagnosis import driver
    from fricli.fitting.diagnosis.fix import augment

    steps = 20 if quick else 200
    lugre = identify.identify(base_log).model_
    built = {"lugre": lugre}
    for arch in ("dissipative", "mlp", "selmic", "nnacm"):
        built[arch] = learning.train_base(base_log, arch=arch, steps=steps)[0]
    adapt_log = logs.load_log(ADAPT_LOG)
    built["residual"] = learning.adapt(lugre, adapt_log, epochs=2)[0]
    ext = logs.load_log(EXT_LOG)
    built["augmented"] = augment(lugre, driver.diagnose(lugre, ext), ext)
    paths = {}
    for kind, model in built.items():
        paths[kind] = os.path.join(tmp, f"{kind}.npz")
        log = adapt_log if kind == "residual" else ext if kind == "augmented" else base_log
        models.save_for_log(paths[kind], model, log, rows_used=len(log))
    return paths


def bench_identify(add, tmp: str, size: dict, reps: int) -> None:
    """identify on a simulated base log of ``identify_rows`` rows (the sample log when None):
    the library call on the loaded log, and the whole command."""
    from fricli.fitting import identify
    if size["identify_rows"]:
        id_path = os.path.join(tmp, "identify.parquet")
        rate = size["identify_rows"] / 351.0
        simulate(id_path, ["--scenario", "base", "--rate", f"{rate:.6g}", "--seed", "1"])
    else:
        id_path = BASE_LOG
    id_log = logs.load_log(id_path)
    add("lugre", f"identify (library), {len(id_log):,} rows",
        median_time(lambda: identify.identify(id_log), reps), "s", "target < 5")
    wall, cpu = run_cli_times(["identify", id_path, "-o", os.path.join(tmp, "id.npz")], reps)
    add("lugre", f"identify command (wall), {len(id_log):,} rows", wall, "s", "target <= 1")
    add("lugre", f"identify command (CPU, user + system), {len(id_log):,} rows", cpu, "s")


def main(argv=None) -> dict:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--torch-worker"]:
        folder, *numbers = argv[1:]
        arch = numbers.pop() if not numbers[-1].isdigit() else "mlp"
        torch_worker(folder, *(int(v) for v in numbers), arch=arch)
        return {}
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="tiny sizes: checks that everything runs")
    ap.add_argument("--json", action="store_true", help="print the figures as JSON on stdout")
    ap.add_argument("--repeats", type=int, default=None, help="repeats per figure (median); default 3, quick 1")
    ap.add_argument("--threads", type=int, default=2, help="PyTorch threads (fricli uses at most 2)")
    ap.add_argument("--plot", default=None, metavar="PNG", help="also measure scaling and plot it to PNG")
    ap.add_argument("--skip-torch", action="store_true", help="do not measure PyTorch even if installed")
    ap.add_argument("--only", choices=["identify", "train-base"], default=None,
                    help="measure only this case (identify: the library call and the whole command; train-base: "
                         "the train-base commands against PyTorch)")
    args = ap.parse_args(argv)
    size = dict(QUICK if args.quick else FULL)
    reps = args.repeats or size["repeats"]
    torch = None if args.skip_torch else torch_version()
    res: dict = {"machine": {"python": platform.python_version(), "numpy": np.__version__, "cpus": os.cpu_count(),
                             "processor": platform.processor() or platform.machine(),
                             "blas_threads": max(blas_threads().values(), default=None),
                             "torch": torch, "torch_threads": args.threads,
                             "quick": args.quick, "repeats": reps},
                 "rows": []}
    rows = res["rows"]

    def add(group, name, value, unit, note=""):
        rows.append({"group": group, "name": name, "value": value, "unit": unit, "note": note})
        say(f"  {group:<9} {name:<52} {fmt(value):>12} {unit} {note}")

    if not args.quick:   # whether the two vCPUs shared a core's vector units while this ran
        say("host")
        host_cores(add)

    if args.only is not None:
        with tempfile.TemporaryDirectory() as tmp:
            if args.only == "identify":
                say("lugre")
                bench_identify(add, tmp, size, reps)
            else:
                say("training")
                bench_train_base(add, tmp, size, reps, torch, args.threads)
        print(json.dumps(res, indent=1) if args.json else format_table(res))
        return res

    with tempfile.TemporaryDirectory() as tmp:
        base_log = logs.load_log(BASE_LOG)

        # ---- training
        say("training")
        x, t = training_arrays(base_log)
        n = x.shape[1]
        net = mlp()
        full = fricli_steps_per_s(x, t, size["steps"], 0, reps)
        mini = fricli_steps_per_s(x, t, size["mini_steps"], 256, reps)
        add("train", f"full-batch steps/s, fricli (N = {n}, sample base log)", full, "steps/s")
        add("train", f"mini-batch (256) steps/s, fricli (N = {n})", mini, "steps/s")
        if torch is not None:
            for threads in dict.fromkeys((args.threads, 1)):
                tfull = torch_steps_per_s(x, t, torch_steps(size["steps"]), 0, reps, threads)
                tmini = torch_steps_per_s(x, t, torch_steps(size["mini_steps"]), 256, reps, threads)
                add("train", f"full-batch steps/s, PyTorch ({threads} thread{'s' * (threads > 1)})", tfull, "steps/s")
                add("train", f"mini-batch (256) steps/s, PyTorch ({threads} thread{'s' * (threads > 1)})", tmini,
                    "steps/s")
                add("train", f"ratio fricli / PyTorch ({threads}), full batch", full / tfull, "x", "target >= 2")
                add("train", f"ratio fricli / PyTorch ({threads}), mini-batch", mini / tmini, "x", "target >= 4")
        else:
            add("train", "PyTorch", None, "", "skipped: torch is not installed")
        big_n = 100_000 if not args.quick else 5_000
        xb, tb = resample(x, t, big_n)
        big_steps = max(5, size["steps"] // 50)
        full_big = fricli_steps_per_s(xb, tb, big_steps, 0, reps)
        add("train", f"full-batch steps/s, fricli (N = {big_n})", full_big, "steps/s")
        if torch is not None:
            tbig = torch_steps_per_s(xb, tb, torch_steps(big_steps), 0, reps, args.threads)
            add("train", f"full-batch steps/s, PyTorch (N = {big_n})", tbig, "steps/s")
            add("train", f"ratio fricli / PyTorch, full batch N = {big_n}", full_big / tbig, "x")
        bench_train_base(add, tmp, size, reps, torch, args.threads)

        # ---- start-up
        say("startup")
        bench_startup(add, reps)

        # ---- the physical limit
        say("limits")
        peak32 = gflops(np.float32, 2048 if not args.quick else 256, None, reps)
        peak32_1 = gflops(np.float32, 2048 if not args.quick else 256, 1, reps)
        peak64 = gflops(np.float64, 2048 if not args.quick else 256, None, reps)
        lay = layer_gflops(n, reps)
        flops = matmul_flops(net, n)
        achieved = flops * full / 1e9
        add("limit", "peak float32 matmul 2048^2, BLAS default threads", peak32, "GFLOP/s")
        add("limit", "peak float32 matmul 2048^2, one thread", peak32_1, "GFLOP/s")
        add("limit", "peak float64 matmul 2048^2, BLAS default threads", peak64, "GFLOP/s")
        add("limit", f"(30 x 31) @ (31 x {n}) float32, one thread", lay, "GFLOP/s")
        add("limit", f"full-batch training, matrix-product GFLOP/s achieved (N = {n})", achieved, "GFLOP/s")
        add("limit", "matrix-product time of 30,000 steps at that layer rate (one thread)",
            flops * 30_000 / (lay * 1e9), "s", "compute limit")
        add("limit", f"full-batch N = {big_n}: matrix-product GFLOP/s achieved", matmul_flops(net, big_n) * full_big / 1e9,
            "GFLOP/s")

        # ---- LuGre simulation and identification
        say("lugre")
        params = dict(fc=10.0, fs=14.0, vs=0.05, delta=1.5, fv=20.0, sigma0=1e5, sigma1=30.0)
        sig_l = tiled_signals(base_log, size["lugre_rows"])
        v, dt = sig_l["qd"], physics.intervals(sig_l["t"])
        g = physics.stribeck(v, params["fc"], params["fs"], params["vs"], params["delta"])
        nl = len(v)
        secs = median_time(lambda: physics.lugre_friction(v, g, params["fv"], params["sigma0"], params["sigma1"], dt),
                           max(reps, 5))
        add("lugre", f"physics.lugre_friction, {nl:,} samples", nl / secs, "samples/s")
        ln = size["loop_rows"]
        secs_loop = median_time(lambda: lugre_loop(v[:ln], g[:ln], params["fv"], params["sigma0"], params["sigma1"],
                                                    dt[:ln], 0.0), reps)
        add("lugre", f"same update as a Python loop, {ln:,} samples (reference)", ln / secs_loop, "samples/s")
        ref, _ = physics.lugre_friction(v[:ln], g[:ln], params["fv"], params["sigma0"], params["sigma1"], dt[:ln], 0.0)
        loop = lugre_loop(v[:ln], g[:ln], params["fv"], params["sigma0"], params["sigma1"], dt[:ln], 0.0)
        res["lugre_loop_max_abs_diff"] = float(np.max(np.abs(ref - loop)))
        model_l = LuGreModel(**params)
        secs = median_time(lambda: model_l.predict(sig_l), max(reps, 5))
        add("lugre", f"LuGreModel.predict (t, qd), {nl:,} samples", nl / secs, "samples/s")

        bench_identify(add, tmp, size, reps)

        # ---- prediction
        say("predict")
        from fricli import models
        paths = build_models(tmp, base_log, args.quick)
        np_rows = size["predict_rows"]
        ext = logs.load_log(EXT_LOG)
        big = tiled_signals(ext, np_rows)
        big_path = os.path.join(tmp, "big.parquet")
        write_log(big, ext.units, big_path)
        for kind in KINDS:
            model, _ = models.load(paths[kind])
            secs = median_time(lambda: model.predict(big), reps)
            add("predict", f"{kind}: model.predict in memory, {np_rows:,} rows", np_rows / secs, "samples/s",
                "target >= 10 M" if kind == "lugre" else "target >= 5 M" if kind in ("mlp", "selmic", "nnacm") else "")
        bench_predict_files(add, tmp, paths, big_path, np_rows, reps, KINDS if not args.quick else KINDS[:2])
        del big
        export_rows(add, paths, ext, reps, args.quick)

        # ---- diagnosis
        say("diagnose")
        if size["diagnose_rows"]:
            dg_path = os.path.join(tmp, "diagnose.parquet")
            simulate(dg_path, ["--scenario", "extended", "--load", "asym", "--effect", "ripple", "--seed", "4",
                               "--duration", f"{size['diagnose_rows'] / 100.0:g}"])
        else:
            dg_path = EXT_LOG
        from fricli.fitting.diagnosis import driver
        dg_log = logs.load_log(dg_path)
        lugre, _ = models.load(paths["lugre"])
        add("diagnose", f"diagnose (library), lugre model, {len(dg_log):,} rows",
            median_time(lambda: driver.diagnose(lugre, dg_log), reps), "s")
        add("diagnose", f"diagnose command (wall), lugre model, {len(dg_log):,} rows",
            run_cli(["diagnose", paths["lugre"], dg_path], reps), "s")

        if args.plot:
            say("scaling")
            res["scaling"] = scaling(x, t, size, reps, torch, args.threads, base_log, paths)
            plot(res["scaling"], args.plot)
            say(f"plot written to {args.plot}")

    table = format_table(res)
    say("")
    say(table)
    if args.json:
        print(json.dumps(res, indent=1))
    else:
        print(table)
    return res


def export_rows(add, paths: dict[str, str], log: logs.Log, reps: int, quick: bool) -> None:
    """Exported C (``fricli export``): ns per call of the step function, compiled with the system C
    compiler at -O2 and timed in CPU time over the rows of ``log``, next to ns per sample of
    ``model.predict`` in double precision (the same arithmetic) on the same rows."""
    from fricli import models
    sys.path.insert(0, os.path.join(ROOT, "tests"))   # the compile-and-run helper the tests use
    import export_check as check

    from fricli.export import c

    if check.compiler() is None:
        add("export", "exported C step", None, "", "skipped: no C compiler")
        return
    targets = {"lugre": "target <= 50", "dissipative": "target <= 300 (default neural model)"}
    with tempfile.TemporaryDirectory() as tmp:
        for kind in KINDS:
            model, _ = models.load(paths[kind])
            header, exe = os.path.join(tmp, f"{kind}.h"), os.path.join(tmp, kind)
            text = c.export(paths[kind], "fr")
            with open(header, "w") as fh:
                fh.write(text)
            check.build(header, "fr", exe)
            builds = [(exe, "-O2", targets.get(kind, ""))]
            if c.AVX2 in text:                          # a network: its portable copy too
                check.build(header, "fr", exe + "_portable", flags=("-DFRICLI_PORTABLE",))
                builds.append((exe + "_portable", "-O2 -DFRICLI_PORTABLE", "portable copy only"))
            x = check.signal_matrix(log.signals, c.signals_of(model))
            best = [math.inf] * len(builds)
            for _ in range(reps):                       # alternating, so both see the same load
                for i, (path, _, _) in enumerate(builds):
                    best[i] = min(best[i], check.time_step(path, x, 0.05 if quick else 0.5))
            for ns, (_, flags, note) in zip(best, builds):
                add("export", f"{kind}: exported C step ({flags}), {len(x):,} rows", ns, "ns/sample", note)
            models.set_precision(model, "double")
            secs = median_time(lambda: model.predict(log.signals), reps)
            add("export", f"{kind}: model.predict, double precision, {len(x):,} rows", 1e9 * secs / len(x),
                "ns/sample")


def scaling(x, t, size, reps, torch, threads, base_log, paths) -> dict:
    """Cost against log length (training N, prediction rows) and network width."""
    from fricli import models
    out = {"train_n": [], "train_fricli_ms": [], "train_torch_ms": [], "rows": [], "lugre_us": [], "mlp_us": [],
           "width": [], "width_fricli_ms": [], "width_torch_ms": []}
    for n in size["scale_n"]:
        xs, ts = resample(x, t, n)
        steps = max(5, int(5e5 / n)) if len(size["scale_n"]) > 2 else 10
        out["train_n"].append(n)
        out["train_fricli_ms"].append(1e3 / fricli_steps_per_s(xs, ts, steps, 0, reps))
        out["train_torch_ms"].append(1e3 / torch_steps_per_s(xs, ts, torch_steps(steps), 0, reps, threads)
                                     if torch is not None else None)
        say(f"  N = {n}: {out['train_fricli_ms'][-1]:.3f} ms/step")
    ext = logs.load_log(EXT_LOG)
    lugre, _ = models.load(paths["lugre"])
    mlp_model, _ = models.load(paths["mlp"])
    for rows in size["scale_rows"]:
        sig = tiled_signals(ext, rows)
        out["rows"].append(rows)
        out["lugre_us"].append(1e6 * median_time(lambda: lugre.predict(sig), reps) / rows * 1e3)
        out["mlp_us"].append(1e6 * median_time(lambda: mlp_model.predict(sig), reps) / rows * 1e3)
        say(f"  rows = {rows}: lugre {out['lugre_us'][-1]:.3f}, mlp {out['mlp_us'][-1]:.3f} us per 1000 rows")
    xs, ts = x, t
    out["width_n"] = xs.shape[1]
    for w in size["scale_width"]:
        steps = max(10, int(1e8 / (w * w * xs.shape[1]))) if len(size["scale_width"]) > 2 else 10
        out["width"].append(w)
        out["width_fricli_ms"].append(1e3 / fricli_steps_per_s(xs, ts, steps, 0, reps, width=w))
        out["width_torch_ms"].append(1e3 / torch_steps_per_s(xs, ts, torch_steps(steps), 0, reps, threads, width=w)
                                     if torch is not None else None)
        say(f"  width {w}: {out['width_fricli_ms'][-1]:.3f} ms/step")
    return out


def plot(sc: dict, path: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    ax = axes[0]
    ax.loglog(sc["train_n"], sc["train_fricli_ms"], "o-", label="fricli")
    if any(v is not None for v in sc["train_torch_ms"]):
        ax.loglog(sc["train_n"], sc["train_torch_ms"], "s--", label="PyTorch")
    ax.set(xlabel="training samples N (full batch)", ylabel="ms per Adam step", title="training, 2-30-30-1")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    ax = axes[1]
    ax.semilogx(sc["rows"], sc["lugre_us"], "o-", label="lugre")
    ax.semilogx(sc["rows"], sc["mlp_us"], "s-", label="mlp")
    ax.set(xlabel="log rows", ylabel="ms per million rows", title="prediction in memory")
    ax.set_ylim(bottom=0)
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    ax = axes[2]
    ax.loglog(sc["width"], sc["width_fricli_ms"], "o-", label="fricli")
    if any(v is not None for v in sc["width_torch_ms"]):
        ax.loglog(sc["width"], sc["width_torch_ms"], "s--", label="PyTorch")
    ax.set(xlabel="hidden width w (2-w-w-1)", ylabel="ms per Adam step",
           title=f"network size, full batch N = {sc['width_n']}")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    from fricli.core.atomic import atomic_open
    with atomic_open(path) as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)


def fmt(value) -> str:
    if value is None:
        return "-"
    if abs(value) >= 1e6:
        return f"{value / 1e6:,.2f} M"
    if abs(value) >= 100:
        return f"{value:,.0f}"
    return f"{value:.3g}"


def format_table(res: dict) -> str:
    m = res["machine"]
    head = (f"fricli benchmarks ({'quick' if m['quick'] else 'full'}; median of {m['repeats']}; "
            f"{m['cpus']} CPUs, numpy {m['numpy']}, torch {m['torch'] or 'not installed'})")
    lines = [head, "", "| group | measurement | value | unit | note |", "|---|---|---:|---|---|"]
    for r in res["rows"]:
        lines.append(f"| {r['group']} | {r['name']} | {fmt(r['value'])} | {r['unit']} | {r['note']} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
