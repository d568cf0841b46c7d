"""One planner makes every model (fricli.fitting.plan): the command, a fleet job, the library and
the demo write the same bytes from the same log and options, and --if-changed touches nothing on
every path."""

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fricli import models
from fricli.cli import cli
from fricli.core import errors, jobs, logs
from fricli.fitting import plan
from fricli.fitting.diagnosis import driver
from fricli.fleet import manifest, pipelines

# the same small runs as options (library, fleet) and as the command's flags
RUNS = {"identify": ({"hold": 0.3}, ["--hold", "0.3"]),
        "train-base": ({"steps": 15, "max_samples": 200, "hidden": (4, 4), "seed": 2},
                       ["--steps", "15", "--max-samples", "200", "--hidden", "4,4", "--seed", "2"]),
        "adapt": ({"epochs": 2, "hidden": (3, 3)}, ["--epochs", "2", "--hidden", "3,3"])}
# diagnose --fix's options as the command gives them (every option of the command that shapes the model)
DIAGNOSE = {"folds": driver.DEFAULT_FOLDS, "min_gain": driver.DEFAULT_MIN_GAIN, "alpha": driver.DEFAULT_ALPHA,
            "only": None, "max_effects": None, "no_carry": False, "accept_implausible": False, "urdf": None,
            "calibrated": None, "calibrate_friction": None, "joint": None, "kt": None, "cutoff": 50.0,
            "drop_invalid": False}


def invoke(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    return res


def files(folder) -> dict:
    """{name: (modification time [ns], bytes)} of the files in ``folder``: what a run touched."""
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(Path(folder).iterdir()) if p.is_file()}


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """A log of joints 2 and 4 and the LuGre model of each (a model folder)."""
    from test_joints import write_log

    root = tmp_path_factory.mktemp("plan")
    log = write_log(root / "arm.parquet", [2, 4])
    assert invoke("identify", log, "-o", root / "bases", "-q").exit_code == 0
    return root, log


@pytest.mark.parametrize("pipeline", sorted(RUNS))
def test_command_fleet_and_library_write_the_same_bytes(arm, tmp_path, pipeline):
    root, log = arm
    given, flags = RUNS[pipeline]
    inputs = [root / "bases"] if pipeline == "adapt" else []
    res = invoke(pipeline, *inputs, log, "-o", tmp_path / "cmd", *flags, "-q")
    assert res.exit_code == 0, res.stderr
    run = plan.fit_log(pipeline, log, str(tmp_path / "lib"), dict(given),
                       inputs=str(root / "bases") if inputs else None)
    assert [o.label for o in run.outcomes] == [2, 4] and run.folder == str(tmp_path / "lib")
    assert not run.unchanged and all(o.made is not None and o.digest == jobs.file_sha256(log) for o in run.outcomes)
    (tmp_path / "fleet").mkdir()
    for joint in ("2", "4"):
        job = manifest.Job(robot="r1", joint=joint, log=log, date="2026-01-01", pipeline=pipeline,
                           model=str(tmp_path / "fleet" / f"joint_{joint}.npz"), options=tuple(sorted(given.items())),
                           base=str(root / "bases" / f"joint_{joint}.npz") if inputs else None)
        assert pipelines.run(job)["status"] == "ok"
    written = files(tmp_path / "cmd")
    assert sorted(written) == ["joint_2.npz", "joint_4.npz"]
    for other in ("lib", "fleet"):
        assert {n: b for n, (_, b) in files(tmp_path / other).items()} == {n: b for n, (_, b) in written.items()}

    # a second run of each path touches nothing
    res = invoke(pipeline, *inputs, log, "-o", tmp_path / "cmd", *flags, "--if-changed")
    assert res.exit_code == errors.UNCHANGED, res.stderr
    assert res.stderr.count("is up to date") == 2
    again = plan.fit_log(pipeline, log, str(tmp_path / "cmd"), dict(given),
                         inputs=str(root / "bases") if inputs else None, if_changed=True)
    assert again.unchanged and [o.output for o in again.outcomes] == [str(tmp_path / "cmd" / n) for n in written]
    job = manifest.Job(robot="r1", joint="4", log=log, date="2026-01-01", pipeline=pipeline,
                       model=str(tmp_path / "cmd" / "joint_4.npz"), options=tuple(sorted(given.items())),
                       base=str(root / "bases" / "joint_4.npz") if inputs else None)
    assert pipelines.run(job)["status"] == "unchanged"
    assert files(tmp_path / "cmd") == written


