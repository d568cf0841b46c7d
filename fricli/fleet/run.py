"""Run a manifest's jobs on Dask (``dask.distributed``): a local cluster sized to the machine by
default, or an existing scheduler. Each job runs ``fricli.fleet.pipelines.run`` on a worker;
the results are appended to the history here, on the client."""

from __future__ import annotations

import contextlib
import dataclasses
import datetime as dt
import fcntl
import os
import re
import secrets
import shutil
import sys
import tempfile
import time
from typing import Callable, Iterator

from fricli.core import errors
from fricli.fleet import history, pipelines
from fricli.fleet.manifest import Manifest

INSTALL_HINT = "fricli fleet needs Dask: pip install 'fricli[fleet]'"
# One BLAS thread per worker process: the processes are the parallelism.
_SINGLE_THREADED = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


class ClusterError(errors.FricliError):
    """Dask is missing or the cluster cannot be reached: nothing can run."""

    exit_code = errors.NOTHING_RAN


@dataclasses.dataclass
class Outcome:
    """A run: every job with its result, the history files written, the exit code for cron."""

    run: str
    jobs: list
    results: list
    written: list
    warnings: list = dataclasses.field(default_factory=list)   # lines for stderr

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.results)

    @property
    def exit_code(self) -> int:
        failed = self.count("failed")
        if not self.results or failed == len(self.results):
            return errors.NOTHING_RAN
        return errors.SOME_FAILED if failed else errors.OK


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ClusterError(INSTALL_HINT) from None
    return distributed


CONNECT_TIMEOUT = 10.0   # s: how long a run waits for a scheduler it is given
SCHEDULER_ADDRESS = re.compile(r"((tcp|tls|ucx|ws|wss)://)?(\[[0-9A-Fa-f:.]+\]|[^\s:/\[\]]+):\d{1,5}")


@contextlib.contextmanager
def client(scheduler: str | None = None, workers: int | None = None, timeout: float = CONNECT_TIMEOUT) -> Iterator:
    """A ``distributed.Client``: on ``scheduler`` (an address such as tcp://10.0.0.5:8786, waited for
    ``timeout`` seconds) or on a local cluster of ``workers`` single-threaded processes (default: one
    per core)."""
    distributed = _distributed()
    if scheduler:
        if not SCHEDULER_ADDRESS.fullmatch(scheduler):   # distributed's own errors for these vary
            raise ClusterError(f"cannot reach the Dask scheduler {scheduler}: not an address of the form "
                               "[tcp://]HOST:PORT (tls://, ucx://, ws://, wss:// too)")
        try:
            c = distributed.Client(scheduler, timeout=f"{timeout:g}s")
        except (OSError, TimeoutError, ValueError) as exc:   # ValueError: e.g. a port beyond 65535
            raise ClusterError(f"cannot reach the Dask scheduler {scheduler}: {errors.one_line(str(exc))}") from None
        with c:
            yield c
        return
    import logging

    logging.getLogger("distributed").setLevel(logging.ERROR)  # its shutdown warnings are not ours to show
    n = workers or os.cpu_count() or 1
    import warnings

    # a fleet killed with SIGKILL leaves multiprocessing's resource tracker to clean up the cluster's
    # semaphores, which it does with a warning of several lines on stderr: nothing for the user to do.
    # The tracker is started with the interpreter's -W options, so this is where it is told.
    quiet_tracker = "ignore:resource_tracker:UserWarning"
    if quiet_tracker not in sys.warnoptions:
        sys.warnoptions.append(quiet_tracker)
    # the workers' scratch space (and its lock files) in a folder of this run, removed at its end:
    # Dask's default, dask-scratch-space in $TMPDIR, keeps lock files after the cluster closes
    remove_stale_scratch()
    scratch = tempfile.mkdtemp(prefix=SCRATCH_PREFIX)
    held = os.open(scratch, os.O_RDONLY)
    fcntl.flock(held, fcntl.LOCK_EX)   # this run's, until its end (``remove_stale_scratch``)
    import dask

    try:
        with dask.config.set({"temporary-directory": scratch}), warnings.catch_warnings():  # "port 8787 in use" of its HTTP server: nothing for the user to do
            warnings.simplefilter("ignore", UserWarning)
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               dashboard_address=None, host="127.0.0.1", env=_SINGLE_THREADED,
                                               local_directory=scratch,
                                               preload=["fricli.fleet.worker"])   # Ctrl-C, logging
        with dask.config.set({"temporary-directory": scratch}), cluster, distributed.Client(cluster) as c:
            yield c
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        os.close(held)


