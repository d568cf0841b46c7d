"""`fricli predict` and `fricli estimate-ext`: batches, pipelines, joints, errors, any model kind."""

import io
import json
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import ROOT, invoke, make_table
from fricli import models
from fricli.applying import predicting
from fricli.core import errors, logs, metrics
from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.models.lugre import LuGreModel

PARAMS = dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0)


@register
class CountingModel(FrictionModel):
    """A stateful test kind: friction = c*qd + the number of rows seen before this batch."""

    kind = "test-counting"

    def __init__(self, c=2.0):
        self.c = c

    def predict(self, signals, state=None):
        seen = 0 if state is None else state
        n = len(signals["t"])
        return self.c * signals["qd"] + seen, seen + n

    def required_inputs(self):
        return {"t", "qd"}

    def get_params(self):
        return {"c": self.c}

    @classmethod
    def from_parts(cls, params, arrays, children):
        return cls(**params)


@register
class InertialModel(FrictionModel):
    """A test kind that reads the acceleration: friction = c*qdd."""

    kind = "test-inertial"

    def __init__(self, c=0.5):
        self.c = c

    def predict(self, signals, state=None):
        return self.c * signals["qdd"], None

    def required_inputs(self):
        return {"qdd"}

    def get_params(self):
        return {"c": self.c}

    @classmethod
    def from_parts(cls, params, arrays, children):
        return cls(**params)