def test_diagnose_fix_command_and_library_write_the_same_bytes(arm, tmp_path):
    root, log = arm
    res = invoke("diagnose", root / "bases", log, "--fix", "-o", tmp_path / "cmd")
    assert res.exit_code == 0, res.stderr
    written = files(tmp_path / "cmd")
    assert sorted(written) == ["joint_2.npz", "joint_4.npz"]
    recorded = models.load(str(tmp_path / "cmd" / "joint_2.npz"))[1]["provenance"]["job"]["options"]
    assert recorded == dict(DIAGNOSE, joint="2")    # the options the library is given below
    run = plan.fit_log("diagnose", log, str(tmp_path / "lib"), dict(DIAGNOSE), inputs=str(root / "bases"))
    assert [o.made.diagnosis is not None for o in run.outcomes] == [True, True]
    assert {n: b for n, (_, b) in files(tmp_path / "lib").items()} == {n: b for n, (_, b) in written.items()}

    res = invoke("diagnose", root / "bases", log, "--fix", "-o", tmp_path / "cmd", "--if-changed")
    assert res.exit_code == errors.UNCHANGED, res.stderr
    assert plan.fit_log("diagnose", log, str(tmp_path / "cmd"), dict(DIAGNOSE), inputs=str(root / "bases"),
                        if_changed=True).unchanged
    assert files(tmp_path / "cmd") == written


def test_diagnose_fix_holds_the_lock(arm, tmp_path):
    root, log = arm
    out = tmp_path / "fixed.npz"
    with jobs.output_lock(str(out)):
        res = invoke("diagnose", root / "bases", log, "--joint", "2", "--fix", "-o", out)
    assert res.exit_code == errors.LOCKED and "being written by another fricli job" in res.stderr
    assert not out.exists()


def test_the_demo_writes_what_the_commands_write(tmp_path):
    """identify, train-base (each architecture) and adapt on the sample logs: the demo's model files
    are the commands' with the same options."""
    from conftest import SAMPLE

    from fricli import demo

    demo.run(str(tmp_path / "demo"), data=str(SAMPLE), steps=5, seed=0)
    base, adapt = SAMPLE / "joint2_base.parquet", SAMPLE / "joint2_adapt.parquet"
    commands = {"lugre": ["identify", base],
                "nn_base": ["train-base", base, "--steps", "5"],
                "selmic": ["train-base", base, "--arch", "selmic", "--steps", "5"],
                "nnacm": ["train-base", base, "--arch", "nnacm", "--steps", "5"],
                "adapted": ["adapt", tmp_path / "demo" / "nn_base.npz", adapt],
                "lugre_adapted": ["adapt", tmp_path / "demo" / "lugre.npz", adapt]}
    for key, args in commands.items():
        res = invoke(*args, "-o", tmp_path / f"{key}.npz", "-q")
        assert res.exit_code == 0, res.stderr
        assert (tmp_path / f"{key}.npz").read_bytes() == (tmp_path / "demo" / f"{key}.npz").read_bytes(), key
    meta = models.load(str(tmp_path / "demo" / "adapted.npz"))[1]
    assert meta["provenance"]["base"]["name"] == "nn_base.npz"


@pytest.fixture(scope="module")
def cad_arm(tmp_path_factory):
    """A four-joint arm whose CAD masses are off, imported with the CAD URDF, and a linear model per joint."""
    from test_estimators import cad_arm_files

    root = tmp_path_factory.mktemp("cad")
    _, log = cad_arm_files(root)
    assert invoke("identify", log, "--kind", "linear", "-o", root / "linear", "-q").exit_code == 0
    return root, str(log)


