"""Inputs and references: a model never reads what it is scored against, and a missing
robot-model column is unknown, not zero (docs/log-format.md).

Every model kind predicts on a simulated log with an external load twice, with and without the
reference columns tau_ext and tau_f_true: every prediction of every command must be the same to
the bit (the exported C to 1e-9, as tests/test_export.py).
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest
from test_export import ABS, REL, _train, needs_cc

import export_check as check

from conftest import declare_zero, invoke as run, write
from fricli import models, sim
from fricli.applying import evaluation, report
from fricli.core import errors, logs, metrics, modelfile
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.diagnosis.driver import residual
from fricli.export import c
from fricli.models import terms as T
from fricli.models.augmented import AugmentedModel
from fricli.models.lugre import LuGreModel

REFERENCES = ["tau_ext", "tau_f_true"]
LUGRE = LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, kc=0.04, ks=0.05, sigma0=1.7e4, sigma1=0.002)


def _without_references(table):
    return table.drop_columns([c for c in REFERENCES if c in table.column_names])


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A log with an external load (full and without its references) and model files of every kind."""
    folder = tmp_path_factory.mktemp("references")
    # an undeclared payload: tau_ext varies with the configuration and loads the gear
    table = sim.simulate("extended", joint=2, seed=2, load="asym", duration=20.0, friction_state="base")
    full, bare = str(folder / "full.parquet"), str(folder / "bare.parquet")
    pq.write_table(table, full)
    pq.write_table(_without_references(table), bare)
    log = logs.load_log(full)
    # the load terms of the diagnosis library (load, payload, quadrant) on top of a loaded LuGre model
    p = LUGRE.predict(log.signals)[0]
    ctx = E.Context(log.signals, p)
    gear = [t for e in (E.Load(), E.Payload(), E.Quadrant()) for t in e.terms(ctx, None)]
    trained = _train(log, np.random.default_rng(3), lugre=LUGRE, terms=gear + [T.term("sign", T.SIGN), T.term("p", T.P)])
    paths = {}
    for kind in ("lugre", "mlp", "selmic", "nnacm", "dissipative", "residual", "augmented", "augmented-nn"):
        paths[kind] = str(folder / f"{kind}.npz")
        models.save_for_log(paths[kind], trained[kind], log, rows_used=len(log), seed=3)
    # diagnose --fix on the loaded log: the augmented model as the command writes it
    paths["fixed"] = str(folder / "fixed.npz")
    res = run("diagnose", paths["lugre"], full, "--fix", "-o", paths["fixed"], "-q")
    assert res.exit_code == 0, res.stderr
    return {"full": full, "bare": bare, "models": paths, "folder": folder}


KINDS = ["lugre", "mlp", "selmic", "nnacm", "dissipative", "residual", "augmented", "augmented-nn", "fixed"]


def _column(path, name):
    return pq.read_table(path).column(name).to_numpy()


def test_the_split_is_one_definition():
    assert set(logs.INPUTS).isdisjoint(logs.REFERENCES)
    assert {"tau_ext", "tau_f_true"} <= set(logs.REFERENCES)
    assert set(logs.ROBOT_MODEL) <= set(logs.INPUTS) and "tau_m" in logs.INPUTS
    assert "tau_ext" not in c.SIGNAL_ORDER


def test_the_models_read_inputs_only(files):
    for kind, path in files["models"].items():
        model, meta = models.load(path)
        assert set(model.required_inputs()) <= set(logs.INPUTS), kind
        assert not set(meta["inputs"]) & set(logs.REFERENCES), kind
    fixed, _ = models.load(files["models"]["fixed"])
    assert fixed.kind == "augmented" and fixed.effects            # the diagnosis added something


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("command", ["predict", "estimate-ext"])
def test_predictions_do_not_read_the_references(files, tmp_path, kind, command):
    column = "tau_f_pred" if command == "predict" else "tau_ext_pred"
    out = {}
    for which in ("full", "bare"):
        out[which] = str(tmp_path / f"{which}.parquet")
        res = run(command, files["models"][kind], files[which], "-o", out[which], "--batch-rows", 5000, "-q")
        assert res.exit_code == 0, res.stderr
    np.testing.assert_array_equal(_column(out["bare"], column), _column(out["full"], column))
    assert np.ptp(_column(out["full"], column)) > 0


