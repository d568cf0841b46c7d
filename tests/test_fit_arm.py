"""fricli fit-arm (fricli/arm.py): a whole arm in one command on the UR10e fitting run, every
step's output kept, the score against the linear baseline on held-out time, --if-changed."""

import importlib.util
import json
import os

import numpy as np
import pytest
from conftest import ROOT, invoke, shared_data

from fricli.core import errors

pytestmark = pytest.mark.skipif(importlib.util.find_spec("pinocchio") is None, reason="needs the robot extra (pin)")
MAPPING = ROOT / "docs" / "ur10e-mapping.toml"
FIT_RUN = "ur-20_02_19_14harm50sec.csv"


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    data = shared_data("ur10e")
    out = tmp_path_factory.mktemp("arm") / "arm"
    args = (data / "identification" / FIT_RUN, "--mapping", MAPPING, "--urdf", data / "ur10e.urdf", "-o", out)
    done = invoke("fit-arm", *args, "--json")
    assert done.exit_code == 0, done.output
    return out, args, json.loads(done.stdout)


@pytest.mark.slow
def test_every_step_is_kept_and_the_models_beat_the_linear_baseline_on_held_out_time(arm):
    out, _, result = arm
    for name in ("fit-cad.parquet", "fit.parquet", "robot.urdf", "robot.calibration.json", "friction.h",
                 "report.md", "report.json", "fit-arm.json"):
        assert (out / name).is_file(), name
    for folder in ("lugre", "fixed"):
        assert sorted(os.listdir(out / folder)) == [f"joint_{j}.npz" for j in range(1, 7)]
    assert result["held_out"] == "the last 25% of the recording's time"
    scores = result["scores"]
    assert sorted(scores) == [str(j) for j in range(1, 7)]
    ratios = [s["ratio"] for s in scores.values()]
    assert result["mean_ratio"] == pytest.approx(np.mean(ratios))
    assert result["mean_ratio"] < 1.0          # better than the standard model where it was not fitted
    assert all(s["rows"] > 500 for s in scores.values())
    assert "| 2 |" in (out / "report.md").read_text()


@pytest.mark.slow
def test_a_second_run_with_if_changed_touches_nothing(arm):
    out, args, _ = arm
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.rglob("*") if p.is_file()}
    done = invoke("fit-arm", *args, "--if-changed")
    assert done.exit_code == errors.UNCHANGED, done.output
    assert "is up to date" in done.stderr
    after = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in out.rglob("*") if p.is_file()}
    assert after == before


def test_holdout_and_validation_recordings_do_not_go_together(tmp_path):
    done = invoke("fit-arm", "run.csv", "--mapping", MAPPING, "--urdf", "r.urdf", "-o", tmp_path / "o",
                  "--validate", "day2.csv", "--holdout", "0.3")
    assert done.exit_code == errors.USAGE
    assert "--holdout applies without --validate" in done.stderr


def test_a_missing_recording_is_one_line(tmp_path):
    done = invoke("fit-arm", tmp_path / "nothing.csv", "--mapping", MAPPING, "--urdf", MAPPING, "-o", tmp_path / "o")
    assert done.exit_code == errors.INPUT
    assert done.stderr.strip().count("\n") == 0 and "nothing.csv" in done.stderr
    assert not (tmp_path / "o").exists()


def test_nothing_held_out_is_refused(tmp_path):
    done = invoke("fit-arm", "run.csv", "--mapping", MAPPING, "--urdf", "r.urdf", "-o", tmp_path / "o", "--holdout", "0")
    assert done.exit_code == errors.USAGE


def test_validation_recordings_of_one_name_get_files_of_their_own():
    from fricli.arm import _names

    assert _names(["a/run.csv", "b/run.csv", "c/other.csv", "d/run.csv"]) == ["run", "run-2", "other", "run-3"]