def test_diagnose_fix_calibrate_honours_if_changed(cad_arm, tmp_path):
    """--fix --calibrate --if-changed: the second run calibrates nothing and writes nothing (exit 9);
    the library, given the recomputed log, writes the same bytes as the command."""
    from fricli.robot import calibration as cb

    root, log = cad_arm
    cal, fixed = tmp_path / "cal.urdf", tmp_path / "fixed"
    args = ["diagnose", root / "linear", log, "--fix", "--calibrate", cal, "-o", fixed, "--if-changed"]
    res = invoke(*args)
    assert res.exit_code == 0, res.stderr
    written, calibration = files(fixed), files(tmp_path)
    assert sorted(written) == [f"joint_{j}.npz" for j in (1, 2, 3, 4)]
    res = invoke(*args)
    assert res.exit_code == errors.UNCHANGED, res.stderr
    assert res.stderr.count("is up to date") == 4 and "calibrating" not in res.stderr
    assert files(fixed) == written and files(tmp_path) == calibration

    # the same fix from the library on the log recomputed with the calibrated robot model
    table, digest = logs.read_table(log)
    _, _, recomputed = cb.recalibrate(table, log, str(root / "cad.urdf"), friction=cb.LOOP_FRICTION,
                                      cutoff_hz=logs.DEFAULT_CUTOFF_HZ)
    options = dict(DIAGNOSE, calibrated=str(cal), urdf_sha256=jobs.file_sha256(str(root / "cad.urdf")))
    run = plan.fit_log("diagnose", log, str(tmp_path / "lib"), options, inputs=str(root / "linear"),
                       read=(recomputed, digest), refit=True)
    assert len(run.outcomes) == 4
    assert {n: b for n, (_, b) in files(tmp_path / "lib").items()} == {n: b for n, (_, b) in written.items()}

    # another URDF is another input: the models are made again
    (root / "cad.urdf").write_text((root / "cad.urdf").read_text() + "\n")
    try:
        res = invoke(*args, "-q")
        assert res.exit_code == 0, res.stderr
        assert all(files(fixed)[n][0] != written[n][0] for n in written)
    finally:
        (root / "cad.urdf").write_text((root / "cad.urdf").read_text()[:-1])


def test_diagnose_arm_writes_what_diagnose_fix_calibrate_writes(cad_arm, tmp_path, monkeypatch):
    """fricli.diagnose_arm(..., calibrate=) is diagnose --fix --calibrate: the same model files,
    calibrated URDF and report, and JSON; with if_changed it calibrates nothing and touches nothing."""
    import fricli
    from fricli.core import jsontext

    root, log = cad_arm
    for where in ("cmd", "lib"):
        (tmp_path / where).mkdir()
    monkeypatch.chdir(tmp_path / "cmd")      # the paths as given are recorded: the same in both
    res = invoke("diagnose", root / "linear", log, "--fix", "--calibrate", "cal.urdf", "-o", "fixed", "--json")
    assert res.exit_code == 0, res.stderr
    monkeypatch.chdir(tmp_path / "lib")
    seen = []
    run = fricli.diagnose_arm(str(root / "linear"), log, "fixed", calibrate="cal.urdf", done=seen.append)
    assert jsontext.dumps(run.to_json()) == res.stdout
    every = {where: {p.relative_to(tmp_path / where).as_posix(): p.read_bytes()
                     for p in sorted((tmp_path / where).rglob("*")) if p.is_file()} for where in ("cmd", "lib")}
    assert sorted(every["lib"]) == ["cal.calibration.json", "cal.urdf"] + [f"fixed/joint_{j}.npz" for j in (1, 2, 3, 4)]
    assert every["lib"] == every["cmd"]
    assert [s.joint for s in seen] == list(run.joints) == [1, 2, 3, 4]
    assert all(s.refitted and s.made is not None and not s.unchanged for s in seen)
    assert run.calibrated_urdf == run.robot_model["calibrated_urdf"] == "cal.urdf" and not run.unchanged
    assert run.notices[0] == ("note", f"calibrating the robot model of {root / 'cad.urdf'} on {log} ...")
    assert [line for _, line in run.notices] == res.stderr.splitlines()[:len(run.notices)]

    written = {**files(tmp_path / "lib"), **files(tmp_path / "lib" / "fixed")}
    again = fricli.diagnose_arm(str(root / "linear"), log, "fixed", calibrate="cal.urdf", if_changed=True)
    assert again.unchanged and again.notices == [] and again.robot_model is None and again.to_json() is None
    assert [(j, s.unchanged, s.output) for j, s in again.joints.items()] == [
        (j, True, f"fixed/joint_{j}.npz") for j in (1, 2, 3, 4)]
    assert {**files(tmp_path / "lib"), **files(tmp_path / "lib" / "fixed")} == written