SCRATCH_PREFIX = "fricli-dask-"
SCRATCH_AGE = 60.0   # s: a scratch folder is locked by its run this long after its creation at the latest


def remove_stale_scratch(folder: str | None = None) -> list[str]:
    """Remove the scratch folders in ``folder`` (default $TMPDIR) of local clusters whose run was
    killed with SIGKILL: older than SCRATCH_AGE and locked by no process (a run holds an exclusive
    ``flock`` on its folder until it ends; the kernel drops a dead process's). Returns those removed."""
    import glob

    removed = []
    for path in glob.glob(os.path.join(folder or tempfile.gettempdir(), SCRATCH_PREFIX + "*")):
        try:
            if time.time() - os.stat(path).st_mtime < SCRATCH_AGE:
                continue
            fd = os.open(path, os.O_RDONLY)
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # fails while its run holds it
            shutil.rmtree(path, ignore_errors=True)
            removed.append(path)
        except OSError:
            pass
        finally:
            os.close(fd)
    return removed


def run_id(now: dt.datetime) -> str:
    return f"{now:%Y%m%dT%H%M%SZ}-{secrets.token_hex(3)}"


def run(manifest: Manifest, *, scheduler: str | None = None, workers: int | None = None,
        if_changed: bool = True, on_done: Callable[[int, int], None] | None = None,
        connect_timeout: float = CONNECT_TIMEOUT) -> Outcome:
    """Run every job of ``manifest`` and append the rows of the jobs that ran to its history.
    A job whose model is up to date but whose history row is missing (an interrupted run, a
    history that could not be written) runs again, so the history catches up.

    ``on_done(done, total)`` is called as jobs finish (for a progress bar); ``connect_timeout``:
    the seconds to wait for ``scheduler``. One run of a manifest
    at a time: the run holds the lock on the manifest (``.NAME.lock`` beside it) from its start to
    its end; a second run of the same manifest raises LockedError at once and touches nothing."""
    from fricli.core import jobs as joblock

    try:
        lock = joblock.output_lock(manifest.path)
        lock.__enter__()
    except errors.LockedError:
        raise errors.LockedError(f"{manifest.path} is being run by another fricli fleet job; this run did "
                                 "nothing") from None
    try:
        return _run(manifest, scheduler=scheduler, workers=workers, if_changed=if_changed, on_done=on_done,
                    timeout=connect_timeout)
    except BaseException:
        lock.__exit__(*sys.exc_info())
        raise
    else:
        lock.__exit__(None, None, None)


