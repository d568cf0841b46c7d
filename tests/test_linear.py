"""The linear friction model (kind ``linear``): the fit, the model file, every command, C export."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import SAMPLE, invoke, no_inertia, write
from fricli import models
from fricli.core import logs
from fricli.models.linear import LinearFriction, fit

SYM = {"fv": 10.5, "fc": 7.25, "offset": -0.4}
ASYM = {"fv": 12.0, "fc": 6.5, "fv_neg": 9.0, "fc_neg": 8.0}


def synthetic(params: dict, tmp_path, *, rest_torque: float = 3.0) -> str:
    """A log whose friction target is exactly the linear model ``params`` wherever the joint moves,
    and ``rest_torque`` (held by stiction, not the model) at standstill."""
    t = np.arange(4000) / 100.0
    qd = 0.8 * np.sin(0.6 * t) + 0.3 * np.sin(1.7 * t)
    qd[1000:1200] = 0.0
    model = LinearFriction(**params)
    tau_f = np.where(qd == 0.0, rest_torque, model(dict(qd=qd)))
    tau_g = 15.0 * np.cos(0.2 * t)
    table = logs.table_from_arrays({"t": t, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": tau_g,
                                    "tau_m": tau_g + tau_f},
                                   {"t": "s", "qd": "rad/s", "qdd": "rad/s^2", "tau_g": "Nm", "tau_m": "Nm"})
    return write(no_inertia(table), tmp_path / "linear.parquet")   # no inertia torque in tau_m


@pytest.mark.parametrize("params", [SYM, ASYM], ids=["symmetric", "asymmetric"])
def test_identify_recovers_the_parameters_exactly(params, tmp_path):
    log = synthetic(params, tmp_path)
    kind = "linear-asymmetric" if "fc_neg" in params else "linear"
    out = tmp_path / "m.npz"
    res = invoke("identify", log, "-o", out, "--kind", kind, "--json", "-q")
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert set(got["parameters"]) == set(params)
    for name, value in params.items():
        assert got["parameters"][name] == pytest.approx(value, abs=1e-9)
    assert got["fit"]["moving"]["max"] < 1e-9          # exact where the joint moves
    assert got["fit"]["max"] == pytest.approx(3.0 - params.get("offset", 0.0), abs=1e-9)  # standstill is not fitted
    assert got["parameter_units"]["fv"] == "Nm s/rad"
    model, meta = models.load(str(out))
    assert meta["kind"] == "linear" and meta["provenance"]["job"]["options"]["kind"] == kind
    assert model.parameters() == pytest.approx(params, abs=1e-9)


def test_the_fit_refuses_motion_in_one_direction():
    qd = np.linspace(0.1, 1.0, 100)
    from fricli.core.errors import DataError

    with pytest.raises(DataError, match="negative velocity"):
        fit({"t": np.arange(100.0), "qd": qd, "tau_m": qd})


@pytest.mark.parametrize("params", [SYM, ASYM], ids=["symmetric", "asymmetric"])
def test_model_file_round_trip(params, tmp_path):
    model = LinearFriction(**params, axis="linear")
    log = logs.load_log(str(SAMPLE / "joint2_base.parquet"))
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, log, rows_used=len(log))
    back, meta = models.load(path)
    assert isinstance(back, LinearFriction) and back.get_params() == model.get_params()
    assert meta["inputs"] == ["qd"]
    np.testing.assert_array_equal(back(log.signals), model(log.signals))
    res = invoke("inspect", path)
    assert res.exit_code == 0 and json.loads(res.stdout)["model"]["params"]["fc"] == params["fc"]


def test_the_asymmetric_model_has_no_offset():
    with pytest.raises(ValueError, match="no offset"):
        LinearFriction(1.0, 2.0, 0.5, fv_neg=1.0, fc_neg=2.0)
    v = np.array([-2.0, -0.0, 0.0, 3.0])
    np.testing.assert_array_equal(LinearFriction(**ASYM)(dict(qd=v)), [-2 * 9.0 - 8.0, 0.0, 0.0, 3 * 12.0 + 6.5])
    np.testing.assert_array_equal(LinearFriction(**SYM)(dict(qd=v)), [-21.0 - 7.25 - 0.4, -0.4, -0.4, 31.5 + 7.25 - 0.4])


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """Linear models fitted on the sample base log; an adapted one and a diagnosed one on top."""
    folder = tmp_path_factory.mktemp("linear")
    base = str(SAMPLE / "joint2_base.parquet")
    paths = {}
    for kind in ("linear", "linear-asymmetric"):
        paths[kind] = str(folder / f"{kind}.npz")
        assert invoke("identify", base, "-o", paths[kind], "--kind", kind, "-q").exit_code == 0
    paths["adapted"] = str(folder / "adapted.npz")
    res = invoke("adapt", paths["linear"], SAMPLE / "joint2_adapt.parquet", "-o", paths["adapted"], "--epochs", 2, "-q")
    assert res.exit_code == 0, res.output
    paths["fixed"] = str(folder / "fixed.npz")
    res = invoke("diagnose", paths["linear"], SAMPLE / "joint2_extended_asym.parquet", "--fix", "-o", paths["fixed"], "-q")
    assert res.exit_code == 0, res.output
    return paths


@pytest.mark.parametrize("kind", ["linear", "linear-asymmetric", "adapted", "fixed"])
def test_export_matches_predict(kind, fitted, tmp_path):
    from test_export import _compare

    import export_check as check

    if check.compiler() is None:
        pytest.skip("no C compiler")
    assert _compare(fitted[kind], str(SAMPLE / "joint2_extended_asym.parquet"), tmp_path) <= 1.0


def test_every_command_reads_a_linear_model(fitted, tmp_path):
    log = SAMPLE / "joint2_extended_asym.parquet"
    path = fitted["linear"]
    for args in (("predict", path, log, "-o", tmp_path / "p.parquet"), ("estimate-ext", path, log, "-o", tmp_path / "e.parquet"),
                 ("report", path, log, "-o", tmp_path / "report"), ("export", path, "-o", tmp_path / "f.h")):
        res = invoke(*args, "-q")
        assert res.exit_code == 0, (args[0], res.output)
    res = invoke("evaluate", "--model", path, "--log", log, "--json")
    assert res.exit_code == 0
    row = json.loads(res.stdout)["results"][0]
    assert 0 < row["friction"]["mae"] <= row["friction"]["rmse"]


def one_speed_each_way(tmp_path, second: float | None = None) -> str:
    """Out at 0.1 rad/s and back at 0.2 rad/s (raised-cosine ramps between); with ``second``, a
    second hold out at that speed. Friction 6 Nm Coulomb, 12 Nm s/rad viscous, plus noise."""
    def ramp(a, b, n=10):
        return a + (b - a) * 0.5 * (1 - np.cos(np.pi * np.arange(n) / n))
    parts = [ramp(0, 0.1), np.full(400, 0.1), ramp(0.1, 0), ramp(0, -0.2), np.full(300, -0.2), ramp(-0.2, 0)]
    if second is not None:
        parts += [ramp(0, second), np.full(400, second), ramp(second, 0)]
    qd = np.concatenate(parts + [np.zeros(50)])
    t = np.arange(qd.size) / 100.0
    tau_f = 6.0 * np.sign(qd) + 12.0 * qd + 0.2 * np.random.default_rng(0).standard_normal(qd.size)
    table = logs.table_from_arrays({"t": t, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": np.zeros_like(t),
                                    "tau_m": tau_f},
                                   {"t": "s", "qd": "rad/s", "qdd": "rad/s^2", "tau_g": "Nm", "tau_m": "Nm"})
    return write(no_inertia(table), tmp_path / "levels.parquet")


@pytest.mark.parametrize("kind", ["linear", "linear-asymmetric"])
def test_one_speed_each_way_is_noted(kind, tmp_path):
    """One speed per direction cannot separate Coulomb from viscous friction (and the offset):
    the fit says so instead of giving what the ramps happen to suggest without a word."""
    res = invoke("identify", one_speed_each_way(tmp_path), "-o", tmp_path / "m.npz", "--kind", kind, "--json")
    assert res.exit_code == 0, res.output
    notes = json.loads(res.stdout)["fit"]["notes"]
    assert len(notes) == 1 and "one speed" in notes[0] and "0.1 and 0.2 rad/s" in notes[0], notes
    assert "note: " + notes[0] in res.stderr
    res = invoke("identify", one_speed_each_way(tmp_path, 0.4), "-o", tmp_path / "m.npz", "--kind", kind, "--json")
    notes = json.loads(res.stdout)["fit"]["notes"]
    assert (notes == []) == (kind == "linear"), notes   # asymmetric: still one speed back
