"""train-base --coupling: a dissipative network per motor of a coupled group (docs/drives.md,
"Neural friction per motor")."""

from __future__ import annotations


import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run
from fricli import models
from fricli.core import modelfile
from fricli.models.coupled import CoupledModel, motor_signals

STEPS = 300   # Adam steps per network: the tests check structure, not the last digit of accuracy


@pytest.fixture(scope="module")
def arm(coupled_arm_logs, tmp_path_factory):
    """The simulated arm's training and held-out logs (conftest), and the wrist's group model trained
    on the first."""
    folder, _ = coupled_arm_logs
    out = tmp_path_factory.mktemp("nn")   # an existing folder: the group's file in it
    res = run("train-base", folder / "train.parquet", "--coupling", "--joint", 5, "--steps", STEPS, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    return folder, out / "joints_5_6.npz"


def _true_rmse(tmp_path, model, test, joint) -> float:
    """RMS error [Nm] of ``fricli predict`` against the simulation's true friction of ``joint``."""
    out = tmp_path / f"p_{model.stem}_{joint}.parquet"
    res = run("predict", model, test, "--joint", joint, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    t = pq.read_table(out)
    err = t.column("tau_f_pred").to_numpy() - t.column("tau_f_true").to_numpy()
    return float(np.sqrt(np.mean(err ** 2)))


def test_coupling_writes_one_group_file_of_a_network_per_motor(arm):
    folder, path = arm
    assert sorted(p.name for p in path.parent.iterdir()) == ["joints_5_6.npz"]
    model, meta = models.load(str(path))
    assert isinstance(model, CoupledModel) and model.joints == (5, 6) and meta["joints"] == [5, 6]
    assert [m.kind for m in model.motors] == ["dissipative", "dissipative"]
    assert set(meta["fit"]["joints"]) == {"5", "6"} and len(meta["fit"]["motors"]) == 2
    job = meta["provenance"]["job"]
    assert job["command"] == "train-base" and job["options"]["coupling"] and job["options"]["joint"] == ["5", "6"]


def test_group_network_beats_per_joint_networks_on_held_out_data(tmp_path, arm):
    folder, group = arm
    train, test = folder / "train.parquet", folder / "test.parquet"
    for joint in (5, 6):
        single = tmp_path / f"j{joint}.npz"
        res = run("train-base", train, "--joint", joint, "--steps", STEPS, "-o", single, "-q")
        assert res.exit_code == 0, res.output
        coupled, alone = _true_rmse(tmp_path, group, test, joint), _true_rmse(tmp_path, single, test, joint)
        # a network of joint 5's own velocity cannot see motor 6 turning with joint 6
        assert alone > 3 * coupled, (joint, alone, coupled)


def test_every_motor_and_the_group_are_dissipative(arm, rng):
    _, path = arm
    model, _ = models.load(str(path))
    w = np.concatenate([rng.normal(size=2000) * 10.0 ** rng.uniform(-6, 3, 2000), [0.0, 1e-300, -1e-300]])
    for motor in model.motors:
        f = motor.predict(motor_signals(w))[0]
        assert np.all(f * w >= 0)
    qd = rng.normal(size=(2000, 2)) * 10.0 ** rng.uniform(-5, 1, (2000, 1))
    tau_f = model.predict_group(qd)
    f = model.motor_friction(model.transmission.motor_velocities(qd))
    power = np.sum(tau_f * qd, axis=1)
    assert np.all(power >= -1e-12 * np.sum(np.abs(f * model.transmission.motor_velocities(qd)), axis=1))


def test_save_load_round_trip_predicts_bit_identically(tmp_path, arm, rng):
    folder, path = arm
    model, meta = models.load(str(path))
    qd = rng.normal(size=(500, 2))
    meta2, arrays = modelfile.read(str(path))
    spec, again_arrays = models.to_parts(model)
    assert spec == meta2["model"] and again_arrays.keys() == arrays.keys()
    copy = tmp_path / "copy.npz"
    modelfile.write(str(copy), dict(meta2, model=spec), again_arrays)
    assert copy.read_bytes() == path.read_bytes()
    np.testing.assert_array_equal(models.load(str(copy))[0].predict_group(qd), model.predict_group(qd))
    member = models.load(str(copy))[0].member(5)
    got, _ = member.predict({"t": np.arange(500.0), "qd": qd[:, 0], "qd@6": qd[:, 1]})
    np.testing.assert_array_equal(got, model.predict_group(qd)[:, 0])


def test_a_linear_group_file_is_written_again_byte_for_byte(tmp_path, arm):
    folder, _ = arm
    path = tmp_path / "lin.npz"
    assert run("identify", folder / "train.parquet", "--coupling", "--joint", 5, "-o", path, "-q").exit_code == 0
    meta, arrays = modelfile.read(str(path))
    model, _ = models.load(str(path))
    assert model.motors is None and model.children() == {}
    spec, again = models.to_parts(model)
    copy = tmp_path / "copy.npz"
    modelfile.write(str(copy), dict(meta, model=spec), again)
    assert copy.read_bytes() == path.read_bytes()


def test_coupling_takes_dissipative_networks_only(tmp_path, arm):
    folder, _ = arm
    res = run("train-base", folder / "train.parquet", "--coupling", "--arch", "mlp", "-o", tmp_path / "m")
    assert res.exit_code == 2 and "dissipative networks" in res.output
    assert not (tmp_path / "m").exists()


def test_a_fleet_job_refuses_a_coupled_train_base(tmp_path):
    from fricli.fleet import manifest

    (tmp_path / "m.toml").write_text('[[robot]]\nname = "r1"\npipeline = "train-base"\nlogs = "*.parquet"\n'
                                     'options = { coupling = true }\n')
    with pytest.raises(manifest.ManifestError, match="use fricli train-base --coupling"):
        manifest.load(str(tmp_path / "m.toml"))


@pytest.mark.parametrize("cxx", [False, True], ids=["c99", "c++"])
def test_exported_network_group_matches_predict_double(cxx, tmp_path, arm):
    import export_check as check
    from test_drives import check_group_export

    if check.compiler(cxx) is None:
        pytest.skip("no compiler")
    folder, path = arm
    header = tmp_path / "wr.h"
    res = run("export", path, "--prefix", "wr", "-o", header, "-q")
    assert res.exit_code == 0, res.output
    assert "wr_step(wr_state *s, const double *qd, double *tau_f)" in header.read_text()
    check_group_export(header, "wr", path, folder / "test.parquet", tmp_path, cxx)