def log_table(n=3000, seed=0, joint=None, with_ext=False):
    """A rotary log with friction from the LuGre model plus noise (and an external torque)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    qd = 0.4 * np.sign(np.sin(0.3 * t)) * (0.3 + np.abs(np.sin(0.05 * t)))
    q = np.cumsum(qd) * 0.01
    tau_g = 30 * np.sin(q + 0.5)
    qdd = np.gradient(qd, t)
    tau_f = LuGreModel(**PARAMS).predict({"t": t, "qd": qd, "tau_g": tau_g})[0]
    ext = 4 * np.sin(0.2 * t) if with_ext else np.zeros(n)
    tau_m = tau_g + 0.5 * qdd + tau_f - ext + rng.normal(0, 0.2, n)
    cols = {"t": t, "q": q, "qd": qd, "qdd": qdd, "tau_m": tau_m, "tau_g": tau_g, "tau_dyn": 0.5 * qdd,
            "label": np.array(["x"] * n)}
    if with_ext:
        cols["tau_ext"] = ext + rng.normal(0, 0.05, n)
    if joint is not None:
        cols = {"joint": np.full(n, joint), **cols}
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm",
             "tau_ext": "Nm"}
    table = logs.table_from_arrays(cols, units)
    return table.replace_schema_metadata({b"origin": b"test"})


def write(table, path, **kwargs):
    pq.write_table(table, path, **kwargs)
    return str(path)


@pytest.fixture
def model_file(tmp_path):
    path = str(tmp_path / "lugre.npz")
    models.save(path, LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    return path


def read(path_or_bytes):
    if isinstance(path_or_bytes, bytes):
        return pq.read_table(io.BytesIO(path_or_bytes))
    return pq.read_table(path_or_bytes)


def test_predict_adds_tau_f_pred_and_carries_everything(tmp_path, model_file):
    table = log_table()
    src = write(table, tmp_path / "log.parquet")
    out = tmp_path / "pred.parquet"
    res = invoke("predict", model_file, src, "-o", out)
    assert res.exit_code == 0, res.output
    assert res.stdout == ""
    assert "MAE" in res.stderr and "3,000 rows" in res.stderr
    got = read(str(out))
    assert got.column_names == table.column_names + ["tau_f_pred"]
    assert got.drop_columns(["tau_f_pred"]).equals(table)
    assert got.schema.metadata[b"origin"] == b"test"
    assert got.schema.field("q").metadata == {b"unit": b"rad"}
    assert got.schema.field("tau_f_pred").metadata == {b"unit": b"Nm"}
    sig = logs.from_table(table, name="x").signals
    np.testing.assert_allclose(got.column("tau_f_pred").to_numpy(), LuGreModel(**PARAMS).predict(sig)[0])


@pytest.mark.parametrize("command,added", [("predict", ["tau_f_pred"]),
                                           ("estimate-ext", ["tau_f_pred", "tau_ext_pred"])])
def test_batches_do_not_change_the_result(tmp_path, model_file, command, added):
    table = log_table(with_ext=True)
    src = write(table, tmp_path / "log.parquet", row_group_size=1000)
    figures = []
    tables = []
    for rows in (7, 1000, 100_000):
        out = tmp_path / f"p{rows}.parquet"
        res = invoke(command, model_file, src, "-o", out, "--batch-rows", rows, "--json", "-q")
        assert res.exit_code == 0, res.output
        data = json.loads(res.stdout)
        assert data["batches"] == -(-3000 // rows)
        figures.append(data)
        tables.append(read(str(out)))
    for got in tables:
        assert got.num_rows == 3000 and got.column_names == table.column_names + added
        assert got.drop_columns(added).equals(table)
        for name in added:
            np.testing.assert_allclose(got.column(name).to_numpy(), tables[-1].column(name).to_numpy(),
                                       rtol=1e-12, atol=1e-12)
    for other in figures[:-1]:
        for key in ["friction"] + (["external"] if command == "estimate-ext" else []):
            assert other[key]["n"] == figures[-1][key]["n"] == 3000
            assert other[key]["mae"] == pytest.approx(figures[-1][key]["mae"], rel=1e-9)
            assert other[key]["max"] == pytest.approx(figures[-1][key]["max"], rel=1e-9)


def test_units_that_disagree_are_flagged_once_whatever_the_batches(tmp_path, model_file):
    """The units of t, q and qd are checked on a file's first record batch: the note is the same
    whether the log is read in one batch or in many."""
    table = log_table()
    k = table.schema.get_field_index("t")
    table = table.set_column(k, table.schema.field(k), pa.array(table.column("t").to_numpy() * 1e3))
    src = write(table, tmp_path / "log.parquet")
    for rows in (300, 100_000):
        res = invoke("predict", model_file, src, "-o", tmp_path / f"p{rows}.parquet", "--batch-rows", rows)
        assert res.exit_code == 0, res.output
        assert res.stderr.count("times the rate of change of q over t") == 1, res.stderr


def test_json_figures_match_metrics(tmp_path, model_file):
    table = log_table()
    src = write(table, tmp_path / "log.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--json", "--batch-rows", 500)
    data = json.loads(res.stdout)
    sig = logs.from_table(table, name="x").signals
    expected = metrics.errors(logs.friction_target(sig), LuGreModel(**PARAMS).predict(sig)[0])
    for key in ("mae", "rmse", "max"):
        assert data["friction"][key] == pytest.approx(expected[key], rel=1e-9)
    assert data["friction"]["n"] == expected["n"] == 3000
    assert data["rows"] == 3000 and data["unit"] == "Nm" and "external" not in data


def test_stdin_to_stdout(tmp_path, model_file):
    buf = io.BytesIO()
    pq.write_table(log_table(), buf)
    res = invoke("predict", model_file, "-", "-o", "-", "--batch-rows", 256, input=buf.getvalue())
    assert res.exit_code == 0, res.stderr
    got = read(res.stdout_bytes)
    assert got.num_rows == 3000 and "tau_f_pred" in got.column_names
    assert "friction error" in res.stderr


def test_json_needs_a_file_output(model_file, tmp_path):
    res = invoke("predict", model_file, write(log_table(), tmp_path / "l.parquet"), "-o", "-", "--json")
    assert res.exit_code == errors.USAGE and "--json" in res.stderr


def test_state_is_carried_across_batches_for_any_kind(tmp_path):
    path = str(tmp_path / "count.npz")
    models.save(path, CountingModel(), joint=None, axis="rotary", units={}, provenance={})
    src = write(log_table(n=100), tmp_path / "l.parquet")
    res = invoke("predict", path, src, "-o", tmp_path / "p.parquet", "--batch-rows", 30, "-q")
    assert res.exit_code == 0, res.output
    got = read(str(tmp_path / "p.parquet"))
    offset = got.column("tau_f_pred").to_numpy() - 2.0 * got.column("qd").to_numpy()
    np.testing.assert_allclose(offset, np.repeat([0, 30, 60, 90], [30, 30, 30, 10]))


def test_time_must_increase_across_batches(tmp_path, model_file):
    table = log_table(n=100)
    t = table.column("t").to_numpy().copy()
    t[50:] -= 0.3                                  # row 50 steps back in time
    table = table.set_column(table.schema.get_field_index("t"), table.schema.field("t"), pa.array(t))
    src = write(table, tmp_path / "l.parquet")
    out = tmp_path / "p.parquet"
    out.write_bytes(b"old")
    res = invoke("predict", model_file, src, "-o", out, "--batch-rows", 50)
    assert res.exit_code == errors.INPUT
    assert "not increasing" in res.stderr and "row 50" in res.stderr
    assert out.read_bytes() == b"old"                # a failed run leaves the old output
    res = invoke("predict", model_file, src, "-o", out, "--batch-rows", 40)   # the second batch holds it
    assert res.exit_code == errors.INPUT and "first at row 50," in res.stderr, res.stderr


def test_a_row_is_named_by_its_row_in_the_file_in_every_batch_and_window(tmp_path, model_file):
    table = log_table(n=300)
    qd = table.column("qd").to_numpy().copy()
    qd[250] = np.nan
    table = table.set_column(table.schema.get_field_index("qd"), table.schema.field("qd"), pa.array(qd))
    src = write(table, tmp_path / "l.parquet")
    for extra in ([], ["--batch-rows", "64"], ["--batch-rows", "64", "--from", "30%"]):
        res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", *extra)
        assert res.exit_code == errors.INPUT and "(first at row 250," in res.stderr, (extra, res.stderr)


def test_a_failure_in_a_later_batch_leaves_stdout_without_a_footer(tmp_path, model_file):
    """Streamed to stdout (a pipe), the batches before the failure are out already: the file must
    read as damaged downstream, not as a complete log of fewer rows."""
    table = log_table(n=300)
    qd = table.column("qd").to_numpy().copy()
    qd[250] = np.nan
    table = table.set_column(table.schema.get_field_index("qd"), table.schema.field("qd"), pa.array(qd))
    src = write(table, tmp_path / "l.parquet")
    res = invoke("predict", model_file, src, "-o", "-", "--batch-rows", "64")
    assert res.exit_code == errors.INPUT and len(res.stdout_bytes) > 0
    with pytest.raises(pa.ArrowInvalid):
        pq.read_table(pa.BufferReader(res.stdout_bytes))
    whole = invoke("predict", model_file, write(log_table(n=300), tmp_path / "ok.parquet"), "-o", "-",
                   "--batch-rows", "64")
    assert whole.exit_code == 0 and pq.read_table(pa.BufferReader(whole.stdout_bytes)).num_rows == 300


def test_several_joints(tmp_path, model_file):
    t2, t4 = log_table(n=400, joint=2), log_table(n=300, seed=1, joint=4)
    both = pa.concat_tables([t4, t2])
    src = write(both, tmp_path / "both.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--batch-rows", 128, "-q")
    assert res.exit_code == 0, res.output
    got = read(str(tmp_path / "p.parquet"))
    assert got.num_rows == 400 and set(got.column("joint").to_pylist()) == {2}
    res = invoke("predict", model_file, src, "-o", tmp_path / "p4.parquet", "--joint", "4", "-q")
    assert res.exit_code == errors.MODEL and "fitted on joint 2, not on joint 4" in res.stderr
    assert not (tmp_path / "p4.parquet").exists()
    res = invoke("predict", model_file, src, "-o", tmp_path / "p5.parquet", "--joint", "5")
    assert res.exit_code == errors.INPUT and "no joint 5" in res.stderr


def test_single_other_joint_is_refused(tmp_path, model_file):
    src = write(log_table(n=200, joint=4), tmp_path / "j4.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet")
    assert res.exit_code == errors.MODEL and "fitted on joint 2, not on joint 4" in res.stderr


def test_log_without_velocity_is_read_whole(tmp_path, model_file):
    table = log_table().drop_columns(["qd", "qdd"])
    src = write(table, tmp_path / "l.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--batch-rows", 100, "--json",
                 "--cutoff", "20")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["batches"] == 1 and "derived" in data["read_whole"]
    sig = logs.from_table(table, name="x", cutoff_hz=20).signals
    np.testing.assert_allclose(read(str(tmp_path / "p.parquet")).column("tau_f_pred").to_numpy(),
                               LuGreModel(**PARAMS).predict(sig)[0])


def test_log_without_acceleration_is_read_in_batches_by_a_model_that_reads_none(tmp_path, model_file):
    """A measured velocity without an acceleration: a model that reads none (LuGre) predicts in
    record batches, no acceleration derived; a model that reads it has it derived from the
    velocity through the zero-phase filter, the log read whole."""
    table = log_table().drop_columns(["qdd"])
    src = write(table, tmp_path / "l.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--batch-rows", 1000, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["batches"] == 3 and data["read_whole"] is None
    sig = logs.from_table(table, name="x", qdd=False).signals
    assert "qdd" not in sig and "qdd" in logs.from_table(table, name="x").signals
    np.testing.assert_allclose(read(str(tmp_path / "p.parquet")).column("tau_f_pred").to_numpy(),
                               LuGreModel(**PARAMS).predict(sig)[0])
    inertial = str(tmp_path / "inertial.npz")
    models.save(inertial, InertialModel(), joint=None, axis="rotary", units={}, provenance={})
    res = invoke("predict", inertial, src, "-o", tmp_path / "q.parquet", "--batch-rows", 1000, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["batches"] == 1 and data["read_whole"] == "qdd derived with a zero-phase filter"
    np.testing.assert_allclose(read(str(tmp_path / "q.parquet")).column("tau_f_pred").to_numpy(),
                               0.5 * logs.from_table(table, name="x").signals["qdd"])
    # without qd both are derived, the acceleration from the derived velocity, whatever the model reads
    assert predicting.whole_reason(table.drop_columns(["qd"]).schema, None, qdd=False) == \
        "qd and qdd derived with a zero-phase filter"


def test_drop_invalid_in_batches(tmp_path, model_file):
    table = log_table(n=300)
    tau = table.column("tau_m").to_numpy().copy()
    tau[[10, 150, 151]] = np.nan
    table = table.set_column(table.schema.get_field_index("tau_m"), table.schema.field("tau_m"), pa.array(tau))
    src = write(table, tmp_path / "l.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--batch-rows", 100)
    assert res.exit_code == errors.INPUT and "--drop-invalid" in res.stderr
    res = invoke("predict", model_file, src, "-o", tmp_path / "p.parquet", "--batch-rows", 100, "--drop-invalid")
    assert res.exit_code == 0
    assert res.stderr.count("dropped 3 rows") == 1
    assert read(str(tmp_path / "p.parquet")).num_rows == 297


def test_drop_invalid_over_a_whole_batch_gives_what_one_batch_gives(tmp_path, model_file):
    """A batch whose rows are all invalid is dropped like any invalid rows: the result does not depend
    on how the log is cut into batches (a log with no valid row at all is refused either way)."""
    table = log_table(n=300)
    tau = table.column("tau_m").to_numpy().copy()
    tau[100:200] = np.nan
    table = table.set_column(table.schema.get_field_index("tau_m"), table.schema.field("tau_m"), pa.array(tau))
    src = write(table, tmp_path / "l.parquet")
    outs = {}
    for rows in (100, 1000):
        outs[rows] = tmp_path / f"p{rows}.parquet"
        res = invoke("predict", model_file, src, "-o", outs[rows], "--batch-rows", rows, "--drop-invalid")
        assert res.exit_code == 0, res.output
        assert res.stderr.count("dropped 100 rows") == 1
    assert read(str(outs[100])).num_rows == 200
    assert read(str(outs[100])).equals(read(str(outs[1000])))
    tau[:] = np.nan
    table = table.set_column(table.schema.get_field_index("tau_m"), table.schema.field("tau_m"), pa.array(tau))
    src = write(table, tmp_path / "none.parquet")
    res = invoke("predict", model_file, src, "-o", tmp_path / "n.parquet", "--batch-rows", 100, "--drop-invalid")
    assert res.exit_code == errors.INPUT and "no valid rows" in res.stderr and len(res.stderr.splitlines()) == 1


def test_estimate_ext(tmp_path, model_file):
    table = log_table(with_ext=True)
    src = write(table, tmp_path / "l.parquet")
    out = tmp_path / "e.parquet"
    res = invoke("estimate-ext", model_file, src, "-o", out, "--json", "--batch-rows", 700)
    assert res.exit_code == 0, res.output
    assert "external torque error" in res.stderr
    got = read(str(out))
    col = {c: got.column(c).to_numpy() for c in ("tau_g", "tau_dyn", "tau_f_pred", "tau_m", "tau_ext_pred")}
    np.testing.assert_allclose(col["tau_ext_pred"], col["tau_g"] + col["tau_dyn"] + col["tau_f_pred"] - col["tau_m"])
    assert got.schema.field("tau_ext_pred").metadata == {b"unit": b"Nm"}
    raw = json.loads(res.stdout)["external"]
    assert raw["mae"] == pytest.approx(metrics.errors(got.column("tau_ext").to_numpy(), col["tau_ext_pred"])["mae"])
    # the low-pass filter removes the measurement noise: the estimate gets closer to the sensor
    res = invoke("estimate-ext", model_file, src, "-o", out, "--json", "--lowpass", "2")
    assert res.exit_code == 0, res.output
    filtered = json.loads(res.stdout)
    assert filtered["external"]["mae"] < 0.7 * raw["mae"] and filtered["lowpass_hz"] == 2
    np.testing.assert_allclose(read(str(out)).column("tau_ext_pred").to_numpy(),
                               logs.lowpass(col["tau_ext_pred"], got.column("t").to_numpy(), 2.0))


def test_lowpass_above_nyquist_warns(tmp_path, model_file):
    src = write(log_table(n=200), tmp_path / "l.parquet")
    res = invoke("estimate-ext", model_file, src, "-o", tmp_path / "e.parquet", "--lowpass", "80")
    assert res.exit_code == 0 and "not applied" in res.stderr


def test_a_lowpass_slower_than_the_log_is_refused_in_one_line(tmp_path, model_file):
    """A cut-off whose period is longer than the log filters nothing but its padding (and, far
    below, makes scipy's filter start singular): one line and 6 (DATA), the output not written."""
    src = write(log_table(n=200), tmp_path / "l.parquet")
    t = read(str(src)).column("t").to_numpy()
    for cutoff in (0.5 / (t[-1] - t[0]), 1e-9):
        res = invoke("estimate-ext", model_file, src, "-o", tmp_path / "e.parquet", "--lowpass", str(cutoff))
        assert res.exit_code == errors.DATA and res.stderr.count("\n") == 1, res.stderr
        assert "is a period longer than the log" in res.stderr and not (tmp_path / "e.parquet").exists()
    assert invoke("estimate-ext", model_file, src, "-o", tmp_path / "e.parquet", "--lowpass",
                  str(2 / (t[-1] - t[0]))).exit_code == 0


@pytest.mark.parametrize("case,code,needle", [
    ("no-model", errors.MODEL, "no such file"),
    ("no-log", errors.INPUT, "no such file"),
    ("not-parquet", errors.INPUT, "not a Parquet file"),
    ("empty-stdin", errors.INPUT, "empty input"),
    ("empty-file", errors.INPUT, "empty input, not a Parquet log"),
])
def test_bad_inputs(tmp_path, model_file, case, code, needle):
    src = write(log_table(n=50), tmp_path / "l.parquet")
    args = ["predict", model_file, src, "-o", tmp_path / "p.parquet"]
    kwargs = {}
    if case == "no-model":
        args[1] = tmp_path / "missing.npz"
    elif case == "no-log":
        args[2] = tmp_path / "missing.parquet"
    elif case == "not-parquet":
        (tmp_path / "x.parquet").write_text("hello")
        args[2] = tmp_path / "x.parquet"
    elif case == "empty-file":
        (tmp_path / "x.parquet").write_bytes(b"")
        args[2] = tmp_path / "x.parquet"
    else:
        args[2] = "-"
        kwargs["input"] = b""
    res = invoke(*args, **kwargs)
    assert res.exit_code == code and needle in res.stderr
    assert "Traceback" not in res.output


def test_state_carried_over_batches_matches_one_pass():
    table = make_table(n=1000)
    sig = logs.from_table(table, name="x").signals
    model = LuGreModel(**PARAMS)
    parts, state = [], None
    for i in range(0, 1000, 33):
        out, state = model.predict({k: v[i:i + 33] for k, v in sig.items()}, state)
        parts.append(out)
    np.testing.assert_allclose(np.concatenate(parts), model.predict(sig)[0], rtol=1e-12, atol=1e-12)


def test_error_sums_match_metrics():
    rng = np.random.default_rng(0)
    y, p = rng.normal(size=1000), rng.normal(size=1000)
    acc = predicting.ErrorSums()
    for i in range(0, 1000, 300):
        acc.add(y[i:i + 300], p[i:i + 300])
    expected = metrics.errors(y, p)
    for key in ("mae", "rmse", "max"):
        assert acc.result()[key] == pytest.approx(expected[key], rel=1e-12)


def test_shell_pipeline(tmp_path, model_file):
    """cat LOG | fricli predict MODEL - -o - | python -c ... with real processes and pipes
    (the simulate stage of the documented pipeline is replaced by cat to keep the test quick)."""
    src = write(log_table(), tmp_path / "l.parquet")
    py = sys.executable
    # pq.ParquetFile, not pq.read_table: the latter's threaded reader aborts at exit now and then
    check = ("import sys, io, pyarrow.parquet as pq; t = pq.ParquetFile(io.BytesIO(sys.stdin.buffer.read())).read(); "
             "print(t.num_rows, 'tau_f_pred' in t.column_names)")
    cmd = f"cat '{src}' | '{py}' -m fricli predict '{model_file}' - -o - | '{py}' -c \"{check}\""
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, env=env,
                          cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["3000", "True"]
    assert "friction error" in proc.stderr


def test_a_model_of_another_robot_models_torques_is_named(tmp_path, model_file):
    """A model records the robot model (URDF sha256, gravity, rotor inertias, payload) of the log it
    was fitted on; applied to a log whose tau_g and tau_dyn came from another, every command says so."""
    robot = {"urdf_sha256": "a" * 64, "gravity": [0.0, 0.0, -9.81], "rotor_inertia": {"2": 0.5}, "payload": None}

    def log_with(record, name):
        table = make_table(500)
        table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                               b"fricli.dynamics": json.dumps(record).encode()})
        pq.write_table(table, tmp_path / name)
        return logs.load_log(str(tmp_path / name))

    same, other = log_with(robot, "same.parquet"), log_with({**robot, "rotor_inertia": {"2": 0.9}}, "other.parquet")
    assert models.provenance(same, rows_used=10)["robot_model"] == robot
    meta = {"provenance": {"robot_model": robot}}
    assert models.robot_model_note(meta, same) is None and models.robot_model_note({}, other) is None
    assert "(differing in rotor inertias)" in models.robot_model_note(meta, other, "m.npz")
    # a declared payload is a load, not another robot model: the model's load terms are there to see it
    loaded = log_with({**robot, "payload": {"mass": 2.8, "com": [0.0, 0.0, 0.0], "frame": "tool0"}}, "load.parquet")
    assert models.robot_model_note(meta, loaded) is None
    held = log_with({**robot, "held": ["finger"]}, "held.parquet")
    assert "(differing in held joints)" in models.robot_model_note(meta, held)
    models.save(model_file, LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={"robot_model": robot})
    for name, warned in (("same.parquet", False), ("other.parquet", True)):
        res = invoke("predict", model_file, tmp_path / name, "-o", tmp_path / "p.parquet", "-q")
        assert res.exit_code == 0, res.stderr
        assert ("another robot model" in res.stderr) == warned, res.stderr
        res = invoke("evaluate", "--model", model_file, "--log", tmp_path / name, "-q")
        assert ("another robot model" in res.stderr) == warned, res.stderr


def test_a_column_the_model_reads_and_the_log_lacks_names_log_and_model(tmp_path):
    """A temperature-dependent model on a log without `temp`: one line naming the log and the model
    (predict and evaluate alike), not the model's bare complaint."""
    path = str(tmp_path / "thermal.npz")
    models.save(path, LuGreModel(**PARAMS, t_ref=30.0, alpha_c=0.004, alpha_v=0.01), joint=None, axis="rotary",
                units=logs.CANONICAL["rotary"], provenance={})
    log = tmp_path / "cold.parquet"
    pq.write_table(make_table(500), log)
    res = invoke("predict", path, log, "-o", tmp_path / "p.parquet")
    assert res.exit_code == errors.DATA
    assert res.stderr.strip() == (f"fricli: error: {log}: the model depends on temperature but the log has no 'temp' "
                                  f"column ({path})")
    res = invoke("evaluate", "--model", f"warm={path}", "--log", log)
    assert res.exit_code == errors.DATA and res.stderr.strip().endswith("has no 'temp' column (warm)"), res.stderr
