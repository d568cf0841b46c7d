"""The EMPS benchmark: the benchmark's own processing, and diagnose on the real measurements.

Skips when ../shared/data (relative to the repository) is absent.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import shared_data

from fricli import models
from fricli.applying import emps
from fricli.core import logs
from fricli.cli import cli

# ----------------------------------------------------------------- processing (no data needed)


def test_central_difference_is_exact_for_a_parabola():
    t = np.arange(50) * 0.001
    x = 3.0 * t ** 2
    d = emps.central_difference(x, 0.001)
    np.testing.assert_allclose(d[1:-1], 6.0 * t[1:-1], rtol=1e-9)
    assert d[0] == 0.0 and d[-1] == 0.0


def test_decimated_drops_49_samples_then_keeps_every_tenth():
    x = np.r_[np.full(49, 7.0), np.ones(1000)]
    y = emps.decimated(x)
    assert len(y) == 100
    # scipy's order-8 Chebyshev filter, applied twice, has a DC gain of 0.9886 (same on y and yhat)
    np.testing.assert_allclose(y, y[50], rtol=1e-9)
    assert y[50] == pytest.approx(0.9886, abs=1e-4)


def test_benchmark_error_is_relative_and_scale_free(rng):
    y = np.sin(np.arange(5000) / 200.0) * 50 + rng.standard_normal(5000)
    assert emps.benchmark_error(y, y) == 0.0
    assert emps.benchmark_error(3 * y, 3 * 0.9 * y) == pytest.approx(10.0)
    assert emps.relative_error(y, 0.9 * y) == pytest.approx(10.0)


# ----------------------------------------------------------------- the measured data


NO_ROBOT_MODEL = ("--no-gravity", "--no-dynamics")


@pytest.fixture(scope="module")
def emps_path():
    return str(shared_data("emps/emps.parquet"))


@pytest.fixture(scope="module")
def emps_log(emps_path):
    return logs.load_log(emps_path, cutoff_hz=emps.CUTOFF_HZ)


def test_benchmark_recipe_reproduces_the_scipy_rerun(emps_log):
    sig = emps_log.signals
    sym = emps.idim_ls(sig["t"], sig["q"], sig["tau_m"])
    for key in ("M", "Fv", "Fc", "offset"):
        assert sym.params[key] == pytest.approx(emps.SCIPY_RERUN["symmetric"][key], abs=0.01), key
    assert sym.rel_error == pytest.approx(4.37, abs=0.005)
    assert sym.cond == pytest.approx(25.99, abs=0.01)
    asym = emps.idim_ls(sig["t"], sig["q"], sig["tau_m"], asymmetric=True)
    assert asym.rel_error == pytest.approx(3.54, abs=0.005)
    for key in ("M", "Fv+", "Fc+", "Fv-", "Fc-"):
        assert asym.params[key] == pytest.approx(emps.PUBLISHED["asymmetric"][key], rel=0.01), key


def test_benchmark_signals_replace_only_velocity_and_acceleration(emps_log):
    sig = emps.signals(emps_log)
    assert sig["tau_m"] is emps_log.signals["tau_m"]
    np.testing.assert_allclose(sig["qd"][1000:-1000], emps_log.signals["qd"][1000:-1000], rtol=1e-3, atol=1e-6)
    assert sig["qd"][0] == 0.0 and sig["qdd"][-1] == 0.0


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory, emps_path):
    """identify, then diagnose --fix, through the CLI (cut-off 100 Hz, the benchmark's)."""
    folder = tmp_path_factory.mktemp("emps")
    base, fixed = str(folder / "emps.npz"), str(folder / "emps-fixed.npz")
    runner = CliRunner()
    # a horizontal axis without a robot model: no gravity, and no tau_dyn (the inertia stays in the target)
    res = runner.invoke(cli, ["identify", emps_path, "--cutoff", "100", *NO_ROBOT_MODEL, "-o", base, "-q"])
    assert res.exit_code == 0, res.stderr
    res = runner.invoke(cli, ["diagnose", base, emps_path, "--cutoff", "100", *NO_ROBOT_MODEL, "--json", "--fix",
                              "-o", fixed])
    assert res.exit_code == 0, res.stderr
    return json.loads(res.stdout), base, fixed


def test_diagnose_finds_the_missing_inertia_first(diagnosed):
    out, _, _ = diagnosed
    assert out["added"][0] == "acceleration"
    inertia = out["effects"][0]["params"]["inertia"]
    assert inertia["unit"] == "kg"
    assert inertia["value"] == pytest.approx(95.1, rel=0.02)


def test_diagnose_finds_the_asymmetry(diagnosed):
    out, _, _ = diagnosed
    assert "direction" in out["added"]
    par = next(e for e in out["effects"] if e["name"] == "direction")["params"]
    # viscous friction is clearly larger for negative velocity (screw fatigue), as published
    assert par["Fv-"]["value"] > 1.2 * par["Fv+"]["value"]


def test_fixed_model_meets_the_benchmark_error(diagnosed, emps_log):
    out, base, fixed = diagnosed
    model, meta = models.load(fixed)
    assert meta["kind"] == "augmented"
    errors = emps.model_errors(model, emps_log)
    assert errors["benchmark"] <= emps.SCIPY_RERUN["asymmetric"]["rel_error"]
    before = emps.model_errors(models.load(base)[0], emps_log)
    assert errors["raw"] < 0.1 * before["raw"]


def test_train_base_says_when_training_learned_nothing(emps_path, tmp_path):
    """Without its inertia (--no-dynamics) the drive's force is mostly M*qdd, which no friction of
    velocity explains: the held-out error is least at the first steps, and stderr says so."""
    res = CliRunner().invoke(cli, ["train-base", emps_path, "--cutoff", "100", "--no-gravity", "--no-dynamics",
                                   "--steps", "500", "--until", "50%", "-o", str(tmp_path / "nn.npz")])
    assert res.exit_code == 0, res.stderr
    assert "training learned nothing the held-out rows confirm" in res.stderr