@pytest.mark.parametrize("kind", KINDS)
def test_evaluate_and_diagnose_predict_the_same_without_references(files, kind):
    """evaluate scores the same prediction (the friction target alone changes: tau_ext is in it);
    diagnose's residual holds the same prediction."""
    model, meta = models.load(files["models"][kind])
    full, bare = logs.load_log(files["full"]), logs.load_log(files["bare"])
    pred, _ = residual(model, full)
    pred_bare, _ = residual(model, bare)
    np.testing.assert_array_equal(pred_bare, pred)
    result = evaluation.evaluate_one(model, meta, bare)
    assert result.external is None
    assert result.friction == metrics.errors(logs.friction_target(bare.signals), pred)
    assert evaluation.evaluate_one(model, meta, full).friction == metrics.errors(
        logs.friction_target(full.signals), pred)


@pytest.mark.parametrize("kind", ["lugre", "residual", "fixed"])
def test_report_predicts_the_same_without_references(files, tmp_path, kind):
    full, bare = logs.load_log(files["full"]), logs.load_log(files["bare"])
    summary = report.write_report(files["models"][kind], bare, str(tmp_path / "bare"))
    pred = models.load(files["models"][kind])[0].predict(full.signals)[0]
    assert "external" not in summary
    assert summary["friction"] == metrics.errors(logs.friction_target(bare.signals), pred)


def test_the_fixed_model_predicts_the_same_before_and_after_without_references(files):
    """diagnose --fix: the model written from the log with its references predicts the same on
    the log without them, and so does the diagnosis of the fixed model (before and after)."""
    fixed, _ = models.load(files["models"]["fixed"])
    full, bare = logs.load_log(files["full"]), logs.load_log(files["bare"])
    np.testing.assert_array_equal(fixed.predict(bare.signals)[0], fixed.predict(full.signals)[0])
    friction, error, _ = fixed.predict_parts(bare.signals)
    f_full, e_full, _ = fixed.predict_parts(full.signals)
    np.testing.assert_array_equal(friction, f_full)
    np.testing.assert_array_equal(error, e_full)


@needs_cc
@pytest.mark.parametrize("kind", ["lugre", "mlp", "residual", "augmented", "fixed"])
def test_exported_c_takes_no_reference(files, tmp_path, kind):
    """The exported step function takes inputs only; run on the log without references it gives
    what predict --precision double gives on the log with them."""
    path = files["models"][kind]
    model, _ = models.load(path)
    names = c.signals_of(model)
    assert not set(names) & set(logs.REFERENCES) and set(names) <= set(logs.INPUTS)
    out = tmp_path / "pred.parquet"
    res = run("predict", path, files["full"], "-o", out, "--precision", "double", "-q")
    assert res.exit_code == 0, res.stderr
    ref = _column(out, "tau_f_pred")
    header = str(tmp_path / "fr.h")
    assert run("export", path, "-o", header, "--prefix", "fr", "-q").exit_code == 0
    exe = str(tmp_path / "fr_driver")
    assert check.build(header, "fr", exe) == ""
    got = check.run(exe, check.signal_matrix(logs.load_log(files["bare"]).signals, names))
    assert np.max(np.abs(got - ref) / (ABS + REL * np.abs(ref))) <= 1.0


def test_a_model_file_whose_terms_read_tau_ext_is_refused(files, tmp_path):
    """A model written by an older fricli with the gear torque tau_g - tau_ext: refused with the
    term and how to refit, never read."""
    model = AugmentedModel(LUGRE, [T.term("tau_l held", T.HELDGRAVITY)], [0.05], effects=["quadrant"])
    spec, arrays = models.to_parts(model)
    spec["params"]["terms"][0]["factors"] = [{"f": "heldgear"}]
    meta = modelfile.base_meta()
    meta.update(kind="augmented", model=spec, joint=2, axis="rotary", units=logs.CANONICAL["rotary"],
                inputs=["qd", "t", "tau_ext", "tau_g"], provenance={}, fit={})
    old = str(tmp_path / "old.npz")
    modelfile.write(old, meta, arrays)
    res = run("predict", old, files["full"], "-o", tmp_path / "out.parquet")
    assert res.exit_code == errors.MODEL
    line, = res.stderr.strip().splitlines()
    assert "'tau_l held' reads the reference column tau_ext" in line and "diagnose" in line and "--fix" in line
    assert not (tmp_path / "out.parquet").exists()