def test_diagnose_arm_refuses_options_that_do_not_go_together(cad_arm):
    import fricli
    from fricli.fitting.optionspec import OptionError

    root, log = cad_arm
    for given, option in (({"calibrate": "c.urdf"}, "calibrate"), ({"friction": "linear"}, "friction"),
                          ({"if_changed": True}, "if_changed"), ({"folds": 1}, "folds"), ({"kt": "x"}, "kt"),
                          ({"time_until": "120%"}, "time_until"), ({"fix": True}, "fix"),
                          ({"output": "f", "calibrate": "c.urdf", "friction": "coulomb"}, "friction"),
                          ({"output": "-"}, "output")):
        with pytest.raises(OptionError) as err:
            fricli.diagnose_arm(str(root / "linear"), log, **given)
        assert err.value.option == option, given
    with pytest.raises(OptionError, match="whole-arm log") as err:     # one joint's model: nothing to calibrate
        fricli.diagnose_arm(str(root / "linear" / "joint_2.npz"), log, str(root / "j2.npz"), calibrate="c.urdf",
                            joint="2")
    assert err.value.option == "calibrate" and not (root / "c.urdf").exists() and not (root / "j2.npz").exists()


def test_a_time_window_is_recorded_and_read(arm, tmp_path):
    """--from/--until reach the planner as a window: the rows it reads and the record it writes."""
    from fricli.core import timewindow

    root, log = arm
    res = invoke("identify", log, "--joint", "2", "--until", "60%", "-o", tmp_path / "cmd.npz", "-q")
    assert res.exit_code == 0, res.stderr
    window = timewindow.Window(None, timewindow.Bound.parse("60%"))
    run = plan.fit_log("identify", log, str(tmp_path / "lib.npz"), {"joint": 2}, window=window)
    assert run.folder is None and len(run.outcomes[0].made.data) == 1200     # 60 % of the joint's 2000 rows
    assert (tmp_path / "lib.npz").read_bytes() == (tmp_path / "cmd.npz").read_bytes()
    assert models.load(str(tmp_path / "lib.npz"))[1]["provenance"]["job"]["options"]["window"] == window.to_json()


def test_import_is_one_library_call(tmp_path):
    """The command's log is the library's (``import_log``), and the library flags a time step no
    controller samples at, as the command does."""
    import pyarrow.parquet as pq
    from test_import import MAPPING, mapping, rows

    from fricli.robot import importing

    (tmp_path / "map.toml").write_text(MAPPING.replace('unit = "s"', 'unit = "s", scale = 1e6'))
    (tmp_path / "rec.csv").write_text("\n".join(rows()) + "\n")
    res = invoke("import", tmp_path / "rec.csv", "--mapping", tmp_path / "map.toml", "-o", tmp_path / "cmd.parquet")
    assert res.exit_code == 0, res.stderr
    result = importing.import_log([str(tmp_path / "rec.csv")], mapping(MAPPING.replace('unit = "s"',
                                                                                   'unit = "s", scale = 1e6')))
    assert result.table.equals(pq.read_table(tmp_path / "cmd.parquet"))
    assert [level for level, line in result.notices if "median time step is 1e+04 s" in line] == ["warning"]
    assert [line for _, line in result.notices][0] in res.stderr
    assert result.name == result.source == str(tmp_path / "rec.csv") and len(result.mapping.joints) == 2
