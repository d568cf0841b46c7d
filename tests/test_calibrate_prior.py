"""The calibration's prior strength chosen by cross-validation over blocks of time (--prior auto)."""

import json

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

from fricli.robot import calibration as cb  # noqa: E402
from fricli.robot.dynamics import RobotModel  # noqa: E402
from test_calibrate import URDF, fricli, harmonics, motion, simulate, true_model, write_log  # noqa: E402


@pytest.fixture(scope="module")
def run():
    rng = np.random.default_rng(11)
    return rng, harmonics(rng, 1200, (0.2, 0.45, 0.7, 1.1), 0.25)


def test_noise_free_data_choose_the_weakest_prior(run):
    rng, fit = run
    model, _ = true_model(rng)
    cal = cb.calibrate(RobotModel(URDF, "cad"), motion(*fit, simulate(model, *fit)))
    choice = cal.report["prior_choice"]
    assert cal.report["prior"] == choice["chosen"] == max(cb.PRIOR_GRID)
    assert choice["folds"] == cb.PRIOR_FOLDS and choice["grid"] == sorted(cb.PRIOR_GRID)
    assert cb.PRIOR_START in cb.PRIOR_GRID
    groups = cal.bodies + [f"{j}.armature" for j in cal.joints]
    assert choice["per_group"] == {g: max(cb.PRIOR_GRID) for g in groups}


def test_noise_around_the_cad_model_chooses_a_strong_prior(run):
    """When the CAD model is right and the torques noisy, every deviation from CAD is noise: the
    held-out blocks favour keeping the parameters at CAD."""
    rng, fit = run
    model = pin.buildModelFromXML(URDF)
    model.armature = np.array([0.9, 1.6, 0.45, 0.05])
    robot = RobotModel(URDF, "cad")
    m = motion(*fit, simulate(model, *fit, rng=rng, noise=3.0))
    m.rotor_inertia = model.armature.copy()
    cal = cb.calibrate(robot, m)
    held = cal.report["prior_choice"]["held_out_rms"]
    assert cal.report["prior"] < cb.PRIOR_START
    assert held[f"{cal.report['prior']:g}"] == min(held.values()) < held[f"{max(cb.PRIOR_GRID):g}"]
    choice = cal.report["prior_choice"]
    assert len(choice["per_group"]) == 2 * len(cal.joints) and set(choice["per_group"].values()) <= set(cb.PRIOR_GRID)
    assert choice["held_out_rms_per_group"] <= min(held.values())


def test_fixed_prior_and_refusal_on_the_command_line(run, tmp_path):
    rng, fit = run
    model, _ = true_model(rng)
    log = write_log(tmp_path / "fit.parquet", *fit, simulate(model, *fit))
    (tmp_path / "cad.urdf").write_text(URDF)
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "--prior", "0.5", "-o", "cal.urdf",
                 cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    report = json.loads((tmp_path / "cal.calibration.json").read_text())
    assert report["prior"] == 0.5 and report["prior_choice"] is None
    assert "prior: 0.5 x each parameter's scale (--prior)" in res.stderr
    for bad in ("-1", "0", "nan", "strong"):
        res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "--prior", bad, "-o", "x.urdf",
                     cwd=tmp_path)
        assert res.returncode == 2 and "Traceback" not in res.stderr and "--prior" in res.stderr
        assert not (tmp_path / "x.urdf").exists()
