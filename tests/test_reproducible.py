"""The same inputs and seed give byte-identical model files and identical Parquet tables, in
separate processes and whatever the BLAS thread count (OMP_NUM_THREADS / OPENBLAS_NUM_THREADS
1 and 2).

Two processes run the same commands in two folders, one with one BLAS thread and one with two
(OpenBLAS caps the count at the number of cores, so on a one-core machine both have one).
Every file and every stdout they produce must be byte for byte the same. Why it holds:
training pins every loaded BLAS to one thread (``fricli.numerics.threads.single_threaded``, through
threadpoolctl, whichever BLAS numpy and scipy use) and splits large full batches over two
worker threads in a fixed way (fricli/numerics/nn/training.py); identify pins the BLAS to one thread
too (its threaded reductions round differently per thread count); model files have fixed zip
timestamps and sorted JSON; Parquet output carries no time stamps.
"""

import json
import os
import subprocess
import sys
import threading

import pyarrow.parquet as pq
import pytest
import threadpoolctl

from conftest import ROOT, SAMPLE
from fricli.numerics.threads import blas_threads, single_threaded

SCRIPT = r"""
import contextlib, io, os, sys
import numpy
from fricli.cli import cli
from fricli.numerics.threads import blas_threads

sample = sys.argv[1]
with open("threads.txt", "w") as fh:
    fh.write(str(max(blas_threads().values())))
runs = {
    "simulate": ["simulate", "--scenario", "adapt", "--joint", "4", "--seed", "5", "-o", "sim.parquet"],
    "identify": ["identify", f"{sample}/joint2_base.parquet", "-o", "lugre.npz", "--json"],
    "train-base": ["train-base", f"{sample}/joint2_base.parquet", "-o", "nn.npz", "--steps", "150"],
    # over 8192 rows in a full batch: the gradient is split over two threads
    "train-base-threads": ["train-base", f"{sample}/joint2_base.parquet", "-o", "nn_all_rows.npz", "--steps", "15",
                           "--no-balance"],
    "train-base-minibatch": ["train-base", f"{sample}/joint2_base.parquet", "-o", "selmic.npz", "--arch", "selmic",
                             "--steps", "100", "--batch-size", "64", "--seed", "3"],
    "adapt": ["adapt", "nn.npz", f"{sample}/joint2_adapt.parquet", "-o", "adapted.npz", "--epochs", "10", "--json"],
    # the base spelled another way (as a fleet spells it): the same bytes
    "adapt-abs": ["adapt", os.path.abspath("nn.npz"), f"{sample}/joint2_adapt.parquet", "-o", "adapted_abs.npz",
                  "--epochs", "10"],
    "diagnose": ["diagnose", "lugre.npz", f"{sample}/joint2_extended_asym.parquet", "--fix", "-o", "fixed.npz",
                 "--folds", "5", "--json"],
    "predict": ["predict", "adapted.npz", f"{sample}/joint2_extended_asym.parquet", "-o", "pred.parquet",
                "--batch-rows", "5000"],
    "estimate-ext": ["estimate-ext", "fixed.npz", f"{sample}/joint2_extended_asym.parquet", "-o", "ext.parquet",
                     "--lowpass", "2"],
    "evaluate": ["evaluate", "--model", "lugre.npz", "--model", "adapted.npz", "--model", "fixed.npz",
                 "--log", f"{sample}/joint2_extended_sym.parquet", "--json"],
}
for name, args in runs.items():
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        try:
            cli.main(args + ["-q"], prog_name="fricli", standalone_mode=False)
        except SystemExit as exc:
            if exc.code:
                raise
    text = out.getvalue()
    # seconds taken are the one thing that may differ between runs
    text = "\n".join(line for line in text.splitlines() if '"seconds":' not in line)
    with open(f"{name}.stdout", "w") as fh:
        fh.write(text)
"""


