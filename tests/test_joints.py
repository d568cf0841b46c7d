"""The joint rule (docs/joints.md) in every command, model folders and whole-arm runs."""

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run, no_inertia
from fricli import models
from fricli.core import errors, logs, modelset
from fricli.models.lugre import LuGreModel

PARAMS = {2: dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0),
          4: dict(fc=2.0, fs=2.5, vs=0.05, delta=1.0, fv=4.0, kc=0.02, ks=0.03, sigma0=1e4, sigma1=5.0)}
ROOT = Path(__file__).resolve().parent.parent
UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_ext": "Nm"}


def joint_columns(joint, n=2000, seed=0):
    """Constant-velocity sweeps at four speeds in both directions, then rest (enough to identify)."""
    t = np.arange(n) * 0.01
    seg = n // 10
    qd = np.concatenate([s * v * np.ones(seg) for v in (0.05, 0.1, 0.2, 0.4) for s in (1, -1)])
    qd = np.concatenate([qd, np.zeros(n - qd.size)])
    q = np.cumsum(qd) * 0.01
    tau_g = (10 if joint == 2 else 4) * np.sin(q + 0.3)
    tau_f = LuGreModel(**PARAMS[joint]).predict({"t": t, "qd": qd, "tau_g": tau_g})[0]
    ext = 0.5 * np.sin(0.7 * t)
    tau_m = tau_g + tau_f - ext + np.random.default_rng(seed).normal(0, 0.05, n)
    return {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_m": tau_m, "tau_g": tau_g, "tau_ext": ext}


def write_log(path, joints, interleave=True):
    """A long-format log of ``joints`` (None: no joint column); rows interleaved in time."""
    if joints is None:
        pq.write_table(no_inertia(logs.table_from_arrays(joint_columns(2), UNITS)), path)
        return str(path)
    parts = [dict(joint_columns(j, seed=j), joint=np.full(2000, j)) for j in joints]
    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    if interleave:
        order = np.argsort(np.concatenate([np.arange(2000)] * len(parts)), kind="stable")
        cols = {k: v[order] for k, v in cols.items()}
    pq.write_table(no_inertia(logs.table_from_arrays(cols, UNITS)), path)
    return str(path)


def half_moving_log(path):
    """Joints 2 and 4, joint 4 at rest throughout (nothing to identify)."""
    cols = [dict(joint_columns(j, seed=j), joint=np.full(2000, j)) for j in (2, 4)]
    for k in ("q", "qd", "qdd"):
        cols[1][k] = np.zeros(2000)
    pq.write_table(no_inertia(logs.table_from_arrays({k: np.concatenate([c[k] for c in cols]) for k in cols[0]},
                                                    UNITS)), path)


def save_lugre(path, joint):
    models.save(str(path), LuGreModel(**PARAMS[joint if joint is not None else 2]), joint=joint, axis="rotary",
                units=logs.CANONICAL["rotary"], provenance={})
    return str(path)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("joints")
    (d / "set").mkdir()
    return {"dir": d, "arm": write_log(d / "arm.parquet", [2, 4]), "j4": write_log(d / "j4.parquet", [4]),
            "plain": write_log(d / "plain.parquet", None),
            "m2": save_lugre(d / "m2.npz", 2), "m4": save_lugre(d / "m4.npz", 4), "anon": save_lugre(d / "anon.npz", None),
            "set": str(d / "set"), "set2": save_lugre(d / "set" / "joint_2.npz", 2),
            "set4": save_lugre(d / "set" / "joint_4.npz", 4)}


def one_error_line(res, code):
    assert res.exit_code == code, (res.exit_code, res.stderr)
    assert isinstance(res.exception, SystemExit), res.exception
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("fricli: error: "), res.stderr
    return lines[0]


def model_args(command, model, log, out):
    return {
        "adapt": ["adapt", model, log, "-o", out / "out.npz", "--epochs", "1"],
        "predict": ["predict", model, log, "-o", out / "out.parquet"],
        "estimate-ext": ["estimate-ext", model, log, "-o", out / "out.parquet"],
        "evaluate": ["evaluate", "--model", model, "--log", log],
        "report": ["report", model, log, "-o", out / "rep"],
        "diagnose": ["diagnose", model, log],
        "diagnose --fix": ["diagnose", model, log, "--fix", "-o", out / "out.npz"],
    }[command]


MODEL_COMMANDS = ["adapt", "predict", "estimate-ext", "evaluate", "report", "diagnose", "diagnose --fix"]
LOG_COMMANDS = ["identify", "train-base"] + MODEL_COMMANDS


def log_args(command, log, files, out):
    if command == "identify":
        return ["identify", log, "-o", out / "out.npz"]
    if command == "train-base":
        return ["train-base", log, "-o", out / "out.npz", "--steps", "5"]
    return model_args(command, files["anon"], log, out)


@pytest.mark.parametrize("command", MODEL_COMMANDS)
def test_wrong_joint_is_refused_the_same_way(files, tmp_path, command):
    """A model fitted on joint 2 on the rows of joint 4: exit 4 naming both joints, nothing written,
    whether the log holds only joint 4 or --joint 4 picks it from a log of both."""
    expected = f"fricli: error: {files['m2']}: the model was fitted on joint 2, not on joint 4 of "
    line = one_error_line(run(*model_args(command, files["m2"], files["j4"], tmp_path)), errors.MODEL)
    assert line.startswith(expected) and files["j4"] in line
    line = one_error_line(run(*model_args(command, files["m2"], files["arm"], tmp_path), "--joint", "4"),
                          errors.MODEL)
    assert line.startswith(expected) and files["arm"] in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", LOG_COMMANDS)
def test_joint_option_on_a_log_without_joint_column(files, tmp_path, command):
    line = one_error_line(run(*log_args(command, files["plain"], files, tmp_path), "--joint", "9"), errors.INPUT)
    assert "the log has no 'joint' column, so --joint 9 can neither select nor relabel its rows" in line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command", MODEL_COMMANDS)
def test_no_conflict_without_joint_names(files, tmp_path, command):
    """A model with no recorded joint on a named joint, and a named model on a log without a
    joint column, are used."""
    res = run(*model_args(command, files["anon"], files["j4"], tmp_path), "-q")
    assert res.exit_code == 0, res.stderr
    res = run(*model_args(command, files["m4"], files["plain"], tmp_path), "-q")
    assert res.exit_code == 0, res.stderr


@pytest.mark.parametrize("command", MODEL_COMMANDS)
def test_model_folder_without_the_log_joint(files, tmp_path, command):
    d = tmp_path / "only2"
    d.mkdir()
    save_lugre(d / "joint_2.npz", 2)
    line = one_error_line(run(*model_args(command, d, files["arm"], tmp_path)), errors.MODEL)
    assert f"{d}: no model for joint 4 of {files['arm']} (the folder holds joints 2; --joint 2 applies it alone)" in line


def test_several_joints_into_one_file_is_refused(files, tmp_path):
    line = one_error_line(run("identify", files["arm"], "-o", tmp_path / "m.npz"), errors.INPUT)
    assert "the log holds joints 2, 4: choose one with --joint, or give -o a folder" in line
    line = one_error_line(run("predict", files["anon"], files["arm"], "-o", tmp_path / "p.parquet"), errors.INPUT)
    assert "the log holds joints 2, 4: choose one with --joint, or give a model folder" in line


def test_an_output_ending_with_a_slash_is_a_folder_for_one_joint_too(files, tmp_path):
    res = run("identify", files["j4"], "-o", f"{tmp_path / 'one'}/", "-q")
    assert res.exit_code == 0, res.stderr
    assert [p.name for p in (tmp_path / "one").iterdir()] == ["joint_4.npz"]
    line = one_error_line(run("identify", files["plain"], "-o", f"{tmp_path / 'two'}/"), errors.OUTPUT)
    assert "names a folder, but" in line and "no 'joint' column" in line and not (tmp_path / "two").exists()


def test_identify_every_joint_into_a_folder(files, tmp_path):
    out = tmp_path / "arm"
    res = run("identify", files["arm"], "-o", out, "--json", "-q")
    assert res.exit_code == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["joint_2.npz", "joint_4.npz"]
    assert set(json.loads(res.stdout)["joints"]) == {"2", "4"}
    listing = modelset.listing(str(out))
    assert list(listing) == [2, 4]
    for joint, path in listing.items():
        _, meta = models.load(path)
        assert meta["joint"] == joint and meta["provenance"]["log_rows"] == 2000
        fc, other = meta["model"]["params"]["fc"], 6 - joint   # each file holds its own joint's fit
        assert abs(fc - PARAMS[joint]["fc"]) < abs(fc - PARAMS[other]["fc"])
        # the same as identifying that joint alone
        res = run("identify", files["arm"], "--joint", joint, "-o", tmp_path / f"alone{joint}.npz", "-q")
        assert res.exit_code == 0
        _, alone = models.load(str(tmp_path / f"alone{joint}.npz"))
        assert alone["model"]["params"] == meta["model"]["params"]
    # --if-changed per joint: only the missing joint is fitted again
    before = (out / "joint_2.npz").stat().st_mtime_ns
    (out / "joint_4.npz").unlink()
    res = run("identify", files["arm"], "-o", out, "--if-changed")
    assert res.exit_code == 0 and "joint_2.npz is up to date" in res.stderr
    assert (out / "joint_4.npz").exists() and (out / "joint_2.npz").stat().st_mtime_ns == before
    res = run("identify", files["arm"], "-o", out, "--if-changed", "-q")
    assert res.exit_code == errors.UNCHANGED


def test_one_joint_failing_leaves_the_others(files, tmp_path):
    half_moving_log(tmp_path / "half.parquet")
    out = tmp_path / "arm"
    line = one_error_line(run("identify", tmp_path / "half.parquet", "-o", out, "-q"), errors.DATA)
    assert "joint 4: " in line and "(models of joints 2 written)" in line
    assert [p.name for p in out.iterdir()] == ["joint_2.npz"]
    models.load(str(out / "joint_2.npz"))


def test_joints_failing_for_one_reason_are_named_together(tmp_path):
    """A recording of one joint moving, the others held: one reason, said once."""
    cols = [dict(joint_columns(2, seed=j), joint=np.full(2000, j)) for j in (1, 2, 3)]
    for held in cols[0], cols[2]:
        for k in ("q", "qd", "qdd"):
            held[k] = np.zeros(2000)
    pq.write_table(no_inertia(logs.table_from_arrays({k: np.concatenate([c[k] for c in cols]) for k in cols[0]},
                                                    UNITS)), tmp_path / "one.parquet")
    line = one_error_line(run("identify", tmp_path / "one.parquet", "-o", tmp_path / "arm", "-q"), errors.DATA)
    assert line.count("joints 1, 3: ") == 1 and "joint 1:" not in line and "joint 3:" not in line
    assert line.endswith("(models of joints 2 written)")
    assert f"    {line}\n" in (ROOT / "docs" / "joints.md").read_text()      # the line docs/joints.md shows


def test_train_base_adapt_and_diagnose_fix_into_folders(files, tmp_path):
    res = run("train-base", files["arm"], "-o", tmp_path / "nn", "--steps", "5", "--max-samples", "200", "-q")
    assert res.exit_code == 0, res.stderr
    res = run("predict", tmp_path / "nn", files["arm"], "-o", tmp_path / "p.parquet", "--json", "-q")
    report = json.loads(res.stdout)      # each joint's rows outside its model's envelope, and their sum
    assert sum(report["per_joint"][j]["outside"] for j in ("2", "4")) == report["extrapolation"]["rows"]
    res = run("adapt", tmp_path / "nn", files["arm"], "-o", tmp_path / "ad", "--epochs", "1", "-q")
    assert res.exit_code == 0, res.stderr
    res = run("diagnose", files["set"], files["arm"], "--fix", "-o", tmp_path / "fixed", "--json", "-q")
    assert res.exit_code == 0, res.stderr
    assert set(json.loads(res.stdout)["joints"]) == {"2", "4"}
    for name in ("nn", "ad", "fixed"):
        found = modelset.listing(str(tmp_path / name))
        assert list(found) == [2, 4], name
    _, meta = models.load(str(tmp_path / "ad" / "joint_4.npz"))
    assert meta["provenance"]["base"]["name"] == "joint_4.npz"   # its bytes: the sha256 below
    assert meta["provenance"]["job"]["inputs"]["base"] == modelfile_sha(tmp_path / "nn" / "joint_4.npz")


def modelfile_sha(path):
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.mark.parametrize("batch_rows", [7, 1000, 1_000_000])
def test_predict_a_folder_across_batches(files, tmp_path, batch_rows):
    """Each joint's rows get its own model, with the state carried per joint across batches
    that cut through the interleaved joints; rows keep their order and columns."""
    out = tmp_path / "p.parquet"
    res = run("estimate-ext", files["set"], files["arm"], "-o", out, "--batch-rows", batch_rows, "--json")
    assert res.exit_code == 0, res.stderr
    got = pq.read_table(out)
    src = pq.read_table(files["arm"])
    assert got.column("joint").equals(src.column("joint")) and got.column("t").equals(src.column("t"))
    assert got.schema.field("tau_f_pred").metadata == {b"unit": b"Nm"}
    report = json.loads(res.stdout)
    assert set(report["per_joint"]) == {"2", "4"} and report["rows"] == 4000
    joint = got.column("joint").to_numpy()
    for j in (2, 4):
        sig = logs.from_table(src, name="arm", joint=j).signals
        np.testing.assert_allclose(got.column("tau_f_pred").to_numpy()[joint == j],
                                   LuGreModel(**PARAMS[j]).predict(sig)[0], rtol=1e-12, atol=1e-12)
        assert report["per_joint"][str(j)]["rows"] == 2000
    # one joint of the folder with --joint: that joint's rows only
    res = run("predict", files["set"], files["arm"], "-o", tmp_path / "p4.parquet", "--joint", "4", "-q")
    assert res.exit_code == 0 and set(pq.read_table(tmp_path / "p4.parquet").column("joint").to_pylist()) == {4}


def test_time_must_increase_per_joint(files, tmp_path):
    table = pq.read_table(files["arm"])
    t = table.column("t").to_numpy().copy()
    t[501] = t[499]      # row 501 is joint 4's sample 250, which now repeats its sample 249's time
    table = table.set_column(table.schema.get_field_index("t"), table.schema.field("t"), pa.array(t))
    pq.write_table(table, tmp_path / "bad.parquet")
    line = one_error_line(run("predict", files["set"], tmp_path / "bad.parquet", "-o", tmp_path / "p.parquet",
                              "--batch-rows", 501), errors.INPUT)
    assert "duplicate timestamps of joint 4" in line


def test_evaluate_report_and_diagnose_a_folder(files, tmp_path):
    res = run("evaluate", "--model", f"lugre={files['set']}", "--log", f"arm={files['arm']}")
    assert res.exit_code == 0, res.stderr
    rows = [line for line in res.stdout.splitlines() if line.startswith("| lugre")]
    assert [r.split("|")[1].strip() for r in rows] == ["lugre (joint 2)", "lugre (joint 4)"]
    res = run("evaluate", "--model", files["set"], "--log", files["arm"], "--json")
    assert [r["joint"] for r in json.loads(res.stdout)["results"]] == [2, 4]
    res = run("report", files["set"], files["arm"], "-o", tmp_path / "rep", "-q")
    assert res.exit_code == 0, res.stderr
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "joint_2/index.html" in page and "joint_4/index.html" in page
    assert (tmp_path / "rep" / "joint_4" / "friction_velocity.png").exists()
    res = run("diagnose", files["set"], files["arm"], "--json")
    assert res.exit_code == 0, res.stderr
    assert set(json.loads(res.stdout)["joints"]) == {"2", "4"}
    res = run("diagnose", files["set"], files["arm"])
    assert "joint 2 (" in res.stdout and "joint 4 (" in res.stdout


def test_a_single_model_file_selects_its_own_joint(files, tmp_path):
    res = run("predict", files["m4"], files["arm"], "-o", tmp_path / "p.parquet", "-q")
    assert res.exit_code == 0, res.stderr
    assert set(pq.read_table(tmp_path / "p.parquet").column("joint").to_pylist()) == {4}


def test_model_file_names_by_joint():
    assert modelset.file_name(3) == "joint_3.npz"
    assert modelset.file_name("left/arm 1") == "joint_left_arm_1.npz"


def test_the_messages_in_docs_joints_md(tmp_path, monkeypatch):
    """The two messages docs/joints.md quotes are what the commands print."""
    from conftest import ROOT

    doc = (ROOT / "docs" / "joints.md").read_text()
    monkeypatch.chdir(tmp_path)
    write_log(tmp_path / "arm.parquet", [2, 4])
    save_lugre(tmp_path / "m2.npz", 2)
    line = one_error_line(run("predict", "m2.npz", "arm.parquet", "--joint", "4", "-o", "p.parquet"), errors.MODEL)
    assert f"    {line}\n" in doc
    half_moving_log(tmp_path / "half.parquet")
    line = one_error_line(run("identify", "half.parquet", "-o", "arm", "-q"), errors.DATA)
    assert f"    {line}\n" in doc


def test_predict_a_folder_drops_invalid_rows_in_place(files, tmp_path):
    table = pq.read_table(files["arm"])
    tau = table.column("tau_m").to_numpy().copy()
    tau[[11, 12, 3000]] = np.nan                   # rows of both joints, one batch boundary apart
    table = table.set_column(table.schema.get_field_index("tau_m"), table.schema.field("tau_m"), pa.array(tau))
    pq.write_table(table, tmp_path / "nan.parquet")
    out = tmp_path / "p.parquet"
    res = run("predict", files["set"], tmp_path / "nan.parquet", "-o", out, "--batch-rows", 12, "--drop-invalid")
    assert res.exit_code == 0, res.stderr
    assert res.stderr.count("dropped 3 rows") == 1
    keep = np.isfinite(tau)
    got = pq.read_table(out)
    np.testing.assert_array_equal(got.column("t").to_numpy(), table.column("t").to_numpy()[keep])
    np.testing.assert_array_equal(got.column("joint").to_numpy(), table.column("joint").to_numpy()[keep])


def test_missing_joint_values(files, tmp_path):
    """A joint column of nulls names no joint (like no column); some nulls are refused."""
    table = pq.read_table(files["plain"])
    nulls = table.append_column("joint", pa.nulls(table.num_rows))
    pq.write_table(nulls, tmp_path / "nulls.parquet")
    res = run("predict", files["m2"], tmp_path / "nulls.parquet", "-o", tmp_path / "p.parquet", "-q")
    assert res.exit_code == 0, res.stderr
    some = table.append_column("joint", pa.array([2] * 100 + [None] * (table.num_rows - 100), pa.int64()))
    pq.write_table(some, tmp_path / "some.parquet")
    for args in (["predict", files["m2"], tmp_path / "some.parquet", "-o", tmp_path / "p.parquet"],
                 ["identify", tmp_path / "some.parquet", "-o", tmp_path / "m.npz"]):
        line = one_error_line(run(*args), errors.INPUT)
        assert "the 'joint' column has missing values" in line


def test_a_joint_column_written_as_floats_names_the_same_joints():
    """A joint column of 2.0 (floats, as a spreadsheet or pandas writes whole numbers) is joint 2:
    a model fitted on joint 2 applies to it, and its model file is joint_2.npz."""
    from fricli.core import joints, modelset

    assert joints.same(2, 2.0) and joints.same("2", 2.0) and not joints.same(2, 2.5)
    assert modelset.file_name(2.0) == modelset.file_name(2) == "joint_2.npz" and joints.listed([1.0, 2.5]) == "1, 2.5"
    joints.check(2, 2.0, "m.npz", "log")        # no JointMismatch