def _run(manifest: Manifest, *, scheduler, workers, if_changed: bool, on_done, timeout: float) -> Outcome:
    from fricli.fleet.manifest import ManifestError

    if os.path.exists(manifest.history) and not os.path.isdir(manifest.history):
        raise ManifestError(f"the history {manifest.history} is a file, not a folder: no job ran (move the file "
                            "away, or give [fleet] history another name)")
    now = dt.datetime.now(dt.timezone.utc).replace(microsecond=0)
    run = run_id(now)
    jobs = list(manifest.jobs)
    results: list = [None] * len(jobs)
    warnings = []
    if jobs:
        with client(scheduler, workers, timeout) as c:
            _run_jobs(c, jobs, range(len(jobs)), results, if_changed, on_done)
            try:
                recorded = _recorded(manifest.history)
            except errors.FricliError as exc:    # the run goes on; what reads the history will fail
                recorded = None
                warnings.append(f"warning: {exc}: the history cannot be read, so the jobs whose rows it lacks "
                                "do not run again, and fricli trend fails on it; move that file away")
            again = [i for i, res in enumerate(results) if res["status"] == "unchanged" and recorded is not None
                     and (jobs[i].robot, str(jobs[i].joint), res["sha256"]) not in recorded]
            if again:
                _run_jobs(c, jobs, again, results, False, on_done)
    rows = [history.row(job, res, run, now) for job, res in zip(jobs, results) if res["status"] != "unchanged"]
    written = history.append(manifest.history, rows, run) if rows else []
    return Outcome(run=run, jobs=jobs, results=results, written=written, warnings=warnings)


def _run_jobs(c, jobs: list, which, results: list, if_changed: bool, on_done) -> None:
    """Run ``jobs[i]`` for i in ``which`` on client ``c`` into ``results[i]``."""
    distributed = _distributed()
    futures = c.map(pipelines.run, [jobs[i] for i in which], if_changed=if_changed, pure=False)
    index = {f.key: i for f, i in zip(futures, which)}
    for done, future in enumerate(distributed.as_completed(futures), 1):
        i = index[future.key]
        try:
            results[i] = future.result()
        except Exception as exc:  # the worker died or the task could not be sent
            results[i] = {"status": "failed", "seconds": float("nan"),
                          "reason": errors.one_line(f"worker lost the job: {type(exc).__name__}: {exc}")}
        if on_done:
            on_done(done, len(futures))


def _recorded(path: str) -> set:
    """(robot, joint, log sha256) of the history's ok rows: empty without a history yet; the
    history's error when it cannot be read."""
    if not os.path.isdir(path):
        return set()
    table = history.read(path)
    cols = [table.column(c).to_pylist() for c in ("robot", "joint", "log_sha256", "status")]
    return {(r, str(j), h) for r, j, h, status in zip(*cols) if status == "ok"}


def table(outcome: Outcome) -> str:
    """Every job and its status, one per line, and a summary line."""
    name = lambda x: errors.one_line(str(x))   # noqa: E731 - names quoted from the manifest, one line each
    rw = max([12] + [len(name(job.robot)) for job in outcome.jobs])
    jw = max([6] + [len(name(job.joint or "-")) for job in outcome.jobs])
    lines = [f"{'robot':<{rw}} {'joint':<{jw}} {'date':<10}  {'status':<9} {'s':>6}  reason"]
    for job, res in sorted(zip(outcome.jobs, outcome.results), key=lambda p: (p[0].robot, p[0].joint, p[0].log)):
        sec = res.get("seconds")
        sec = f"{sec:6.2f}" if sec == sec and sec is not None else "     -"
        lines.append(f"{name(job.robot):<{rw}} {name(job.joint or '-'):<{jw}} {job.date:<10}  {res['status']:<9} {sec}  "
                     f"{name(res.get('reason', ''))}".rstrip())
    lines.append(f"{len(outcome.jobs)} jobs: {outcome.count('ok')} ok, {outcome.count('unchanged')} unchanged, "
                 f"{outcome.count('failed')} failed")
    return "\n".join(lines)


