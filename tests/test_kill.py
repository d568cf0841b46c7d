"""SIGKILL a model-writing job: the previous model stays intact, byte for byte.

What holds (docs/reliability.md):
- killed while it trains (most of a run), a job leaves no temporary file; it leaves its empty
  lock file ``.NAME.lock``, whose lock the kernel released with the process, so the next job
  is not refused and removes the file;
- killed while it writes (between creating ``.NAME.XXXX.tmp`` and the ``os.replace``), a job
  leaves that temporary file; the model file itself is the previous one, and the next write to
  the same model removes the leftover.
"""

import os
import signal
import subprocess
import sys
import time

from click.testing import CliRunner

from conftest import ROOT, make_table, write
from fricli import models
from fricli.core import errors
from fricli.numerics import forked
from fricli.cli import cli


def fricli(*args, cwd, prelude=""):
    code = prelude + "from fricli.cli import main\nimport sys\nsys.argv = ['fricli', *sys.argv[1:]]\nmain()\n"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-c", code, *map(str, args)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


def wait_until(condition, proc, timeout=60.0):
    end = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            raise AssertionError(f"the job ended early ({proc.returncode}): {proc.stderr.read().decode()}")
        if time.monotonic() > end:
            proc.kill()
            raise AssertionError("the job did not get there in time")
        time.sleep(0.02)


def setup(tmp_path):
    """A log and a previous model made from it; returns (log, model path, model bytes)."""
    log = write(make_table(n=2000), tmp_path / "log.parquet")
    model = tmp_path / "model.npz"
    res = CliRunner().invoke(cli, ["train-base", log, "-o", str(model), "--steps", "5", "-q"])
    assert res.exit_code == 0, res.stderr
    return log, model, model.read_bytes()


def children_of(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux; [] elsewhere)."""
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(p) for p in f.read().split()]
    except OSError:
        return []


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, ended but not reaped, does not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def names(folder):
    return sorted(p.name for p in folder.iterdir())


def test_sigkill_during_training_keeps_the_previous_model(tmp_path):
    log, model, previous = setup(tmp_path)
    lock = tmp_path / ".model.npz.lock"
    proc = fricli("train-base", log, "-o", model, "--steps", 10**9, "--seed", "1", "-q", cwd=tmp_path)
    wait_until(lock.exists, proc)  # the log is read and the job holds the lock: it trains now
    time.sleep(0.3)
    other = CliRunner().invoke(cli, ["train-base", log, "-o", str(model), "--steps", "5", "-q"])
    assert other.exit_code == errors.LOCKED, other.stderr  # a second job is refused meanwhile
    if forked.AVAILABLE:   # the held-out probe trains in a child process
        wait_until(lambda: children_of(proc.pid), proc)
    children = children_of(proc.pid)
    proc.send_signal(signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL
    end = time.monotonic() + 10   # ... which stops at its next step once its parent is gone
    while any(alive(pid) for pid in children):
        assert time.monotonic() < end, "the child process outlived its killed parent"
        time.sleep(0.05)
    assert model.read_bytes() == previous
    assert models.load(str(model))
    assert names(tmp_path) == [".model.npz.lock", "log.parquet", "model.npz"]  # no temporary file
    # the kernel released the lock with the process: the next job runs, and tidies up
    res = CliRunner().invoke(cli, ["train-base", log, "-o", str(model), "--steps", "5", "--seed", "1", "-q"])
    assert res.exit_code == 0, res.stderr
    assert model.read_bytes() != previous
    assert names(tmp_path) == ["log.parquet", "model.npz"]


# Dies at the fsync before os.replace: the whole new model is in the temporary file by then.
DIE_WHILE_WRITING = "import os, signal\nos.fsync = lambda fd: os.kill(os.getpid(), signal.SIGKILL)\n"


def test_sigkill_while_writing_the_model_leaves_only_a_temporary_file(tmp_path):
    log, model, previous = setup(tmp_path)
    proc = fricli("train-base", log, "-o", model, "--steps", "5", "--seed", "2", "-q", cwd=tmp_path,
                  prelude=DIE_WHILE_WRITING)
    assert proc.wait(timeout=60) == -signal.SIGKILL, proc.stderr.read().decode()
    assert model.read_bytes() == previous
    assert models.load(str(model))
    left = [n for n in names(tmp_path) if n not in ("log.parquet", "model.npz")]
    temps = [n for n in left if n.startswith(".model.npz.") and n.endswith(".tmp")]
    assert len(temps) == 1 and sorted(left) == sorted(temps + [".model.npz.lock"])
    # the next write of the same model removes the leftover
    res = CliRunner().invoke(cli, ["train-base", log, "-o", str(model), "--steps", "5", "--seed", "2", "-q"])
    assert res.exit_code == 0, res.stderr
    assert names(tmp_path) == ["log.parquet", "model.npz"]
    assert model.read_bytes() != previous



def test_sigterm_during_training_keeps_the_previous_model_and_tidies_up(tmp_path):
    """SIGTERM (kill, timeout, a service manager) is an interruption: exit 143, nothing left behind."""
    log, model, previous = setup(tmp_path)
    proc = fricli("train-base", log, "-o", model, "--steps", 10**9, "--seed", "1", "-q", cwd=tmp_path)
    wait_until((tmp_path / ".model.npz.lock").exists, proc)
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == errors.TERMINATED
    assert proc.stderr.read().decode().splitlines()[-1] == "fricli: terminated"
    assert model.read_bytes() == previous
    assert names(tmp_path) == ["log.parquet", "model.npz"]


def test_sigterm_while_stdin_is_spooled_leaves_no_spool(tmp_path):
    log, model, _ = setup(tmp_path)
    spool = tmp_path / "tmp"
    spool.mkdir()
    code = "from fricli.cli import main\nimport sys\nsys.argv = ['fricli', *sys.argv[1:]]\nmain()\n"
    env = dict(os.environ, TMPDIR=str(spool), PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", code, "predict", str(model), "-", "-o", str(tmp_path / "p.parquet")],
                            cwd=tmp_path, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdin.write(open(log, "rb").read(1000))    # part of the log; stdin stays open
    proc.stdin.flush()
    wait_until(lambda: any(spool.iterdir()), proc)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == errors.TERMINATED
    proc.stdin.close()
    assert list(spool.iterdir()) == [] and not (tmp_path / "p.parquet").exists()
