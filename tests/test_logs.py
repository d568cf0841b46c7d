"""The log contract: required columns, units, derived motion, friction target sign."""

import types

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import make_table
from fricli.core import logs
from fricli.core.errors import DataError, LogError


def test_reads_si_log():
    log = logs.from_table(make_table(), name="x")
    assert log.axis == "rotary" and log.units["tau"] == "Nm"
    assert set(["t", "q", "qd", "qdd", "tau_m", "tau_g"]) <= set(log.signals)


def test_degrees_are_converted_to_radians():
    ref = make_table()
    t = ref.column("t").to_numpy()
    q = np.rad2deg(ref.column("q").to_numpy())
    qd = np.rad2deg(ref.column("qd").to_numpy())
    deg = logs.table_from_arrays({"t": t, "q": q, "qd": qd, "tau_m": ref.column("tau_m").to_numpy()},
                                 {"t": "s", "q": "deg", "qd": "deg/s", "tau_m": "N·m"})
    a = logs.from_table(ref, name="rad").signals
    b = logs.from_table(deg, name="deg").signals
    np.testing.assert_allclose(b["q"], a["q"], rtol=1e-12)
    np.testing.assert_allclose(b["qd"], a["qd"], rtol=1e-12)


def test_linear_axis_units():
    table = logs.table_from_arrays({"t": np.arange(10.0), "q": np.linspace(0, 1, 10), "tau_m": np.ones(10)},
                                   {"t": "s", "q": "mm", "tau_m": "N"})
    log = logs.from_table(table, name="lin")
    assert log.axis == "linear" and log.units["tau"] == "N"
    np.testing.assert_allclose(log.signals["q"], np.linspace(0, 1e-3, 10))


def test_mixed_axis_units_refused():
    table = logs.table_from_arrays({"t": np.arange(10.0), "q": np.zeros(10), "tau_m": np.ones(10)},
                                   {"q": "rad", "tau_m": "N"})
    with pytest.raises(LogError, match="mixes"):
        logs.from_table(table, name="x")


def test_unit_of_wrong_dimension_refused():
    table = make_table(units={"tau_g": "rad"})
    with pytest.raises(LogError, match="tau_g"):
        logs.from_table(table, name="x")
    # a time of another kind's unit says so (it was "does not fit a rotary axis", or "mixes rotary
    # and linear units" for metres)
    for unit in ("deg", "m", "Nm"):
        with pytest.raises(LogError, match=f"column 't' has unit '{unit}', not a unit of time"):
            logs.from_table(make_table(units={"t": unit}), name="x")
    with pytest.raises(LogError, match="column 'q' has unit 's', not a unit of angle"):
        logs.from_table(make_table(units={"q": "s"}), name="x")


@pytest.mark.parametrize("drop,needle", [("t", "'t'"), ("tau_m", "tau_m")])
def test_missing_required_column_is_named(drop, needle):
    table = make_table().drop_columns([drop])
    with pytest.raises(LogError, match=needle):
        logs.from_table(table, name="x")


def test_needs_q_or_qd():
    with pytest.raises(LogError, match="'q', 'qd'"):
        logs.from_table(make_table().drop_columns(["q", "qd"]), name="x")


def test_current_needs_kt():
    ref = make_table()
    table = logs.table_from_arrays({"t": ref.column("t").to_numpy(), "q": ref.column("q").to_numpy(),
                                    "i_m": ref.column("tau_m").to_numpy()}, {"i_m": "A"})
    with pytest.raises(LogError, match="--kt"):
        logs.from_table(table, name="x")
    log = logs.from_table(table, name="x", kt=2.0)
    np.testing.assert_allclose(log.signals["tau_m"], 2.0 * table.column("i_m").to_numpy())