@dataclasses.dataclass
class FleetRun:
    """``run_fleet``'s result: the ``manifest``, its ``jobs``, the run's ``outcome`` (None with
    ``list_only``) and the ``warnings`` (lines the command prints on stderr)."""

    manifest: Manifest
    outcome: Outcome | None
    warnings: list

    @property
    def jobs(self) -> list:
        return self.manifest.jobs

    @property
    def run_warnings(self) -> list:
        """The warnings of the jobs' run: those after the manifest's, which ``run_fleet`` handed to
        ``warn`` as it read the manifest."""
        return self.warnings[len(self.manifest.unmatched):]

    @property
    def exit_code(self) -> int:
        """The command's: OK, SOME_FAILED or NOTHING_RAN (OK for a listing)."""
        return errors.OK if self.outcome is None else self.outcome.exit_code

    def listing(self) -> str:
        """What ``fricli fleet --list`` prints: a tab-separated line per job (robot, joint, date,
        pipeline, log, model)."""
        return "\n".join("\t".join(errors.one_line(str(x)) for x in (j.robot, j.joint, j.date, j.pipeline, j.log,
                                                                      j.model)) for j in self.jobs)

    def table(self) -> str:
        """The table ``fricli fleet`` prints at the end of a run."""
        return table(self.outcome)

    def as_json(self) -> dict:
        """What ``fricli fleet --json`` prints (with ``--list``: the jobs, as ``listing``)."""
        o = self.outcome
        if o is None:
            return {"jobs": [{"robot": j.robot, "joint": j.joint, "date": j.date, "pipeline": j.pipeline, "log": j.log,
                              "model": j.model} for j in self.jobs]}
        return {"run": o.run, "history": o.written, "exit_code": o.exit_code,
                "jobs": [{"robot": j.robot, "joint": j.joint, "date": j.date, "log": j.log, "model": j.model,
                          "status": r["status"], "reason": r.get("reason", ""), "seconds": r.get("seconds"),
                          "warnings": r.get("warnings", [])} for j, r in zip(o.jobs, o.results)]}


def run_fleet(manifest: str, *, scheduler: str | None = None, connect_timeout: float = CONNECT_TIMEOUT,
              workers: int | None = None, force: bool = False, list_only: bool = False, allow_outside: bool = False,
              warn: Callable[[str], None] | None = None,
              on_done: Callable[[int, int], None] | None = None) -> FleetRun:
    """``fricli fleet MANIFEST``: every job of the manifest file ``manifest`` (docs/fleet.md) run on
    Dask (``scheduler`` an address, waited for ``connect_timeout`` [s] > 0; else a local cluster of
    ``workers`` >= 1 processes), each model refreshed unless up to date (``force``: every one), the
    history appended (``on_done(0, jobs)`` first, then as jobs finish); with ``list_only`` the jobs
    only (no Dask needed). ``warn(line)`` gets the manifest's warnings as it is read. Returns a
    ``FleetRun`` (``as_json()``, ``table()``, ``listing()``: what the command prints; ``exit_code``;
    the warnings). OptionError naming a wrong option; ManifestError when no log matches."""
    from fricli.fitting.optionspec import Option, check_values
    from fricli.fleet import manifest as mf

    check_values({"connect_timeout": connect_timeout, "workers": workers},
                 {"connect_timeout": Option("connect_timeout", "float", CONNECT_TIMEOUT, low=0.0, low_open=True),
                  "workers": Option("workers", "int", low=1)}, "fleet")
    m = mf.load(os.fspath(manifest), allow_outside=allow_outside)
    found = [f"warning: {line}" for line in m.unmatched]   # a robot dropping out of a nightly run must not go unnoticed
    for line in found:
        if warn:
            warn(line)
    if list_only:
        return FleetRun(m, None, found)
    if not m.jobs:
        raise mf.ManifestError(f"{manifest}: no log matches the manifest's globs")
    if on_done:
        on_done(0, len(m.jobs))
    outcome = run(m, scheduler=scheduler, workers=workers, if_changed=not force, on_done=on_done,
                  connect_timeout=connect_timeout)
    late = list(outcome.warnings) + [f"warning: {job.robot} joint {job.joint or '-'} {job.date}: {line}"
                                     for job, res in zip(outcome.jobs, outcome.results)
                                     for line in res.get("warnings", [])]
    return FleetRun(m, outcome, found + late)