def test_a_column_marked_as_reference_is_not_read(files, tmp_path):
    """A column whose field metadata says role: reference is carried through but never an input
    (here it would otherwise be a candidate of the diagnosis's column effect)."""
    import pyarrow as pa

    table = pq.read_table(files["full"])
    values = pa.array(np.asarray(table.column("tau_ext")) * 2.0)
    table = table.append_column(pa.field("sensor2", pa.float64(), metadata={"role": "reference"}), values)
    log = logs.from_table(table, name="marked")
    assert "sensor2" not in log.signals and "sensor2" in log.table.column_names
    assert not any(e.name == "column:sensor2" for e in E.library(log.signals))


# ------------------------------------------------------------------- a missing robot-model column


@pytest.fixture(scope="module")
def arm():
    """Two joints as ``fricli import`` writes them without --urdf: no tau_g, no tau_dyn."""
    import pyarrow as pa

    parts = []
    for joint, seed in ((2, 5), (3, 6)):
        part = sim.simulate("base", joint=2, seed=seed).select(["t", "q", "qd", "qdd", "tau_m"])
        parts.append(part.append_column("joint", pa.array(np.full(part.num_rows, joint))))
    return pa.concat_tables(parts)


def test_identify_on_an_arm_without_tau_g_refuses_with_the_fix(arm, tmp_path):
    log = write(arm, tmp_path / "arm.parquet")
    out = tmp_path / "models"
    res = run("identify", log, "-o", out, "-q")
    assert res.exit_code == errors.DATA
    line, = res.stderr.strip().splitlines()
    assert "no 'tau_g' column" in line and "unknown, not zero" in line
    assert "fricli dynamics LOG --urdf URDF" in line and "fricli import ... --urdf" in line and "--no-gravity" in line
    assert not out.exists() or not list(out.iterdir())


def test_predict_on_a_log_without_tau_g_refuses(files, arm, tmp_path):
    log = write(arm.filter(np.asarray(arm.column("joint")) == 2), tmp_path / "j2.parquet")
    res = run("predict", files["models"]["lugre"], log, "-o", tmp_path / "out.parquet")
    assert res.exit_code == errors.DATA and "no 'tau_g' column" in res.stderr
    assert not (tmp_path / "out.parquet").exists()


@pytest.mark.parametrize("how", ["options", "metadata"])
def test_declared_zero_proceeds_and_says_so(arm, tmp_path, how):
    """Declared by --no-gravity --no-dynamics or by the log's metadata key fricli.zero_columns: the
    fit proceeds, and stderr says once (not once per joint) that tau_g and tau_dyn were taken as 0."""
    log = write(declare_zero(arm, "tau_g", "tau_dyn") if how == "metadata" else arm, tmp_path / "arm.parquet")
    flags = ["--no-gravity", "--no-dynamics"] if how == "options" else []
    out = tmp_path / "models"
    res = run("identify", log, "-o", out, *flags, "--json")
    assert res.exit_code == 0, res.stderr
    notes = [ln for ln in res.stderr.splitlines() if ln.startswith("note:") and "taken as 0" in ln]
    assert len(notes) == 1 and "tau_g and no tau_dyn" in notes[0]
    fits = json.loads(res.stdout)["joints"]
    assert set(fits) == {"2", "3"}
    res = run("predict", out / "joint_2.npz", log, "--joint", 2, "-o", tmp_path / "p.parquet", *flags)
    assert res.exit_code == 0, res.stderr
    assert any(ln.startswith("note:") and "taken as 0" in ln for ln in res.stderr.splitlines())


def test_a_declaration_names_robot_model_columns_only(arm):
    table = declare_zero(arm, "tau_ext")
    with pytest.raises(errors.LogError, match="only tau_g and tau_dyn can be declared zero"):
        logs.from_table(table, name="arm", joint=2)