def test_derived_velocity_and_acceleration_match_analytic():
    rate, n = 1000.0, 4000
    t = np.arange(n) / rate
    w = 2 * np.pi * 0.5
    q = 0.3 * np.sin(w * t)
    table = logs.table_from_arrays({"t": t, "q": q, "tau_m": np.zeros(n)}, {})
    log = logs.from_table(table, name="x", cutoff_hz=20.0)
    inner = slice(200, n - 200)  # away from the filter's edges
    np.testing.assert_allclose(log.signals["qd"][inner], 0.3 * w * np.cos(w * t[inner]), atol=2e-4 * 0.3 * w)
    np.testing.assert_allclose(log.signals["qdd"][inner], -0.3 * w * w * np.sin(w * t[inner]), atol=2e-3 * 0.3 * w * w)
    assert log.derived == {"columns": ["qd", "qdd"], "cutoff_hz": 20.0}


def test_given_velocity_is_kept():
    log = logs.from_table(make_table(), name="x")
    assert log.derived["columns"] == ["qdd"]
    np.testing.assert_array_equal(log.signals["qd"], make_table().column("qd").to_numpy())


def test_friction_target_sign_positive_along_motion():
    log = logs.from_table(make_table(), name="x")
    target = logs.friction_target(log.signals)
    qd = log.signals["qd"]
    assert np.all(np.sign(target[qd != 0]) == np.sign(qd[qd != 0]))
    np.testing.assert_allclose(target, 5 * np.sign(qd) + 10 * qd, atol=1e-12)


def test_target_and_external_torque_are_consistent():
    sig = {"t": np.arange(3.0), "tau_m": np.array([1.0, 2, 3]), "tau_g": np.array([0.5, 0, -1]),
           "tau_dyn": np.array([0.1, 0.2, 0.3]), "tau_ext": np.array([2.0, -1, 0])}
    target = logs.friction_target(sig)
    np.testing.assert_allclose(target, sig["tau_m"] + sig["tau_ext"] - sig["tau_g"] - sig["tau_dyn"])
    # a perfect friction prediction recovers the external torque exactly
    np.testing.assert_allclose(logs.external_torque(sig, target), sig["tau_ext"], atol=1e-12)


def test_nan_refused_with_count_and_row():
    tau = make_table().column("tau_m").to_numpy().copy()
    tau[[7, 9]] = np.nan
    table = make_table().set_column(3, "tau_m", pa.array(tau))
    with pytest.raises(LogError, match=r"2 rows.*row 7"):
        logs.from_table(table, name="x")
    messages = []
    log = logs.from_table(table, name="x", drop_invalid=True, warn=messages.append)
    assert len(log) == 498 and len(log.table) == 498 and "dropped 2" in messages[0]


@pytest.mark.filterwarnings("error")
def test_absurd_values_are_refused_like_nan_and_time_may_be_large():
    """Values beyond MAGNITUDE_LIMIT (uninitialised memory) are invalid rows, whose sum may
    overflow without a warning; one just within the limit is kept; t (absolute time) may be large."""
    table = make_table()
    tau = table.column("tau_m").to_numpy().copy()
    tau[[3, 4]] = 1e308                     # their sum overflows; each value is finite but absurd
    tau[7] = -logs.MAGNITUDE_LIMIT          # at the limit: kept
    with pytest.raises(LogError, match=r"2 rows hold NaN, infinite or absurd values .*first at row 3, columns tau_m"):
        logs.from_table(table.set_column(3, "tau_m", pa.array(tau)), name="x")
    log = logs.from_table(table.set_column(3, "tau_m", pa.array(tau)), name="x", drop_invalid=True)
    assert len(log) == 498
    t = table.column("t").to_numpy() + 1.7e9 # seconds since 1970
    assert len(logs.from_table(table.set_column(0, "t", pa.array(t)), name="x")) == 500


@pytest.mark.parametrize("kind,needle", [("dup", "duplicate"), ("back", "not increasing")])
def test_time_order(kind, needle):
    t = make_table().column("t").to_numpy().copy()
    t[5] = t[4] if kind == "dup" else t[4] - 1
    table = make_table().set_column(0, "t", pa.array(t))
    with pytest.raises(LogError, match=needle):
        logs.from_table(table, name="x")


def test_wrong_type_column():
    table = make_table().set_column(3, "tau_m", pa.array(["a"] * 500))
    with pytest.raises(LogError, match="tau_m.*type"):
        logs.from_table(table, name="x")


def test_empty_log():
    with pytest.raises(LogError, match="empty"):
        logs.from_table(make_table().slice(0, 0), name="x")