def run_in(folder, threads):
    folder.mkdir()
    env = dict(os.environ, OMP_NUM_THREADS=str(threads), OPENBLAS_NUM_THREADS=str(threads),
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-c", SCRIPT, str(SAMPLE)], cwd=folder, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def test_same_bytes_in_separate_processes_and_across_blas_thread_counts(tmp_path):
    one, two = tmp_path / "threads1", tmp_path / "threads2"
    procs = [run_in(one, 1), run_in(two, 2)]
    for proc in procs:
        _, err = proc.communicate(timeout=600)
        assert proc.returncode == 0, err.decode()
    assert (one / "threads.txt").read_text() == "1"
    assert (two / "threads.txt").read_text() == str(min(2, os.cpu_count() or 1))
    files = sorted(p.name for p in one.iterdir())
    assert files == sorted(p.name for p in two.iterdir())
    outputs = [f for f in files if f.endswith((".npz", ".parquet"))]
    assert len(outputs) == 10
    assert (one / "adapted.npz").read_bytes() == (one / "adapted_abs.npz").read_bytes()
    for name in files:
        if name == "threads.txt":
            continue
        assert (one / name).read_bytes() == (two / name).read_bytes(), f"{name} differs"
        if name.endswith(".parquet"):
            assert pq.read_table(one / name).equals(pq.read_table(two / name))
    assert '"fit"' in (one / "identify.stdout").read_text()  # stdout was captured, not lost


@pytest.fixture
def two_blas_threads():
    """Every loaded BLAS (numpy's and scipy's) on two threads during the test, so that a limit to
    one is visible whatever the environment says."""
    import scipy.linalg  # noqa: F401

    if (os.cpu_count() or 1) < 2:
        pytest.skip("one core: BLAS caps its thread count at one")
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        assert set(blas_threads().values()) == {2}
        yield


def test_single_threaded_pins_every_blas_and_restores_it(two_blas_threads):
    with single_threaded():
        assert set(blas_threads().values()) == {1}
        with single_threaded():
            assert set(blas_threads().values()) == {1}
        assert set(blas_threads().values()) == {1}      # the inner block does not lift the limit
    assert set(blas_threads().values()) == {2}


def test_single_threaded_holds_until_the_last_thread_leaves(monkeypatch):
    # a recording stand-in for threadpoolctl: the threads' order of entry and exit is forced
    calls = []

    class Limits:
        def __init__(self, limits, user_api):
            calls.append(("set", limits, user_api))

        def restore_original_limits(self):
            calls.append(("restore",))

    monkeypatch.setattr(threadpoolctl, "threadpool_limits", Limits)
    entered, leave = threading.Event(), threading.Event()

    def first():
        with single_threaded():
            entered.set()
            leave.wait(10)

    worker = threading.Thread(target=first)
    worker.start()
    assert entered.wait(10)
    with single_threaded():
        leave.set()
        worker.join(10)                     # the first thread leaves while this one is inside
        assert calls == [("set", 1, "blas")]
    assert calls == [("set", 1, "blas"), ("restore",)]


_PINNED = """
import json
from fricli.core import logs
from fricli.fitting import identify
from fricli.numerics.threads import blas_threads

seen = []
fit = identify.LuGreIdentifier._fit
identify.LuGreIdentifier._fit = lambda self, *a: seen.append(blas_threads()) or fit(self, *a)
identify.identify(logs.load_log({path!r}))
import scipy.optimize  # noqa: E402,F401
print(json.dumps([seen[0], blas_threads()]))
"""


def test_identify_pins_scipys_blas_too():
    # a fresh interpreter, where identify itself imports scipy (and scipy's own BLAS library)
    code = _PINNED.format(path=str(SAMPLE / "joint2_base.parquet"))
    env = dict(os.environ, OPENBLAS_NUM_THREADS="2", PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    inside, loaded = json.loads(proc.stdout.strip().splitlines()[-1])
    assert sorted(inside) == sorted(loaded)          # scipy's BLAS library was loaded before the fit
    assert set(inside.values()) == {1}