def test_the_python_call_refuses_what_the_command_refuses(tmp_path):
    """fricli.fit_arm: the same errors as fit-arm, as exception types of the same exit codes."""
    import fricli

    with pytest.raises(fricli.OptionError) as both:
        fricli.fit_arm(["run.csv"], MAPPING, "r.urdf", tmp_path / "o", validate=["day2.csv"], holdout=0.3)
    assert both.value.option == "holdout" and both.value.exit_code == errors.USAGE
    with pytest.raises(fricli.OptionError):
        fricli.fit_arm(["run.csv"], MAPPING, "r.urdf", tmp_path / "o", holdout=0)
    with pytest.raises(fricli.FricliError) as missing:
        fricli.fit_arm([tmp_path / "nothing.csv"], MAPPING, MAPPING, tmp_path / "o")
    assert missing.value.exit_code == errors.INPUT and "nothing.csv" in str(missing.value)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_failed_run_over_an_earlier_one_says_which_files_are_its_own(arm, tmp_path, monkeypatch):
    """A step failing after others were redone leaves a folder of two runs: the error says which."""
    import shutil

    import fricli
    from fricli import arm as arm_module

    out, args, _ = arm
    copy = tmp_path / "arm"
    shutil.copytree(out, copy)
    recording = tmp_path / FIT_RUN
    recording.write_bytes(args[0].read_bytes() + b"\n")          # another file: the import is redone

    def failing(self, *a, **k):
        raise errors.DataError("joint 3: the joint does not move")

    monkeypatch.setattr(arm_module._Steps, "models", failing)
    with pytest.raises(errors.DataError) as info:
        fricli.fit_arm([str(recording)], str(MAPPING), str(args[4]), str(copy), if_changed=True)
    assert str(info.value) == (f"joint 3: the joint does not move (in {copy}, this run redid fit-cad.parquet; "
                               "its other files are of the run before)")
    assert (copy / "report.md").read_bytes() == (out / "report.md").read_bytes()


@pytest.mark.slow
def test_a_missing_report_is_made_again_and_a_step_record_of_another_shape_redoes_the_steps(arm, tmp_path):
    import shutil

    out, args, _ = arm
    copy = tmp_path / "arm"
    shutil.copytree(out, copy)
    args = [copy if a == out else a for a in args]
    (copy / "report.md").unlink()
    done = invoke("fit-arm", *args, "--if-changed")
    assert done.exit_code == 0, done.output
    assert (copy / "report.md").read_bytes() == (out / "report.md").read_bytes()
    (copy / "fit-arm.json").write_text('{"steps": 5}')
    done = invoke("fit-arm", *args, "--if-changed", "--json")
    assert done.exit_code == 0, done.output
    assert "fit-cad.parquet" in json.loads(done.stdout)["redone"]   # redone, the record being of no use


def test_a_joint_the_calibration_made_worse_is_warned_of():
    from fricli.arm import worse_after_calibration

    scores = {"1": {"lugre": 0.18, "fixed": 0.23, "rows": 900}, "2": {"lugre": 0.5, "fixed": 0.4, "rows": 900},
              "z": {"lugre": 1.0, "fixed": 1.04, "rows": 900},        # within 2 / sqrt(1800) = 4.7 %
              "y": {"lugre": 1.0, "fixed": 1.04, "rows": 90_000}}     # beyond 2 / sqrt(180000) = 0.47 %
    found = worse_after_calibration(scores)
    assert [line.split(":")[0] for _, line in found] == ["joint 1", "joint y"]
    assert found[0][1].startswith("joint 1: the fixed model on the calibrated robot model scores 0.23 on the held-out "
                                  "rows, worse than the LuGre model on the CAD one (0.18)")


@pytest.mark.slow
def test_the_report_warns_of_exactly_the_joints_the_calibration_made_worse(arm):
    _, _, result = arm
    worse = sorted(j for j, s in result["scores"].items() if s["fixed"] > s["lugre"] * (1 + 2 / np.sqrt(2 * s["rows"])))
    warned = sorted(line.split(":")[0].removeprefix("joint ") for line in result["notices"]
                    if "worse than the LuGre model on the CAD one" in line)
    assert warned == worse