def test_joint_selection():
    a, b = make_table(), make_table()
    a = a.append_column("joint", pa.array([2] * 500))
    b = b.append_column("joint", pa.array([4] * 500))
    both = pa.concat_tables([a, b])
    with pytest.raises(LogError, match="choose one with --joint"):
        logs.from_table(both, name="x")
    assert logs.from_table(both, name="x", joint="4").joint == 4
    with pytest.raises(LogError, match="no joint 3"):
        logs.from_table(both, name="x", joint=3)


def test_with_column_keeps_field_metadata():
    table = logs.with_column(make_table(), "tau_f_pred", np.zeros(500), "Nm")
    assert logs.field_unit(table.schema.field("q")) == "rad"
    assert logs.field_unit(table.schema.field("tau_f_pred")) == "Nm"


def test_unreadable_inputs(tmp_path):
    with pytest.raises(LogError, match="no such file"):
        logs.load_log(str(tmp_path / "missing.parquet"))
    bad = tmp_path / "bad.parquet"
    bad.write_text("not parquet")
    with pytest.raises(LogError, match="not a Parquet file"):
        logs.load_log(str(bad))


def test_too_short_to_derive():
    table = logs.table_from_arrays({"t": np.arange(2.0), "q": np.zeros(2), "tau_m": np.zeros(2)}, {})
    with pytest.raises(DataError):
        logs.from_table(table, name="x")


@pytest.mark.parametrize("data", [b"", b"not parquet", None])
def test_stdin_spool_is_arrow_file_and_leaves_nothing(monkeypatch, tmp_path, data):
    """stdin reaches pyarrow as its own file, not a Python file object (reading through Python
    now and then aborts the interpreter at exit; docs/reliability.md); the spool's name is gone
    at once and the file closes with its ParquetFile, or at once on bad input."""
    import gc
    import io
    import tempfile
    import types

    import pyarrow as pa

    if data is None:
        sink = io.BytesIO()
        pq.write_table(make_table(100), sink)
        data = sink.getvalue()
    monkeypatch.setattr("sys.stdin", types.SimpleNamespace(buffer=io.BytesIO(data)))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    sources = []
    real = pq.ParquetFile

    def recording(source, **kwargs):
        sources.append(source)
        return real(source, **kwargs)

    monkeypatch.setattr(logs.pq, "ParquetFile", recording)
    try:
        pf = logs.stdin_parquet()
        assert not list(tmp_path.iterdir())
        assert pf.read().num_rows == 100
        del pf
    except LogError:
        assert data != b"" or not sources
    gc.collect()
    assert not list(tmp_path.iterdir())
    for source in sources:
        assert isinstance(source, pa.NativeFile) and not isinstance(source, pa.PythonFile)
        assert source.closed
    assert sources or data == b""


@pytest.mark.parametrize("phase", [0.0, 0.7, 1.9])
def test_derived_acceleration_has_no_filter_transient_at_the_ends(phase):
    """qdd derived through a low cut-off (10 Hz at 500 Hz): within the first and last 0.1 s its error
    stays below the acceleration itself (scipy's default padding left up to 7.6 times it)."""
    t = np.arange(0.0, 5.0, 0.002)
    w = 2 * np.pi * 0.5
    sig = {"t": t, "q": np.sin(w * t + phase)}
    logs.derive_motion(sig, 10.0)
    error = np.abs(sig["qdd"] + w ** 2 * np.sin(w * t + phase))
    assert max(error[:50].max(), error[-50:].max()) < w ** 2
    assert error[100:-100].max() < 0.05


