"""fricli fleet, fricli trend and simulate --fleet: a small simulated fleet end to end."""

import datetime as dt
import importlib.util
import json
import os
import shutil
import socket
import subprocess
import sys

import numpy as np
import pytest

from conftest import run_in
from fricli import models
from fricli.core import errors, logs, metrics
from fricli.fleet import history, manifest, trend

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = {**os.environ, "PYTHONPATH": ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")}
COMPARED = ["robot", "joint", "date", "status", "pipeline", "model_kind", "log_sha256", *history.PARAMETERS,
            *history.ERRORS]

needs_dask = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason="the fleet extra (dask[distributed]) is not installed")


def fricli(*args, cwd):
    """The command in a fresh process (runs that start Dask workers)."""
    return subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], cwd=cwd, env=ENV,
                          capture_output=True, text=True, timeout=300)


def invoke(*args, cwd):
    """The command in this process (commands that start no cluster): (exit code, stdout, stderr)."""
    return run_in(cwd, *args)


@pytest.fixture(scope="module")
def fleet_dir(tmp_path_factory):
    """2 robots x 2 joints x 1 day, simulated once."""
    folder = tmp_path_factory.mktemp("fleet") / "plant"
    res = invoke("simulate", "--fleet", "2x2x1", "--seed", 3, "-o", folder, cwd=folder.parent)
    assert res.returncode == 0, res.stderr
    return folder


def copy_of(fleet_dir, tmp_path, name="plant"):
    dst = tmp_path / name
    shutil.copytree(fleet_dir, dst)
    return dst


def history_rows(folder):
    table = history.read(str(folder / "history"))
    return table.select(COMPARED).sort_by([("robot", "ascending"), ("joint", "ascending"),
                                           ("date", "ascending")]).to_pylist()


def test_simulated_fleet_layout(fleet_dir):
    m = manifest.load(str(fleet_dir / "fleet.toml"))
    assert [(j.robot, j.joint, j.date) for j in m.jobs] == [
        ("robot001", "1", "2026-01-01"), ("robot001", "2", "2026-01-01"),
        ("robot002", "1", "2026-01-01"), ("robot002", "2", "2026-01-01")]
    truth = json.loads((fleet_dir / "truth.json").read_text())
    fcs = {(d["robot"], d["joint"]): d["fc"] for d in truth["daily"]}
    assert len(set(fcs.values())) == 4  # every joint its own friction


