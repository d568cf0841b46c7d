import pathlib
import sys

import numpy as np
import pytest

from fricli.core.logs import table_from_arrays

ROOT = pathlib.Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_data"
SHARED_DATA = ROOT.parent / "shared" / "data"


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def invoke(*args, **kwargs):
    """``fricli ARGS`` run in this process through click's CliRunner (arguments turned into strings;
    ``kwargs`` go to ``CliRunner.invoke``, e.g. ``input=``, ``catch_exceptions=False``)."""
    from click.testing import CliRunner

    from fricli.cli import cli

    return CliRunner().invoke(cli, [str(a) for a in args], **kwargs)


def run_in(cwd, *args, **kwargs):
    """``fricli ARGS`` run in this process with ``cwd`` as the working directory, for tests of what a
    command does rather than of the process: a ``subprocess.CompletedProcess`` (returncode, stdout and
    stderr as text). stderr holds what a process would print there: the command's text, warnings
    under Python's default filters, and what libraries write to file descriptor 2 (e.g. a C++ parser's
    complaint). An exception other than the command's exit is raised."""
    import os
    import subprocess
    import tempfile
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno, line))

    old = os.getcwd()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as fd2, warnings.catch_warnings():
        warnings.resetwarnings()
        warnings.simplefilter("default")
        for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning):
            warnings.simplefilter("ignore", category)
        warnings.showwarning = show
        os.chdir(cwd)
        sys.stderr.flush()
        os.dup2(fd2.fileno(), 2)
        try:
            res = invoke(*args, **kwargs)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            os.chdir(old)
        fd2.seek(0)
        native = fd2.read().decode(errors="replace")
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    return subprocess.CompletedProcess(list(args), res.exit_code, res.stdout, res.stderr + native)


@pytest.fixture
def fricli_in_process(monkeypatch):
    """During the test, ``subprocess.run([sys.executable, "-m", "fricli", ...])`` (as the scripts in
    benchmarks/ and docs/ run a command) runs the command in this process through ``run_in``:
    for tests of a script's results, not of its processes. Other commands run as before."""
    import os
    import subprocess

    real = subprocess.run

    def run(cmd, *args, **kwargs):
        if args or not (isinstance(cmd, (list, tuple)) and list(cmd[:3]) == [sys.executable, "-m", "fricli"]):
            return real(cmd, *args, **kwargs)
        done = run_in(kwargs.get("cwd") or os.getcwd(), *cmd[3:], **({"input": kwargs["input"]} if "input" in kwargs else {}))
        if not (kwargs.get("text") or kwargs.get("universal_newlines") or kwargs.get("encoding")):
            done = subprocess.CompletedProcess(done.args, done.returncode, done.stdout.encode(), done.stderr.encode())
        if kwargs.get("check") and done.returncode:
            raise subprocess.CalledProcessError(done.returncode, cmd, done.stdout, done.stderr)
        return done

    monkeypatch.setattr(subprocess, "run", run)


# ---------------------------------------------------------------- trained once per test run
# Model files and logs that several test files need with the same data and the same options.
# Tests read them and write their outputs elsewhere (their own tmp_path).


@pytest.fixture(scope="session")
def coupled_arm_logs(tmp_path_factory):
    """The simulated coupled-wrist arm (fricli.sim.coupled, default arm), 20 s at 1 kHz: a training
    run (seed 11) and a held-out run (seed 12), as (folder holding train.parquet and test.parquet,
    {"train": run, "test": run})."""
    from fricli.core import logs
    from fricli.sim.coupled import simulate_coupled

    folder = tmp_path_factory.mktemp("coupled_arm")
    runs = {}
    for name, seed in (("train", 11), ("test", 12)):
        runs[name] = simulate_coupled(duration=20.0, rate_hz=1000.0, rng=np.random.default_rng(seed))
        logs.write_table(runs[name].table, str(folder / f"{name}.parquet"))
    return folder, runs


def declare_zero(table, *columns):
    """``table`` with the schema metadata key fricli.zero_columns: the robot-model columns (tau_g,
    tau_dyn; default tau_dyn) it lacks are zero, as for a log with no inertia torque in tau_m."""
    import json

    meta = dict(table.schema.metadata or {})
    meta[b"fricli.zero_columns"] = json.dumps(list(columns or ("tau_dyn",))).encode()
    return table.replace_schema_metadata(meta)


def no_inertia(table):
    """``table`` with a tau_dyn column of zeros in tau_m's unit: a synthetic log whose tau_m holds no
    inertia torque (a missing tau_dyn is unknown, not zero)."""
    from fricli.core import logs

    if "tau_dyn" in table.column_names:
        return table
    unit = logs.field_unit(table.schema.field("tau_m")) if "tau_m" in table.column_names else "Nm"
    return logs.with_column(table, "tau_dyn", np.zeros(table.num_rows), unit or "Nm")


def make_table(n=500, rate=100.0, units=None, **extra):
    """A small valid log: sinusoidal motion, friction = 5 sign(qd) + 10 qd, no inertia torque
    (tau_dyn zero)."""
    t = np.arange(n) / rate
    q = 0.5 * np.sin(0.5 * t)
    qd = 0.25 * np.cos(0.5 * t)
    tau_g = 20 * np.sin(q)
    tau_m = tau_g + 5 * np.sign(qd) + 10 * qd
    cols = {"t": t, "q": q, "qd": qd, "tau_m": tau_m, "tau_g": tau_g}
    cols.update(extra)
    default_units = {"t": "s", "q": "rad", "qd": "rad/s", "tau_m": "Nm", "tau_g": "Nm"}
    default_units.update(units or {})
    return no_inertia(table_from_arrays(cols, default_units))


def write(table, path):
    import pyarrow.parquet as pq

    pq.write_table(table, path)
    return str(path)


def shared_data(name):
    path = SHARED_DATA / name
    if not path.exists():
        pytest.skip(f"{path} is absent")
    return path


def imported_modules(source: str, package: str, top_level: bool = False) -> set[str]:
    """Every name ``source`` (a module of ``package``) imports, absolute (relative imports
    resolved): ``import a.b`` gives a.b, ``from P import X`` gives P.X. ``top_level``: only the
    imports run when the module is imported (at module level and in its if/try/with blocks), else
    those in functions and classes too."""
    import ast

    found = set()

    def visit(nodes):
        for node in nodes:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                if not top_level:
                    visit(node.body)
                continue
            if isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(parts + ([base] if base else []))
                found.update(f"{base}.{alias.name}" for alias in node.names)
            for field in ("body", "orelse", "finalbody", "handlers"):
                if isinstance(getattr(node, field, None), list):
                    visit(getattr(node, field))

    visit(ast.parse(source).body)
    return found