def test_constant_acceleration_column_is_not_a_measurement():
    """A qdd column of zeros while the velocity varies is dropped with a note and derived."""
    n = 2000
    notes = []
    log = logs.from_table(make_table(n=n, qdd=np.zeros(n), units={"qdd": "rad/s^2"}), name="x", warn=notes.append)
    assert log.derived["columns"] == ["qdd"]
    assert any("qdd is constant" in m and "derived from the velocity" in m for m in notes)
    # for a reader that reads no acceleration it is dropped and not derived, and the note says so
    notes.clear()
    unread = logs.from_table(make_table(n=n, qdd=np.zeros(n), units={"qdd": "rad/s^2"}), name="x",
                             warn=notes.append, qdd=False)
    assert "qdd" not in unread.signals and unread.derived == {}
    assert any("qdd is constant" in m and "left out (not read)" in m for m in notes)
    t = np.arange(n) / 100.0
    inner = slice(200, n - 200)
    np.testing.assert_allclose(log.signals["qdd"][inner], -0.125 * np.sin(0.5 * t[inner]), atol=2e-3)
    # a measured acceleration is kept, and so is a constant one while the velocity is constant too
    qdd = -0.125 * np.sin(0.5 * t)
    assert logs.from_table(make_table(n=n, qdd=qdd, units={"qdd": "rad/s^2"}), name="x").derived == {}


def test_constant_velocity_column_while_the_position_moves_is_derived():
    n = 2000
    notes = []
    log = logs.from_table(make_table(n=n, qd=np.zeros(n)), name="x", warn=notes.append)
    assert log.derived["columns"] == ["qd", "qdd"]
    assert any("qd is constant" in m for m in notes)
    t = np.arange(n) / 100.0
    np.testing.assert_allclose(log.signals["qd"][200:-200], 0.25 * np.cos(0.5 * t[200:-200]), atol=2e-3)


def test_constant_velocity_sweep_keeps_its_velocity():
    """A constant-velocity sweep agrees with its constant qd (and qdd = 0): both kept."""
    n = 500
    t = np.arange(n) / 100.0
    table = logs.table_from_arrays({"t": t, "q": 0.2 * t, "qd": np.full(n, 0.2), "qdd": np.zeros(n),
                                    "tau_m": np.full(n, 3.0), "tau_g": np.zeros(n)}, {})
    log = logs.from_table(table, name="x", zero=("tau_dyn",))
    assert log.derived == {}


def test_a_job_derives_the_acceleration_only_where_it_reads_it(tmp_path):
    """A log with a measured velocity and no acceleration: identify and train-base (kinds that read
    none) and adapt over a base that reads none leave it out (no zero-phase filter over the whole
    log, none recorded as derived); diagnose, adapt over a base that reads it, and a reader of
    everything derive it."""
    from fricli import models
    from fricli.fitting import runs
    from fricli.models.lugre import LuGreModel

    table = make_table(n=2000)
    base = str(tmp_path / "lugre.npz")
    models.save(base, LuGreModel(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, sigma0=1e4, sigma1=5.0),
                joint=None, axis="rotary", units={}, provenance={})
    opts = runs.options("identify", {})
    for pipeline, given, reads in (("identify", None, False), ("train-base", None, False), ("adapt", base, False),
                                   ("diagnose", None, True), (None, None, True)):
        data = runs.read(table, "", "x", opts, base=given, pipeline=pipeline)
        assert ("qdd" in data.signals) == reads, pipeline
        assert data.derived == ({"columns": ["qdd"], "cutoff_hz": opts["cutoff"]} if reads else {}), pipeline
    assert runs.reads_acceleration("adapt", models.load(base)[0]) is False
    inertial = types.SimpleNamespace(required_inputs=lambda: {"qd", "qdd"})
    assert runs.reads_acceleration("adapt", inertial) is True


@pytest.mark.parametrize("keep, needle", [(("t", "qd"), "missing required column 'tau_m'"),
                                          (("qd", "tau_m"), "missing required column 't'"),
                                          (("t", "tau_m"), "needs at least one of the columns 'q', 'qd'")])
def test_a_log_without_a_required_column_is_input_not_a_missing_robot_model(tmp_path, keep, needle):
    """Without tau_g and a required column, the error is the required column (3 (INPUT)), not
    advice to add tau_g (6 (DATA)) that would not make the file a log."""
    from conftest import invoke
    from fricli.core import errors

    table = make_table()
    path = tmp_path / "l.parquet"
    pq.write_table(table.select(list(keep)), path)
    for args in (("identify", path, "-o", tmp_path / "m.npz"), ("train-base", path, "-o", tmp_path / "m.npz")):
        res = invoke(*args)
        assert res.exit_code == errors.INPUT and needle in res.stderr, (args, res.stderr)
