"""Inputs a reliability sweep threw at fricli: devices, pipes and endless stdin, a log too long for
identify's memory, decompression bombs, model files with parameters of the wrong type or range,
negative URDF inertias. Each is one line on stderr with its documented exit code, no traceback."""

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from conftest import ROOT
from fricli import models
from fricli.cli import cli
from fricli.core import errors, files, logs, modelfile
from fricli.fitting import runs
from fricli.models.lugre import LuGreModel

PARAMS = dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0)


def one_error_line(result, code, text):
    assert result.exit_code == code, (result.exit_code, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fricli: error: "), result.stderr
    assert text in lines[0], lines[0]
    assert "Traceback" not in result.stderr


@pytest.fixture
def model(tmp_path):
    path = tmp_path / "lugre.npz"
    models.save(str(path), LuGreModel(**PARAMS), joint=None, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    return path


def log_file(tmp_path, n=4000):
    t = np.arange(n) * 0.01
    qd = np.sin(t)
    table = logs.table_from_arrays({"t": t, "q": np.cumsum(qd) * 0.01, "qd": qd, "tau_m": 5 * np.sign(qd) + qd,
                                    "tau_g": np.zeros(n), "tau_dyn": np.zeros(n)},
                                   {"t": "s", "q": "rad", "qd": "rad/s", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm"})
    path = tmp_path / "log.parquet"
    pq.write_table(table, path)
    return path


def fricli(args, cwd, prelude="", env=None, **kwargs):
    code = prelude + "from fricli.cli import main\nimport sys\nsys.argv = ['fricli', *sys.argv[1:]]\nmain()\n"
    env = env or dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    return subprocess.Popen([sys.executable, "-c", code, *map(str, args)], cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


# ------------------------------------------------------------------ devices, pipes, stdin


def finish(proc, timeout: float, why: str) -> str:
    """The stderr of ``proc`` once it ends; the test fails with ``why`` if it runs past ``timeout`` s."""
    try:
        return proc.communicate(timeout=timeout)[1]
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        pytest.fail(why)


@pytest.mark.parametrize("where", ["log", "model"])
def test_a_device_or_a_named_pipe_is_refused_before_it_is_read(tmp_path, model, where):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    log = log_file(tmp_path)
    for path in ("/dev/zero", str(fifo)):
        args = ["predict", str(model), path] if where == "log" else ["predict", path, str(log)]
        proc = fricli([*args, "-o", "out.parquet"], tmp_path)
        err = finish(proc, 60, f"{path} as {where} was read without end")   # a FIFO without a writer would block its open
        code = errors.INPUT if where == "log" else errors.MODEL
        assert proc.returncode == code, err
        assert err.splitlines() == [f"fricli: error: {path}: is {'a device' if path == '/dev/zero' else 'a named pipe'}"
                                    f", not a regular file; fricli reads a {'log' if where == 'log' else 'model file'} "
                                    "only from a regular file (or - for stdin)"], err
        assert not (tmp_path / "out.parquet").exists()


def test_an_endless_stdin_is_refused_at_the_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(files, "STDIN_LIMIT", 1 << 16)
    res = CliRunner().invoke(cli, ["identify", "-", "-o", str(tmp_path / "m.npz")], input=b"\0" * (1 << 17))
    one_error_line(res, errors.INPUT, f"stdin: more than {1 << 16:,} bytes on stdin (the limit)")
    assert not (tmp_path / "m.npz").exists()


def test_a_spooled_stdin_is_refused_at_its_limit(tmp_path, model, monkeypatch):
    monkeypatch.setattr(files, "SPOOL_LIMIT", 1 << 16)
    res = CliRunner().invoke(cli, ["predict", str(model), "-", "-o", str(tmp_path / "o.parquet")],
                             input=b"\0" * (1 << 17))
    one_error_line(res, errors.INPUT, f"stdin: more than {1 << 16:,} bytes on stdin (the limit)")


def test_stdin_from_a_device_stops_at_the_limit(tmp_path):
    """stdin is /dev/zero: without a limit the read grows until memory runs out."""
    with open("/dev/zero", "rb") as zero:
        proc = fricli(["identify", "-", "-o", "m.npz"], tmp_path, stdin=zero,
                      prelude="import fricli.core.files as f\nf.STDIN_LIMIT = 1 << 22\n")
        err = finish(proc, 60, "an endless stdin was read without end")
    assert proc.returncode == errors.INPUT, err
    assert err.splitlines() == [f"fricli: error: stdin: more than {1 << 22:,} bytes on stdin (the limit); write the "
                                "input to a file and give its path"]


def _bytes_read(pid: int) -> int:
    with open(f"/proc/{pid}/io") as fh:
        return next(int(line.split()[1]) for line in fh if line.startswith("rchar:"))


@pytest.mark.skipif(not os.path.exists("/proc/self/io"), reason="reads /proc/PID/io (Linux)")
def test_sigterm_is_honoured_while_an_endless_stdin_is_read(tmp_path):
    """stdin is /dev/urandom, which never blocks: a read of the whole stream in one call runs no
    signal handler until it returns, which it never does. SIGTERM once the read is under way."""
    with open("/dev/urandom", "rb") as endless:
        proc = fricli(["identify", "-", "-o", "m.npz"], tmp_path, stdin=endless)
        deadline = time.monotonic() + 60
        while proc.poll() is None and _bytes_read(proc.pid) < 64 << 20 and time.monotonic() < deadline:
            time.sleep(0.01)
        proc.send_signal(signal.SIGTERM)
        err = finish(proc, 10, "SIGTERM was not honoured while stdin was read")
    assert proc.returncode == errors.TERMINATED, err
    assert err.splitlines() == ["fricli: terminated"]


def test_a_model_named_dash_says_models_are_not_read_from_stdin(tmp_path):
    log = log_file(tmp_path)
    res = CliRunner().invoke(cli, ["predict", "-", str(log), "-o", str(tmp_path / "o.parquet")])
    one_error_line(res, errors.MODEL, "-: a model is read from a file, not from stdin")


# ------------------------------------------------------------------ identify's memory


def test_identify_refuses_a_log_longer_than_its_memory_limit(tmp_path, monkeypatch):
    log = log_file(tmp_path)
    monkeypatch.setattr(runs, "IDENTIFY_MAX_ROWS", 1000)
    res = CliRunner().invoke(cli, ["identify", str(log), "-o", str(tmp_path / "m.npz")])
    one_error_line(res, errors.DATA, "4,000 rows of one joint; identify fits at most 1,000 (about ")
    assert "--from, --until" in res.stderr
    assert not (tmp_path / "m.npz").exists()


def test_identify_limit_counts_the_rows_of_one_joint(tmp_path):
    table = pa.table({"joint": pa.array([1, 2] * 600), "t": pa.array(np.arange(1200.0))})
    runs.check_rows(table, "x", 600)       # 600 rows a joint: within
    with pytest.raises(errors.DataError, match="601 rows of one joint"):
        runs.check_rows(pa.table({"joint": pa.array([1] * 601 + [2]), "t": pa.array(np.arange(602.0))}), "x", 600)


def test_the_identify_limit_holds_within_two_gigabytes():
    assert runs.IDENTIFY_MAX_ROWS * runs.IDENTIFY_BYTES_PER_ROW <= 2 << 30
    assert runs.IDENTIFY_MAX_ROWS < 10_000_000


# ------------------------------------------------------------------ model files


def rewrite(path, change):
    meta, arrays = modelfile.read(str(path))
    change(meta, arrays)
    modelfile.write(str(path), meta, arrays)


def test_a_decompression_bomb_is_refused_relative_to_the_file_size(model):
    meta, arrays = modelfile.read(str(model))
    arrays["pad"] = np.zeros(40 << 17)            # 40 MiB of zeros: a few tens of kB deflated
    data = modelfile.dumps(meta, arrays)
    assert len(data) < 1 << 20
    with pytest.raises(errors.ModelFileError, match=r"its entries unpack to 41,94\d,\d+ bytes, more than"):
        modelfile.loads(data, "bomb.npz")
    assert modelfile.decompressed_limit(len(data)) < 40 << 20


@pytest.mark.parametrize("change, text", [
    (lambda m: m["model"]["params"].update(fc="7.0"), "parameter 'fc' is str '7.0', not a number"),
    (lambda m: m["model"]["params"].update(fc=True), "parameter 'fc' is bool True, not a number"),
    (lambda m: m["model"]["params"].update(fc=-5.0), "fc = -5 is negative"),
    (lambda m: m["model"]["params"].update(fv=-1.0), "fv = -1 is negative"),
    (lambda m: m.update(kind="linear"), "its kind 'linear' disagrees with its model spec's 'lugre'"),
    (lambda m: m.update(format_version="1"), 'model format version "1" is not supported (this fricli reads version 1)'),
    (lambda m: m.update(format_version=True), "model format version true is not supported"),
    (lambda m: m.update(format_version=1.0), "model format version 1.0 is not supported"),
])
def test_model_parameters_are_checked_against_the_spec(tmp_path, model, change, text):
    rewrite(model, lambda meta, arrays: change(meta))
    log = log_file(tmp_path)
    res = CliRunner().invoke(cli, ["predict", str(model), str(log), "-o", str(tmp_path / "o.parquet")])
    one_error_line(res, errors.MODEL, text)
    assert not (tmp_path / "o.parquet").exists()


def test_a_linear_model_with_a_string_parameter_is_refused(tmp_path):
    from fricli.models.linear import LinearFriction

    path = tmp_path / "lin.npz"
    models.save(str(path), LinearFriction(1.0, 2.0), joint=None, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    rewrite(path, lambda meta, arrays: meta["model"]["params"].update(fv="1"))
    with pytest.raises(errors.ModelFileError, match="parameter 'fv' is str '1', not a number"):
        models.load(str(path))


# ------------------------------------------------------------------ URDF


@pytest.mark.parametrize("inertia, text", [
    ('ixx="-5" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"', "ixx -5 kg m^2: a moment of inertia is not negative"),
    ('ixx="1" ixy="3" ixz="0" iyy="1" iyz="0" izz="1"', "its inertia tensor has a negative principal moment (-2 kg m^2)"),
])
def test_a_negative_urdf_inertia_is_refused(inertia, text):
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    urdf = f"""<robot name="r"><link name="base"/>
      <joint name="j" type="revolute"><parent link="base"/><child link="l"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="10" velocity="3"/></joint>
      <link name="l"><inertial><mass value="1"/><inertia {inertia}/></inertial></link></robot>"""
    with pytest.raises(errors.ModelFileError, match=re.escape(f"r.urdf: link 'l': {text}")):
        RobotModel(urdf, "r.urdf")


# ------------------------------------------------------------------ fleet manifests


def manifest(tmp_path, fleet="", logs_glob="logs/*.parquet"):
    (tmp_path / "logs").mkdir(exist_ok=True)
    log_file(tmp_path / "logs")
    path = tmp_path / "fleet.toml"
    path.write_text(f'[fleet]\n{fleet}\n[[robot]]\nname = "r1"\nlogs = "{logs_glob}"\n')
    return path


@pytest.mark.parametrize("fleet, logs_glob, what", [
    ("", "/etc/*", "robot r1's log /etc/"),
    ("", "../*/logs/*.parquet", "robot r1's log "),
    ('models = "../../outside-models"', "logs/*.parquet", "the models folder "),
    ('history = "/tmp/history"', "logs/*.parquet", "the history /tmp/history"),
])
def test_a_manifest_is_confined_to_its_folder(tmp_path, fleet, logs_glob, what):
    folder = tmp_path / "m"
    folder.mkdir()
    (tmp_path / "other" / "logs").mkdir(parents=True)
    log_file(tmp_path / "other" / "logs")
    path = manifest(folder, fleet, logs_glob)
    res = CliRunner().invoke(cli, ["fleet", str(path), "--list"])
    one_error_line(res, errors.NOTHING_RAN, f"{path}: {what}")
    assert "is outside the manifest's folder" in res.stderr and "--allow-outside" in res.stderr
    trusted = CliRunner().invoke(cli, ["fleet", str(path), "--list", "--allow-outside"])
    assert trusted.exit_code == 0, trusted.stderr


@pytest.mark.parametrize("robot, joints, needle", [
    ("..", "[2]", "name must be letters, digits"),
    (".", "[2]", "name must be letters, digits"),
    ("r1", '[".."]', "joint '..': a joint is a whole number or a name without"),
    ("r1", '["a/../../b"]', "joint 'a/../../b'"),
    ("r1", "[true]", "joint True"),
])
def test_a_robot_or_joint_name_cannot_lead_out_of_the_models_folder(tmp_path, robot, joints, needle):
    folder = tmp_path / "m"
    folder.mkdir()
    path = manifest(folder)
    path.write_text(path.read_text().replace('name = "r1"', f'name = "{robot}"') + f"joints = {joints}\n")
    res = CliRunner().invoke(cli, ["fleet", str(path), "--list"])
    one_error_line(res, errors.NOTHING_RAN, needle)


def test_a_symbolic_link_out_of_the_folder_is_outside(tmp_path):
    folder = tmp_path / "m"
    folder.mkdir()
    (tmp_path / "secret").mkdir()
    log_file(tmp_path / "secret")
    path = manifest(folder, "", "link/*.parquet")
    os.symlink(tmp_path / "secret", folder / "link")
    res = CliRunner().invoke(cli, ["fleet", str(path), "--list"])
    one_error_line(res, errors.NOTHING_RAN, "robot r1's log")


def test_a_second_run_of_a_manifest_is_refused_at_start(tmp_path):
    pytest.importorskip("distributed")
    from fricli.core import jobs

    path = manifest(tmp_path)
    with jobs.output_lock(str(path)):      # a first run holds it
        res = CliRunner().invoke(cli, ["fleet", str(path), "--workers", "1"])
    one_error_line(res, errors.LOCKED, f"{path} is being run by another fricli fleet job; this run did nothing")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet.toml", "logs"]   # no history, no models


def test_the_limits_in_the_docs_are_the_codes():
    text = (ROOT / "docs" / "reliability.md").read_text()
    assert f"more than {runs.IDENTIFY_MAX_ROWS:,} rows" in text
    assert f"about {runs.IDENTIFY_BYTES_PER_ROW} bytes a row" in text
    assert f"`more than {files.STDIN_LIMIT:,} bytes on stdin (the limit)`" in text
    assert files.STDIN_LIMIT == 1 << 30 and files.SPOOL_LIMIT == 64 << 30    # "1 GiB", "64 GiB"
    assert modelfile.MIN_UNPACKED == 16 << 20 and modelfile.MAX_EXPANSION == 32   # "16 MiB plus 32 times"


# ------------------------------------------------------------------ output


def test_a_log_without_units_is_noted_at_run_time(tmp_path, model):
    t = np.arange(400) * 0.01
    bare = pa.table({"t": t, "qd": np.sin(t), "tau_m": np.sign(np.sin(t)), "tau_g": np.zeros(400),
                     "tau_dyn": np.zeros(400)})
    pq.write_table(bare, tmp_path / "bare.parquet")
    res = CliRunner().invoke(cli, ["predict", str(model), str(tmp_path / "bare.parquet"), "-o", str(tmp_path / "o.parquet")])
    assert res.exit_code == 0, res.stderr
    assert res.stderr.count("no column carries a unit") == 1, res.stderr
    assert f"note: {tmp_path / 'bare.parquet'}: no column carries a unit (Parquet field metadata 'unit'): read as SI" \
        in res.stderr
    with_units = log_file(tmp_path)
    res = CliRunner().invoke(cli, ["predict", str(model), str(with_units), "-o", str(tmp_path / "p.parquet")])
    assert res.exit_code == 0 and "no column carries a unit" not in res.stderr, res.stderr


def named_log_and_model(tmp_path, log_name):
    """A log of joint "wrist\\nroll" saved as ``log_name`` and a linear model of that joint: (log, model)."""
    from fricli.models.linear import LinearFriction

    table = pq.read_table(log_file(tmp_path))
    table = table.append_column("joint", pa.array(["wrist\nroll"] * table.num_rows))
    pq.write_table(table, tmp_path / log_name)
    model = tmp_path / "lin.npz"
    models.save(str(model), LinearFriction(1.0, 5.0), joint="wrist\nroll", axis="rotary",
                units=logs.CANONICAL["rotary"], provenance={})
    return tmp_path / log_name, model


def test_a_line_break_in_a_joint_name_stays_escaped_in_success_lines(tmp_path):
    log, model = named_log_and_model(tmp_path, "named.parquet")
    res = CliRunner().invoke(cli, ["estimate-ext", str(model), str(log), "-o",
                                   str(tmp_path / "o.parquet")])
    assert res.exit_code == 0, res.stderr
    for line in res.stderr.splitlines():
        assert not line.startswith("roll"), res.stderr
    assert "rows of joint wrist\\nroll -> " in res.stderr, res.stderr


def test_a_line_break_in_a_joint_name_stays_escaped_in_the_evaluation_table(tmp_path):
    log, model = named_log_and_model(tmp_path, "named\nlog.parquet")
    res = CliRunner().invoke(cli, ["evaluate", "--model", str(model), "--log", str(log)])
    assert res.exit_code == 0, res.stderr
    assert "named\\nlog friction MAE" in res.stdout, res.stdout
    for line in res.stdout.splitlines():
        assert not line.startswith(("roll", "log.parquet")), res.stdout


def test_a_line_break_in_a_name_stays_escaped_in_the_fleet_table():
    from fricli.fleet import run
    from fricli.fleet.manifest import Job

    job = Job(robot="r1", joint="wrist\nroll", log="/l.parquet", date="2026-01-01", pipeline="lugre",
              model="/m.npz", options=())
    outcome = run.Outcome(run="x", jobs=[job], results=[{"status": "failed", "reason": "bad\nrow",
                                                         "seconds": 1.0}], written=[])
    lines = run.table(outcome).splitlines()
    assert len(lines) == 3 and "wrist\\nroll" in lines[1] and "bad\\nrow" in lines[1], lines


def test_a_narrow_position_range_says_where_the_joint_dwells():
    from fricli.fitting.diagnosis import structure

    rng = np.random.default_rng(0)
    n = 8000
    m = 3 * n // 4
    q = np.concatenate([np.linspace(-1.64, 1.22, m), 0.0111 + 1e-5 * rng.random(n - m)])   # rests a quarter of the time
    e = rng.normal(0, 0.01, n)
    e[m:] += 1.0                                        # an offset while it rests
    s = structure.Structure(time=structure.View(0.0, False, {"frequency_hz": None}),
                            velocity=structure.View(0.0, False, {"range": None}),
                            position=structure.over_variable(e, q, 0.01))
    line = s.line("Nm", "rad/s", "rad")
    lo, hi = s.position.where["range"]
    assert lo <= 0.0111 <= hi and hi - lo < 0.05 * 2.86
    assert f"over position {structure.span(lo, hi)} rad (28 % of the rows, where the joint dwells; its position spans " \
           "-1.64 .. 1.22 rad)" in line, line
    e_wide = rng.normal(0, 0.01, n) + np.where(q > 0.5, 1.0, 0.0)       # over a stretch of the travel: no such clause
    wide = structure.over_variable(e_wide, q, 0.01)
    assert "dwells" not in structure.Structure(s.time, s.velocity, wide).line("Nm", "rad/s", "rad")



def test_calibration_priors_of_a_coupled_motor_raise_no_numpy_warning():
    """A joint whose diagonal of the mass matrix is 0 (nothing beyond it) under a motor that does
    not drive it: 0 / 0 was computed and printed as a raw RuntimeWarning."""
    pytest.importorskip("pinocchio")
    import warnings

    from fricli.robot import calibration
    from fricli.robot.dynamics import RobotModel

    urdf = """<robot name="r"><link name="base"/>
      <joint name="a" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="10" velocity="3"/></joint>
      <link name="l1"><inertial><origin xyz="0.3 0 0"/><mass value="2"/>
        <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
      <joint name="b" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>
      <limit lower="-3" upper="3" effort="10" velocity="3"/></joint>
      <link name="l2"/></robot>"""
    robot = RobotModel(urdf, "r.urdf")
    ratio = np.array([[1.0, 0.0], [1.0, 1.0]])
    ones = np.ones(2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scales = calibration.prior_scales(robot, calibration.cad_parameters(robot), 1e-4 * ones, ones, ones, ones,
                                          1.0, ratio)
    assert np.isfinite(scales).all()


def test_the_deploy_page_names_what_a_coupled_group_exports():
    from fricli.export import coupled

    text = (ROOT / "docs" / "deploy.md").read_text()
    assert "PREFIX_step(PREFIX_state *s, const double *qd, double *tau_f)" in text
    assert "PREFIX_step(PREFIX_state *s, const double *qd, double *tau_f)" in coupled.__doc__
    assert "_step_array" not in coupled.__doc__ and "_step_parts" not in coupled.__doc__


def test_the_payload_page_counts_its_commands():
    text = (ROOT / "docs" / "payload.md").read_text()
    block = text.split("```sh\n", 1)[1].split("```", 1)[0].splitlines()
    third = block[2]
    assert third.startswith("fricli payload ")
    assert "The third command, `fricli payload`, prints" in text
    assert block[3].startswith("fricli import ") and "the fourth command's payload options" in text


@pytest.mark.slow
def test_a_fleet_run_leaves_no_dask_scratch_space(tmp_path):
    pytest.importorskip("distributed")
    path = manifest(tmp_path)
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    proc = fricli(["fleet", str(path), "--workers", "1"], tmp_path, env=dict(
        os.environ, TMPDIR=str(scratch), OMP_NUM_THREADS="1",
        PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])))
    _, err = proc.communicate(timeout=300)
    assert "appended to" in err, err       # the run ran (its one job fails on this log: exit 12 is fine here)
    left = [str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*") if "dask" in p.name or p.suffix == ".lock"]
    assert left == [], left


@pytest.mark.slow
def test_a_killed_fleet_prints_no_resource_tracker_warning(tmp_path):
    pytest.importorskip("distributed")
    path = manifest(tmp_path)
    proc = fricli(["fleet", str(path), "--workers", "1"], tmp_path)
    deadline = time.time() + 120
    while time.time() < deadline and not list(tmp_path.glob("models/r1/*")):   # the worker has started its job
        time.sleep(0.2)
    time.sleep(0.5)
    proc.send_signal(signal.SIGKILL)
    _, err = proc.communicate(timeout=120)
    assert "resource_tracker" not in err and "leaked" not in err, err


def test_a_line_break_in_a_manifest_joint_stays_escaped_in_the_job_list(tmp_path):
    path = manifest(tmp_path)
    path.write_text(path.read_text() + 'joints = ["wrist\\nroll"]\n')
    res = CliRunner().invoke(cli, ["fleet", str(path), "--list"])
    assert res.exit_code == 0, res.stderr
    assert len(res.stdout.splitlines()) == 1 and "\twrist\\nroll\t" in res.stdout, res.stdout