@pytest.mark.slow
@needs_dask
def test_run_skip_and_one_corrupt_log(fleet_dir, tmp_path):
    folder = copy_of(fleet_dir, tmp_path)
    first = fricli("fleet", "fleet.toml", cwd=folder)
    assert first.returncode == errors.OK, first.stderr
    assert "4 jobs: 4 ok, 0 unchanged, 0 failed" in first.stdout
    rows = history_rows(folder)
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    truth = {(d["robot"], str(d["joint"])): d for d in json.loads((folder / "truth.json").read_text())["daily"]}
    for r in rows:  # the identified Coulomb friction is the joint's own, within 5 %
        assert r["fc"] == pytest.approx(truth[(r["robot"], r["joint"])]["fc"], rel=0.05)

    # a model made by the fleet is up to date for the identify command with the same options
    log = folder / "robot001/joint1/2026-01-01.parquet"
    same = invoke("identify", log, "-o", folder / "models/robot001/joint1/2026-01-01.npz", "--joint", "1",
                  "--if-changed", cwd=folder)
    assert same.returncode == errors.UNCHANGED, same.stderr

    files = sorted((folder / "history").rglob("*.parquet"))
    second = fricli("fleet", "fleet.toml", "--json", cwd=folder)
    assert second.returncode == errors.OK, second.stderr
    assert {j["status"] for j in json.loads(second.stdout)["jobs"]} == {"unchanged"}
    assert sorted((folder / "history").rglob("*.parquet")) == files  # nothing appended

    # robot001's rows lost (a run interrupted before it wrote them): its models are up to date,
    # yet its jobs run again so that the history catches up
    shutil.rmtree(folder / "history" / "robot=robot001")
    fourth = fricli("fleet", "fleet.toml", cwd=folder)
    assert "4 jobs: 2 ok, 2 unchanged, 0 failed" in fourth.stdout, fourth.stdout + fourth.stderr
    assert [(r["robot"], r["joint"]) for r in history_rows(folder)] == [
        ("robot001", "1"), ("robot001", "2"), ("robot002", "1"), ("robot002", "2")]

    # a history part damaged (a disk full, a copy cut short): the run says so, once
    part = sorted((folder / "history" / "robot=robot002").glob("*.parquet"))[0]
    kept = part.read_bytes()
    part.write_bytes(kept[: len(kept) // 2])
    fifth = fricli("fleet", "fleet.toml", cwd=folder)
    assert fifth.returncode == errors.OK, fifth.stderr
    assert f"warning: {part}: cannot read this part of the history" in fifth.stderr, fifth.stderr
    part.write_bytes(kept)

    bad = folder / "robot002/joint2/2026-01-01.parquet"
    bad.write_bytes(b"PAR1 this is not a parquet file")
    third = fricli("fleet", "fleet.toml", cwd=folder)
    assert third.returncode == errors.SOME_FAILED, third.stderr
    assert "4 jobs: 0 ok, 3 unchanged, 1 failed" in third.stdout
    failed = [line for line in third.stdout.splitlines() if " failed " in line and "jobs:" not in line]
    assert len(failed) == 1 and failed[0].startswith("robot002     2 "), third.stdout
    assert failed[0].endswith(f"{bad}: not a Parquet file: damaged (truncated, or written only in part)"), failed[0]
    assert "Traceback" not in third.stdout + third.stderr
    rows = history.read(str(folder / "history")).to_pylist()
    assert [(r["robot"], r["joint"], r["status"]) for r in rows if r["status"] != "ok"] == [
        ("robot002", "2", "failed")]


def test_nothing_could_run(tmp_path):
    (tmp_path / "empty.toml").write_text('[[robot]]\nname = "r1"\nlogs = "nowhere/*.parquet"\njoints = [1]\n')
    res = invoke("fleet", "empty.toml", cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN and "no log matches" in res.stderr
    (tmp_path / "broken.toml").write_text("[[robot]\n")
    res = invoke("fleet", "broken.toml", cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN and res.stderr.startswith("fricli: error: ") \
        and "not valid TOML" in res.stderr and len(res.stderr.splitlines()) == 1
    (tmp_path / "typo.toml").write_text('[[robot]]\nname = "r1"\nlog = "x.parquet"\n')
    res = invoke("fleet", "typo.toml", cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN and "unknown key 'log'" in res.stderr


@needs_dask
def test_every_job_failing_is_nothing_ran(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "2026-02-01.parquet").write_bytes(b"junk")
    (tmp_path / "m.toml").write_text('[[robot]]\nname = "r1"\nlogs = "a/*.parquet"\n')
    res = fricli("fleet", "m.toml", "--workers", 1, cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN, res.stderr
    assert "1 jobs: 0 ok, 0 unchanged, 1 failed" in res.stdout


def test_missing_dask_gives_the_install_hint(fleet_dir, tmp_path):
    folder = copy_of(fleet_dir, tmp_path)
    blocker = tmp_path / "blocked" / "distributed"
    blocker.mkdir(parents=True)
    (blocker / "__init__.py").write_text("raise ImportError('blocked for the test')\n")
    env = {**ENV, "PYTHONPATH": str(blocker.parent) + os.pathsep + ENV["PYTHONPATH"]}
    res = subprocess.run([sys.executable, "-m", "fricli", "fleet", "fleet.toml"], cwd=folder, env=env,
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == errors.NOTHING_RAN
    assert res.stderr == "fricli: error: fricli fleet needs Dask: pip install 'fricli[fleet]'\n"
    assert not (folder / "history").exists()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
@needs_dask
def test_distributed_cluster_gives_the_local_history(fleet_dir, tmp_path):
    local = copy_of(fleet_dir, tmp_path, "local")
    remote = copy_of(fleet_dir, tmp_path, "remote")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = os.path.join(os.path.dirname(sys.executable), "dask")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([dask, "worker", address, "--host", "127.0.0.1", "--nthreads", "1",
                                           "--no-dashboard"], env=ENV, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout="30s") as c:  # both workers up before the run
            c.wait_for_workers(2, timeout=60)
        res = fricli("fleet", "fleet.toml", "--scheduler", address, cwd=remote)
        assert res.returncode == errors.OK, res.stderr
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
    assert fricli("fleet", "fleet.toml", cwd=local).returncode == errors.OK
    assert history_rows(remote) == history_rows(local)


@pytest.mark.slow
@needs_dask
def test_unreachable_scheduler(fleet_dir, tmp_path):
    folder = copy_of(fleet_dir, tmp_path)
    res = invoke("fleet", "fleet.toml", "--scheduler", f"tcp://127.0.0.1:{_free_port()}", "--connect-timeout", "1",
                 cwd=folder)
    assert res.returncode == errors.NOTHING_RAN
    assert "cannot reach the Dask scheduler" in res.stderr and len(res.stderr.splitlines()) == 1


@pytest.mark.parametrize("address", ["garbage", "tcp://127.0.0.1", "foo://1.2.3.4:1"])
def test_a_scheduler_address_that_is_none_is_nothing_ran(fleet_dir, tmp_path, address):
    folder = copy_of(fleet_dir, tmp_path)
    res = invoke("fleet", "fleet.toml", "--scheduler", address, cwd=folder)
    assert res.returncode == errors.NOTHING_RAN, res.stderr
    assert "cannot reach the Dask scheduler" in res.stderr and len(res.stderr.splitlines()) == 1


def test_a_history_that_is_a_file_runs_nothing(fleet_dir, tmp_path):
    """No job runs (their models would be rewritten and the history never written): 12, one line."""
    folder = copy_of(fleet_dir, tmp_path)
    shutil.rmtree(folder / "history", ignore_errors=True)
    (folder / "history").write_text("x")
    res = invoke("fleet", "fleet.toml", cwd=folder)
    assert res.returncode == errors.NOTHING_RAN and "is a file, not a folder: no job ran" in res.stderr, res.stderr
    assert not (folder / "models").exists() or not any((folder / "models").rglob("*.npz"))


def test_a_base_the_manifest_writes_is_refused(tmp_path):
    """Adapted from a model it overwrites, a job's models would drift from night to night."""
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "2026-01-02.parquet").write_bytes(b"")
    (tmp_path / "m.toml").write_text('[fleet]\npipeline = "adapt"\n[[robot]]\nname = "r1"\njoints = [2]\n'
                                     'logs = "logs/*.parquet"\nbase = "models/r1/joint2/2026-01-02.npz"\n')
    with pytest.raises(manifest.ManifestError, match="is a model a job of this manifest writes"):
        manifest.load(str(tmp_path / "m.toml"))


# ------------------------------------------------------------------ trends on made-up histories


def synthetic_history(folder, rng, days=30, wearing=(("r1", "2"),), rate=0.02, onset=10, sd=0.02):
    """One row per joint and day: fc, fv with day-to-day noise ``sd``; ``wearing`` grow by ``rate`` per day."""
    start = dt.date(2026, 3, 1)
    run_time = dt.datetime(2026, 4, 1, tzinfo=dt.timezone.utc)
    rows = []
    for robot in ("r1", "r2"):
        for joint in ("1", "2", "3"):
            grow = rate if (robot, joint) in wearing else 0.0
            for day in range(days):
                f = (1 + grow * max(0, day - onset)) * (1 + sd * rng.standard_normal(2))
                job = manifest.Job(robot=robot, joint=joint, log=f"{robot}/{joint}/{day}.parquet",
                                   date=(start + dt.timedelta(days=day)).isoformat(), pipeline="identify",
                                   model="m.npz", options=())
                rows.append(history.row(job, {"status": "ok", "kind": "lugre", "seconds": 0.1,
                                              "parameters": {"fc": 7 * f[0], "fv": 12 * f[1]},
                                              "errors": {"mae": 0.2, "rmse": 0.3, "max": 1.0}}, "run1", run_time))
    history.append(str(folder), rows, "run1")
    return folder


def test_trend_flags_the_wearing_joint_only(tmp_path, rng):
    synthetic_history(tmp_path / "h", rng)
    result = trend.trends(history.read(str(tmp_path / "h")))
    assert [(t.robot, t.joint) for t in result if t.flagged] == [("r1", "2")]
    worn = next(t for t in result if t.flagged)
    assert worn.level["fc"] == pytest.approx(0.02 * 18, abs=0.05)   # 19 days of 2 %/day from day 10, median of 3
    assert worn.growth["fc"] == pytest.approx(0.02, abs=0.004)
    growing = next(r for r in worn.reasons if "growing" in r)   # the days measured, its figure not rounded to the limit
    assert growing == f"fc growing {100 * worn.growth['fc']:.3g} %/day over the last 14 days (limit 1 %/day)"
    # a history of 12 days: the growth is measured over those, not over the 14 days of the window
    synthetic_history(tmp_path / "short", rng, days=12, onset=0)
    short = next(t for t in trend.trends(history.read(str(tmp_path / "short"))) if t.flagged)
    assert [r for r in short.reasons if "growing" in r][0].endswith(" %/day over the last 12 days (limit 1 %/day)")


def test_trend_history_keeps_units_and_reads_as_a_plain_parquet_dataset(tmp_path, rng):
    import pyarrow.dataset as ds   # any Parquet dataset reader, not fricli's own

    synthetic_history(tmp_path / "h", rng, days=3)
    table = history.read(str(tmp_path / "h"))
    assert table.schema.field("fc").metadata[b"unit"] == b"Nm"
    plain = ds.dataset(tmp_path / "h", format="parquet", partitioning="hive").to_table()
    assert plain.num_rows == 2 * 3 * 3 and {str(r) for r in plain.column("robot").to_pylist()} == {"r1", "r2"}
    assert not list((tmp_path / "h").rglob("*.tmp"))


def test_trend_one_bad_day_is_no_wear(tmp_path, rng):
    folder = synthetic_history(tmp_path / "h", rng, wearing=())
    rows = history.read(str(folder)).to_pylist()
    spike = dict(next(r for r in rows if r["robot"] == "r2" and r["joint"] == "3" and r["date"].day == 25))
    spike["fc"] *= 1.6
    spike["run_time"] = dt.datetime(2026, 4, 2, tzinfo=dt.timezone.utc)
    history.append(str(folder), [spike], "run2")   # a later run of the same day replaces it
    assert not any(t.flagged for t in trend.trends(history.read(str(folder))))


def test_trend_cli_exit_codes_json_and_figures(tmp_path, rng):
    synthetic_history(tmp_path / "h", rng)
    (tmp_path / "fig").mkdir()
    res = invoke("trend", "h", "--json", "--figures", "fig", cwd=tmp_path)
    assert res.returncode == errors.WEAR, res.stderr
    out = json.loads(res.stdout)
    assert out["flagged"] == ["r1/2"] and out["rule"]["max_level"] == 0.15
    assert [p.name for p in (tmp_path / "fig").iterdir()] == ["r1-joint2.png"]
    calm = invoke("trend", "h", "--max-level", "1", "--max-growth", "0.05", cwd=tmp_path)
    assert calm.returncode == errors.OK and "0 of 6 joints flagged" in calm.stderr
    short = tmp_path / "short"
    synthetic_history(short, rng, days=5)
    res = invoke("trend", "short", cwd=tmp_path)
    assert res.returncode == errors.OK and "too little data" in res.stdout
    # a folder that is not a history (the manifest's folder, the models): not "0 joints flagged"
    (tmp_path / "not-history").mkdir()
    (tmp_path / "not-history" / "a.parquet").write_text("hi")
    res = invoke("trend", "not-history", cwd=tmp_path)
    assert res.returncode == errors.INPUT and res.stderr.count("\n") == 1 and "not a fleet history" in res.stderr


def test_theil_sen_is_robust():
    days = np.arange(10.0)
    y = 0.5 * days
    y[3] = 100.0
    assert trend.theil_sen(days, y) == pytest.approx(0.5)


def test_job_with_diagnose_records_effects_in_process(fleet_dir, tmp_path):
    from fricli.fleet import pipelines

    folder = copy_of(fleet_dir, tmp_path)
    text = (folder / "fleet.toml").read_text().replace('pipeline = "identify"', 'pipeline = "identify"\ndiagnose = true')
    (folder / "fleet.toml").write_text(text)
    job = manifest.load(str(folder / "fleet.toml")).jobs[0]
    assert job.diagnose
    result = pipelines.run(job)
    assert result["status"] == "ok" and result["reason"] == "", result
    assert result["effects"] == []          # the daily log is exactly an extended LuGre model
    assert "model" not in result            # only plain data goes back to the client
    again = pipelines.run(job)
    assert again["status"] == "unchanged"


def test_manifest_options_over_the_command_defaults(tmp_path):
    from fricli.fitting import optionspec
    from fricli.fleet import pipelines

    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "2026-05-04.parquet").write_bytes(b"")
    (tmp_path / "m.toml").write_text('[options.identify]\ncutoff = 20\nhold = 0.5\n\n'
                                     '[[robot]]\nname = "r1"\nlogs = "logs/*.parquet"\njoints = [2]\n')
    (job,) = manifest.load(str(tmp_path / "m.toml")).jobs
    assert job.date == "2026-05-04" and job.joint == "2" and job.model.endswith("models/r1/joint2/2026-05-04.npz")
    opts = pipelines.options_of(job)
    # the options every command of the pipeline records at their defaults, with the manifest's
    assert opts == dict(optionspec.defaults("identify"), joint="2", cutoff=20.0, hold=0.5)
    assert {"kt": None, "drop_invalid": False, "travel": 0.002, "refine": False}.items() <= opts.items()
    assert isinstance(opts["cutoff"], float)


@pytest.mark.parametrize("options, needle", [
    ('samples = "foo"', "identify option samples = 'foo': expected one of auto, steady, settled"),
    ("hold = -1", "identify option hold = -1.0: expected a number > 0"),
    ("refine = 1", "identify option refine = 1: expected true or false"),
    ("travle = 1.0", "unknown identify option 'travle' (known: "),
    ("joint = 3", "option 'joint' is set by joints = [...]"),
    ("coupling = true", "option 'coupling' fits several joints into one model; a fleet job fits one joint"),
])
def test_a_wrong_manifest_option_is_one_line_naming_robot_key_and_expectation(tmp_path, options, needle):
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "2026-05-04.parquet").write_bytes(b"")
    (tmp_path / "m.toml").write_text(f'[[robot]]\nname = "r7"\nlogs = "logs/*.parquet"\noptions = {{ {options} }}\n')
    with pytest.raises(manifest.ManifestError) as info:
        manifest.load(str(tmp_path / "m.toml"))
    assert str(info.value).startswith(f"{tmp_path / 'm.toml'}: robot r7: ") and needle in str(info.value)
    res = invoke("fleet", "m.toml", cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN and len(res.stderr.splitlines()) == 1 and needle in res.stderr


@pytest.mark.parametrize("text, needle", [
    ('[fleet]\nhistroy = "h"\n', "[fleet]: unknown key 'histroy' (use diagnose, history, models, pipeline)"),
    ("[options.identfy]\nhold = 0.5\n", "[options]: unknown pipeline 'identfy' (use identify, train-base, adapt)"),
    ('[default]\nlogs = "logs/*.parquet"\n', "unknown table 'default' (use [fleet], [defaults]"),
    ("", "robot r7: joint 2 is listed twice in joints"),
])
def test_a_misspelt_manifest_name_or_a_joint_twice_stops_the_run(tmp_path, text, needle):
    """Names outside [[robot]] are checked as a robot's keys are: a misspelt one would be ignored
    (the history written elsewhere, an option not applied) and the run would say ok."""
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "2026-05-04.parquet").write_bytes(b"")
    joints = "[1, 2, 2]" if not text else "[1]"
    (tmp_path / "m.toml").write_text(f'{text}\n[[robot]]\nname = "r7"\nlogs = "logs/*.parquet"\njoints = {joints}\n')
    with pytest.raises(manifest.ManifestError) as info:
        manifest.load(str(tmp_path / "m.toml"))
    assert needle in str(info.value)
    res = invoke("fleet", "m.toml", cwd=tmp_path)
    assert res.returncode == errors.NOTHING_RAN and len(res.stderr.splitlines()) == 1 and needle in res.stderr


def test_a_robot_joint_without_logs_is_named(tmp_path):
    (tmp_path / "r1").mkdir()
    (tmp_path / "r1" / "2026-05-04-j1.parquet").write_bytes(b"")
    (tmp_path / "m.toml").write_text('[defaults]\nlogs = "{robot}/*-j{joint}.parquet"\njoints = [1, 2]\n\n'
                                     '[[robot]]\nname = "r1"\n\n[[robot]]\nname = "r2"\n')
    m = manifest.load(str(tmp_path / "m.toml"))
    assert [(j.robot, j.joint) for j in m.jobs] == [("r1", "1")]
    assert m.unmatched == ("robot r1 joint 2: no log matches r1/*-j2.parquet",
                           "robot r2 joint 1: no log matches r2/*-j1.parquet",
                           "robot r2 joint 2: no log matches r2/*-j2.parquet")
    res = invoke("fleet", "m.toml", "--list", cwd=tmp_path)
    assert res.returncode == 0 and "warning: robot r2 joint 1: no log matches r2/*-j1.parquet" in res.stderr
    listed = invoke("fleet", "m.toml", "--list", "--json", cwd=tmp_path)     # the listing as JSON, not TSV
    assert listed.returncode == 0, listed.stderr
    jobs = json.loads(listed.stdout)["jobs"]
    assert [(j["robot"], j["joint"], j["date"], j["pipeline"]) for j in jobs] == [("r1", "1", "2026-05-04", "identify")]


def test_two_logs_of_one_name_for_one_joint_fail_naming_each_other(tmp_path):
    """Logs of one robot joint found by two globs under the same file name would write one model
    file: each night the two jobs would overwrite each other's model and neither would be up to date.
    Both jobs fail, each naming the other log; the robot's other jobs are not touched."""
    from fricli.fleet import pipelines

    for folder in ("incoming", "archive"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "2026-05-04-j1.parquet").write_bytes(folder.encode())
    (tmp_path / "incoming" / "2026-05-05-j1.parquet").write_bytes(b"x")
    (tmp_path / "m.toml").write_text('[[robot]]\nname = "r1"\njoints = [1]\n'
                                     'logs = ["incoming/*-j{joint}.parquet", "archive/*-j{joint}.parquet"]\n')
    jobs = manifest.load(str(tmp_path / "m.toml")).jobs
    assert [os.path.relpath(j.log, tmp_path) for j in jobs] == [
        "archive/2026-05-04-j1.parquet", "incoming/2026-05-04-j1.parquet", "incoming/2026-05-05-j1.parquet"]
    assert [os.path.relpath(j.clash, tmp_path) if j.clash else "" for j in jobs] == [
        "incoming/2026-05-04-j1.parquet", "archive/2026-05-04-j1.parquet", ""]
    for job in jobs[:2]:
        res = pipelines.run(job)
        assert res["status"] == "failed" and job.clash in res["reason"] and "same file name" in res["reason"]
        assert not os.path.exists(job.model)
    assert "same file name" not in pipelines.run(jobs[2])["reason"]
    res = invoke("fleet", "m.toml", "--list", cwd=tmp_path)
    assert res.returncode == 0 and res.stdout.count("2026-05-04-j1") == 4


# A fleet job and the command make the same model from the same log and options: every pipeline,
# every joint of a two-joint log (the command writes the joints into a folder).
SAME_RUNS = {"identify": ({"hold": 0.3}, ["--hold", "0.3"]),
             "train-base": ({"steps": 15, "max_samples": 200, "hidden": "4,4", "seed": 2},
                            ["--steps", "15", "--max-samples", "200", "--hidden", "4,4", "--seed", "2"]),
             "adapt": ({"epochs": 2, "hidden": "3,3"}, ["--epochs", "2", "--hidden", "3,3"])}


@pytest.mark.parametrize("pipeline", sorted(SAME_RUNS))
def test_fleet_job_and_command_write_the_same_bytes(tmp_path, pipeline):
    from test_joints import write_log

    from fricli.fleet import pipelines

    log = write_log(tmp_path / "arm.parquet", [2, 4])
    given, flags = SAME_RUNS[pipeline]
    bases = tmp_path / "bases"
    args = []
    if pipeline == "adapt":
        assert invoke("identify", log, "-o", bases, "-q", cwd=tmp_path).returncode == 0
        args = [bases]
    res = invoke(pipeline, *args, log, "-o", tmp_path / "cmd", *flags, "-q", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    for joint in ("2", "4"):
        job = manifest.Job(robot="r1", joint=joint, log=log, date="2026-01-01", pipeline=pipeline,
                           model=str(tmp_path / "fleet" / f"joint{joint}.npz"), options=tuple(sorted(given.items())),
                           base=str(bases / f"joint_{joint}.npz") if pipeline == "adapt" else None)
        result = pipelines.run(job)
        assert result["status"] == "ok", result
        # the history's error figures: over the rows in motion, whatever the pipeline
        data = logs.load_log(log, joint=joint)
        model = models.load(job.model)[0]
        moving = metrics.in_motion(data.signals["qd"])
        want = metrics.errors(logs.friction_target(data.signals)[moving], model.predict(data.signals)[0][moving])
        assert result["errors"] == pytest.approx(want)
        command_file = tmp_path / "cmd" / f"joint_{joint}.npz"
        assert (tmp_path / "fleet" / f"joint{joint}.npz").read_bytes() == command_file.read_bytes()
    # and each is up to date for the other
    again = invoke(pipeline, *args, log, "-o", tmp_path / "fleet" / "joint4.npz", "--joint", "4", *flags,
                   "--if-changed", cwd=tmp_path)
    assert again.returncode == errors.UNCHANGED, again.stderr


def test_the_fleet_prints_the_warnings_identify_prints(tmp_path):
    """A log on which identify warns (joint4_extended_asym with three 40 Nm spikes in tau_m, which the
    static curve cannot follow): the fleet prints the same warning, named by robot, joint and date, and
    keeps it in --json."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from conftest import SAMPLE

    (tmp_path / "logs").mkdir()
    table = pq.read_table(SAMPLE / "joint4_extended_asym.parquet")
    k = table.column_names.index("tau_m")
    tau_m = table.column(k).to_numpy().copy()
    tau_m[[3000, 6000, 9000]] += 40.0
    pq.write_table(table.set_column(k, table.schema.field(k), pa.array(tau_m)),
                   tmp_path / "logs" / "2026-05-04.parquet")
    (tmp_path / "m.toml").write_text('[[robot]]\nname = "r1"\nlogs = "logs/*.parquet"\njoints = [4]\n')
    command = invoke("identify", tmp_path / "logs" / "2026-05-04.parquet", "-o", tmp_path / "one.npz", "-q",
                     cwd=tmp_path)
    said = [line.removeprefix("warning: ") for line in command.stderr.splitlines() if line.startswith("warning: ")]
    assert said
    res = invoke("fleet", "m.toml", "--json", "-q", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert [line for line in res.stderr.splitlines() if line.startswith("warning: ")] == \
        [f"warning: r1 joint 4 2026-05-04: {line}" for line in said]
    assert json.loads(res.stdout)["jobs"][0]["warnings"] == said


def test_simulate_fleet_never_writes_over_a_users_folder(tmp_path):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "fleet.toml").write_text("my manifest")
    (tmp_path / "a-file").write_text("mine too")
    for target in (mine, tmp_path / "a-file", tmp_path / "a-file" / "sub"):
        res = invoke("simulate", "--fleet", "1x1x1", "-o", target, cwd=tmp_path)
        assert res.returncode == errors.OUTPUT and res.stderr.startswith("fricli: error: "), res.stderr
    assert (mine / "fleet.toml").read_text() == "my manifest" and sorted(p.name for p in mine.iterdir()) == ["fleet.toml"]
    assert (tmp_path / "a-file").read_text() == "mine too"


def test_a_gms_models_history_keeps_its_steady_sliding_curve(fleet_dir, tmp_path):
    """identify --kind gms in the fleet: the history's fc, fs are the model's steady-sliding levels
    (``GMSModel.steady_parameters``), not the share of the Coulomb level a fit left outside the elements."""
    from fricli.fleet import pipelines

    folder = copy_of(fleet_dir, tmp_path)
    (folder / "fleet.toml").write_text((folder / "fleet.toml").read_text() + '\n[options.identify]\nkind = "gms"\n')
    job = manifest.load(str(folder / "fleet.toml")).jobs[0]
    result = pipelines.run(job)
    assert result["status"] == "ok" and result["kind"] == "gms", result
    model, _ = models.load(job.model)
    steady = model.steady_parameters()
    assert result["parameters"] == steady and steady["fc"] >= model.fc + model.force.sum()


@needs_dask
@pytest.mark.skipif(importlib.util.find_spec("pty") is None or not hasattr(os, "fork"), reason="no pseudo-terminal")
def test_on_a_terminal_the_progress_bar_is_drawn_and_cleared_before_the_table(fleet_dir, tmp_path):
    """Run in a pseudo-terminal of 100 columns (stdout and stderr a terminal): the bar over the jobs
    is drawn on stderr and wiped before the table, which starts a clean line."""
    import fcntl
    import pty
    import struct
    import termios

    folder = copy_of(fleet_dir, tmp_path)
    pid, fd = pty.fork()
    if pid == 0:   # the child: a terminal of 24 x 100, then the command
        try:
            fcntl.ioctl(1, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
            os.chdir(folder)
            os.execve(sys.executable, [sys.executable, "-m", "fricli", "fleet", "fleet.toml"], ENV)
        finally:
            os._exit(127)
    out = bytearray()
    while True:
        try:
            data = os.read(fd, 4096)
        except OSError:    # the child closed the terminal
            break
        if not data:
            break
        out.extend(data)
    _, status = os.waitpid(pid, 0)
    text = out.decode("utf-8", "replace")
    assert os.waitstatus_to_exitcode(status) == errors.OK, text
    bar, table = text.split("robot        joint", 1)
    assert "fleet:" in bar and "/4 [" in bar and "job/s" in bar, text    # tqdm's bar over the 4 jobs
    pieces = bar.split("\r")
    assert pieces[-1] == "" and pieces[-2].strip() == "" and len(pieces[-2]) >= 50, repr(bar[-200:])   # wiped
    assert "4 jobs: 4 ok" in table and "fleet:" not in table


def test_the_scratch_folder_of_a_killed_run_is_removed_by_the_next(tmp_path):
    """A run killed with SIGKILL cannot remove its cluster's scratch folder; the next run removes
    it: old enough, and locked by no process (a live run holds its folder's lock)."""
    import fcntl
    import os
    import time

    from fricli.fleet import run

    dead, live, young = (tmp_path / f"{run.SCRATCH_PREFIX}{name}" for name in ("dead", "live", "young"))
    for folder in (dead, live, young):
        (folder / "dask-scratch-space").mkdir(parents=True)
    old = time.time() - 2 * run.SCRATCH_AGE
    for folder in (dead, live):
        os.utime(folder, (old, old))
    held = os.open(live, os.O_RDONLY)
    fcntl.flock(held, fcntl.LOCK_EX)
    try:
        assert run.remove_stale_scratch(str(tmp_path)) == [str(dead)]
    finally:
        os.close(held)
    assert not dead.exists() and live.exists() and young.exists()


def test_a_baseline_too_short_to_flag_anything_is_refused(tmp_path, rng):
    """A baseline is the median of at least 3 days' values: --baseline-days 1 or 2 would leave every
    joint "too little data" and switch the alarm off without a word."""
    from fricli.cli import cli as group

    synthetic_history(tmp_path / "h", rng)
    option = next(p for p in group.get_command(None, "trend").params if p.name == "baseline_days")
    assert option.type.min == trend.MIN_BASELINE_DAYS
    res = invoke("trend", "h", "--baseline-days", "2", cwd=tmp_path)
    assert res.returncode == errors.USAGE and "--baseline-days" in res.stderr
    from fricli import fleet_trend

    with pytest.raises(errors.OptionError):
        fleet_trend(str(tmp_path / "h"), baseline_days=2)


def test_a_damaged_history_part_is_named_in_one_line(tmp_path, rng):
    """Columns of another type, missing dates, dates out of range: 3 (INPUT) naming the file."""
    import glob

    import pyarrow as pa
    import pyarrow.parquet as pq

    for change in (lambda t: t.set_column(t.schema.get_field_index("fc"), "fc", pa.array(["x"] * t.num_rows)),
                   lambda t: t.set_column(t.schema.get_field_index("date"), "date", pa.nulls(t.num_rows, pa.date32())),
                   lambda t: t.set_column(t.schema.get_field_index("date"), "date",
                                          pa.array([-800000] * t.num_rows, pa.date32()))):
        folder = tmp_path / f"h{len(list(tmp_path.iterdir()))}"
        synthetic_history(folder, rng)
        part = sorted(glob.glob(str(folder / "robot=*" / "*.parquet")))[0]
        pq.write_table(change(pq.read_table(part)), part)
        res = invoke("trend", folder.name, cwd=tmp_path)
        assert res.returncode == errors.INPUT and res.stderr.count("\n") == 1, res.stderr
        assert f"{part}: not a fricli history file" in res.stderr or "not a fricli history file" in res.stderr
