"""Defective inputs as recorders and other tools write them: one clear refusal or the good rows
kept, never an internal error."""

import re

import numpy as np
import pyarrow as pa
import pytest

from conftest import invoke, make_table, write
from fricli.core import logs, modelfile
from fricli.core.errors import LogError, ModelFileError


def test_infinite_time_is_an_invalid_row_not_a_time_order_error():
    table = make_table()
    t = table.column("t").to_numpy().copy()
    t[50] = np.inf
    table = table.set_column(0, "t", pa.array(t))
    with pytest.raises(LogError, match=r"1 rows hold NaN, infinite .*first at row 50, columns t.*--drop-invalid"):
        logs.from_table(table, name="x")
    log = logs.from_table(table, name="x", drop_invalid=True)
    assert len(log) == 499 and np.isfinite(log.signals["t"]).all()


def test_missing_values_are_invalid_rows_that_drop_invalid_drops():
    table = make_table()
    tau = table.column("tau_m").to_numpy()
    table = table.set_column(3, "tau_m", pa.array(tau, mask=np.isin(np.arange(500), [7, 9])))
    with pytest.raises(LogError, match=r"'tau_m' has 2 missing values \(first at row 7\).*--drop-invalid"):
        logs.from_table(table, name="x")
    messages = []
    log = logs.from_table(table, name="x", drop_invalid=True, warn=messages.append)
    assert len(log) == 498 and len(log.table) == 498
    np.testing.assert_array_equal(log.signals["tau_m"], np.delete(tau, [7, 9]))
    assert any("dropped 2 of 500 rows" in m and "missing" in m for m in messages)


def test_missing_column_names_a_column_that_differs_in_case():
    table = make_table().rename_columns([c.upper() if c == "tau_m" else c for c in make_table().column_names])
    with pytest.raises(LogError, match=r"missing required column 'tau_m'.*'TAU_M'.*case"):
        logs.from_table(table, name="x")


@pytest.mark.parametrize("metadata", [{"fricli.import": "[1, 2]"}, {"fricli.dynamics": '"x"'},
                                      {"fricli.import": '{"robot": [1]}'}, {"fricli.dynamics": '{"held": 5}'},
                                      {"fricli.dynamics": '{"gravity": [0, 0, "a"], "urdf_sha256": "ab"}'},
                                      {"fricli.import": '{"robot": {"gravity": [0, 0]}}'}])
def test_robot_record_of_another_shape_counts_as_unrecorded(metadata):
    schema = make_table().schema.with_metadata(metadata)
    assert logs.robot_record(schema) == {}
    assert logs.robot_model(schema) is None and logs.gravity_of(schema) == logs.DEFAULT_GRAVITY


@pytest.mark.parametrize("listed", ['[["tau_g"]]', '[{"a": 1}]', "[null]"])
def test_zero_columns_of_other_values_refused(listed):
    table = make_table().drop_columns(["tau_g"]).replace_schema_metadata({"fricli.zero_columns": listed})
    with pytest.raises(LogError, match="only tau_g and tau_dyn can be declared zero"):
        logs.from_table(table, name="x")


def test_cli_reads_a_log_whose_import_record_is_not_an_object(tmp_path):
    table = make_table().replace_schema_metadata({"fricli.import": "[1, 2]"})
    write(table, tmp_path / "log.parquet")
    result = invoke("identify", tmp_path / "log.parquet", "--kind", "linear", "-o", tmp_path / "m.npz")
    assert result.exit_code == 0, result.output


META = {"format": modelfile.FORMAT, "format_version": modelfile.FORMAT_VERSION, "kind": "lugre"}


@pytest.mark.parametrize("key,value", [("joint", [1]), ("joint", {"a": 1}), ("provenance", [1]),
                                       ("units", "Nm"), ("units", None), ("model", [1]), ("kind", 5),
                                       ("inputs", "qd")])
def test_model_meta_of_the_wrong_shape_refused(key, value):
    data = modelfile.dumps(META | {key: value}, {"w": np.ones(3)})
    with pytest.raises(ModelFileError, match=rf"m\.npz: damaged model \(meta '{key}'"):
        modelfile.loads(data, "m.npz")


@pytest.mark.parametrize("value", [1e308, -1e39, float("inf"), float("nan")])
@pytest.mark.parametrize("where", ["top", "child", "list"])
def test_a_model_parameter_no_fit_writes_is_a_damaged_model(value, where):
    """fv = 1e308 was accepted: predictions of 1e307 Nm, an RMS error of inf, and exit 0."""
    params = {"fc": 1.0, "fv": value} if where == "top" else {"fc": 1.0, "pieces": [0.5, value]}
    spec = {"kind": "lugre", "params": params}
    if where == "child":
        spec = {"kind": "residual", "params": {}, "children": {"base": spec}}
    import io
    import json

    buf = io.BytesIO()   # as another tool writes it (fricli's writer refuses NaN and inf)
    np.savez(buf, meta=np.array(json.dumps(META | {"model": spec})))
    data = buf.getvalue()
    with pytest.raises(ModelFileError, match=r"m\.npz: damaged model \(parameter '(fv|pieces)' is .*NaN, infinite or huge"):
        modelfile.loads(data, "m.npz")
    spec_ok = {"kind": "lugre", "params": {"fc": 1.0, "fv": 3.0e38, "t_ref": None, "flag": True}}
    assert modelfile.loads(modelfile.dumps(META | {"model": spec_ok}, {}), "m.npz")[0]["model"] == spec_ok


def test_model_meta_of_the_right_shape_loads():
    meta = META | {"joint": "j2", "provenance": {}, "units": {"tau": "Nm"}, "model": {}, "inputs": ["qd"]}
    assert modelfile.loads(modelfile.dumps(meta, {}), "m.npz")[0] == meta
    assert modelfile.loads(modelfile.dumps(META | {"joint": None}, {}), "m.npz")[0]["joint"] is None


HEADED = """header = true
time = {column = "t", unit = "s"}

[[joints]]
name = 1
q = "q"
tau_m = "tau"
"""


def recording_of(text, mapping_text=HEADED):
    import tomllib

    from fricli.robot import recording
    from fricli.robot.mapping import parse_mapping

    return recording.read_recording(text.encode(), parse_mapping(tomllib.loads(mapping_text)), "rec.csv")


ROWS = "".join(f"{k * 0.01:.2f},{np.sin(k * 0.01):.6f},{1 + 0.1 * k:.1f}\n" for k in range(20))


@pytest.mark.parametrize("head", ["# recorded by the cell controller\n#\n", "\ufeff# recorded, 2024\n\n"])
def test_comment_lines_before_the_header_are_skipped(head):
    rec = recording_of(head + "t,q,tau\n" + ROWS)
    assert len(rec.lines) == 20 and not rec.defects
    np.testing.assert_allclose(rec.values["tau"], 1 + 0.1 * np.arange(20))


def test_a_header_written_as_a_comment_names_the_columns():
    """numpy.savetxt(header=...) writes '# t,q,tau' above the rows."""
    rec = recording_of("# t,q,tau\n" + ROWS)
    assert len(rec.lines) == 20 and not rec.defects and rec.lines[0] == 2


def test_comment_lines_before_rows_without_a_header_are_skipped():
    rec = recording_of("# run 4\n# t q tau\n" + ROWS, HEADED.replace("header = true", "header = false")
                       .replace('"t"', "1").replace('"q"', "2").replace('"tau"', "3"))
    assert len(rec.lines) == 20 and not rec.defects


NUMBERED = HEADED.replace("header = true", "header = false").replace('"t"', "1").replace('"q"', "2").replace('"tau"', "3")


@pytest.mark.parametrize("mapping", [HEADED, NUMBERED])
def test_a_byte_order_mark_is_not_part_of_the_first_line(mapping):
    """Without a header the mark made the first row's time non-numeric: the row was dropped."""
    text = ("t,q,tau\n" if mapping is HEADED else "") + ROWS
    rec = recording_of("\ufeff" + text, mapping)
    assert len(rec.lines) == 20 and not rec.defects
    np.testing.assert_allclose(rec.values["tau"] if mapping is HEADED else rec.values[3], 1 + 0.1 * np.arange(20))


def test_a_nul_byte_far_into_a_text_file_is_a_malformed_row():
    """A file with NUL bytes in its first 64 KiB is binary; a NUL further on (a block a crash left
    unwritten) is a damaged row: dropped and reported, the others kept."""
    lines = ("t,q,tau\n" + "".join(f"{k * 0.01:.2f},{np.sin(k * 0.01):.6f},{1 + 0.1 * k:.1f}\n"
                                    for k in range(5000))).splitlines(True)
    assert sum(map(len, lines[:4001])) > 65536
    lines[4000] = "\x00" + lines[4000]
    rec = recording_of("".join(lines))
    assert len(rec.lines) == 4999 and sum(d.count for d in rec.defects.values()) == 1
    with pytest.raises(LogError, match="a binary file"):
        recording_of("".join(lines[:10]) + "\x00" + "".join(lines[10:]))


def two_joints(b):
    a = make_table().append_column("joint", pa.array([2] * 500))
    return pa.concat_tables([a, b.append_column("joint", pa.array([3] * b.num_rows))])


def test_a_joints_bad_row_is_given_as_the_logs_row():
    b = make_table()
    tau = b.column("tau_m").to_numpy().copy()
    tau[5] = np.nan
    log = two_joints(b.set_column(3, "tau_m", pa.array(tau)))
    with pytest.raises(LogError, match=r"first at row 505, columns tau_m"):
        logs.from_table(log, name="x", joint=3)
    nulls = two_joints(b.set_column(3, "tau_m", pa.array(tau, mask=np.isnan(tau))))
    with pytest.raises(LogError, match=r"1 missing values \(first at row 505\)"):
        logs.from_table(nulls, name="x", joint=3)


def test_time_order_is_given_as_the_logs_row_after_rows_were_dropped():
    b = make_table()
    t, tau = b.column("t").to_numpy().copy(), b.column("tau_m").to_numpy().copy()
    tau[5] = np.nan
    t[100] = t[99]
    log = two_joints(b.set_column(0, "t", pa.array(t)).set_column(3, "tau_m", pa.array(tau)))
    with pytest.raises(LogError, match=r"duplicate timestamps \(first at row 600, t = 0\.99 s\)"):
        logs.from_table(log, name="x", joint=3, drop_invalid=True)
    with pytest.raises(LogError, match=r"duplicate timestamps \(first at row 100, t = 0\.99 s\)"):
        logs.from_table(b.set_column(0, "t", pa.array(t)).set_column(3, "tau_m", pa.array(tau)), name="x",
                        drop_invalid=True)


def test_time_stamps_that_float32_cannot_hold_apart_say_so():
    """Seconds since 1970 in float32 are 128 s apart: every row looks like the one before."""
    table = make_table()
    t = (table.column("t").to_numpy() + 1.7e9).astype(np.float32)
    table = table.set_column(0, pa.field("t", pa.float32(), metadata={"unit": "s"}), pa.array(t))
    with pytest.raises(LogError, match=r"duplicate timestamps \(first at row 1, t = 1700000000 s\); 't' is stored "
                                       r"as float32, whose steps are 128 s at this time: write it as float64"):
        logs.from_table(table, name="x")


def test_a_mapping_saved_with_a_byte_order_mark_reads():
    """Windows editors save UTF-8 with a byte order mark, which TOML parsers refuse."""
    from fricli.robot.mapping import load_mapping

    def load(text, tmp):
        tmp.write_bytes(text)
        return load_mapping(str(tmp))

    import pathlib
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        path = pathlib.Path(folder) / "map.toml"
        plain = load(HEADED.encode(), path)
        assert load("\ufeff".encode() + HEADED.encode(), path) == plain
        assert load(HEADED.encode("utf-16"), path) == plain


def test_decimal_columns_are_read_as_numbers():
    """A database export writes fixed-point decimals; they are numbers like any other."""
    import decimal

    table = make_table()
    tau = np.round(table.column("tau_m").to_numpy(), 4)
    column = pa.array([decimal.Decimal(f"{v:.4f}") for v in tau], type=pa.decimal128(12, 4))
    table = table.set_column(3, pa.field("tau_m", column.type, metadata={"unit": "Nm"}), column)
    np.testing.assert_allclose(logs.from_table(table, name="x").signals["tau_m"], tau, rtol=0, atol=1e-12)


@pytest.mark.parametrize("scale,unit,warned", [(1e9, "s", True), (1e9, "ns", False), (1.0, "s", False),
                                               (1e-7, "s", True), (1e3, "s", True), (1e3, "ms", False),
                                               (10.0, "s", False)])
def test_a_time_step_no_controller_samples_at_is_flagged(scale, unit, warned):
    """Nanoseconds labelled as seconds: every derivative and rate would be off by 1e9; milliseconds
    as seconds make the 100 Hz log a 0.1 Hz one (10 Hz, the slowest a controller samples at, passes)."""
    table = make_table()
    t = table.column("t").to_numpy() * scale
    table = table.set_column(0, pa.field("t", pa.float64(), metadata={"unit": unit}), pa.array(t))
    messages = []
    logs.from_table(table, name="x", warn=messages.append)
    flagged = [m for m in messages if "median time step" in m]
    assert bool(flagged) == warned, messages
    if warned:
        assert flagged == [f"warning: x: the median time step is {0.01 * scale:.3g} s, which no controller samples at: "
                           "check the unit of 't' (Parquet field metadata 'unit': s, ms, us or ns; docs/log-format.md)"]


def test_a_rotary_position_that_wraps_is_differentiated_unwrapped():
    """A log without qd whose position is recorded within one turn: its velocity comes from the
    unwrapped position (no spike of 2 pi / dt where it wraps), with a note."""
    t = np.arange(2000) / 100.0
    turning = 3.0 + 0.5 * np.sin(0.5 * t)                       # crosses pi back and forth
    wrapped = np.angle(np.exp(1j * turning))
    tau = 5 * np.sign(np.cos(0.5 * t))
    got = {}
    for name, q in (("turning", turning), ("wrapped", wrapped)):
        table = pa.table({"t": t, "q": q, "tau_m": tau})
        table = table.replace_schema_metadata({b"fricli.zero_columns": b'["tau_g", "tau_dyn"]'})
        messages = []
        got[name] = logs.from_table(table, name=name, warn=messages.append, cutoff_hz=5.0).signals["qd"]
        assert any("jumps by a turn where it wraps" in m for m in messages) == (name == "wrapped"), messages
    np.testing.assert_allclose(got["wrapped"], got["turning"], atol=1e-9)
    assert np.abs(got["wrapped"]).max() < 0.3


@pytest.mark.parametrize("header,row_end", [("t,q,tau,\n", ""), ("t,q,tau\n", ","), ("t,q,tau,\n", ",")])
def test_a_delimiter_ending_the_header_or_every_row_is_no_column(header, row_end):
    """Spreadsheet and LabVIEW exports end lines with a delimiter, sometimes the header's only."""
    rows = "".join(line + row_end + "\n" for line in ROWS.splitlines())
    rec = recording_of(header + rows)
    assert len(rec.lines) == 20 and not rec.defects
    np.testing.assert_allclose(rec.values["tau"], 1 + 0.1 * np.arange(20))


def test_a_header_longer_than_the_rows_otherwise_is_still_refused():
    with pytest.raises(LogError, match=r"no usable rows \(20 with wrong number of fields"):
        recording_of("t,q,tau,extra\n" + ROWS)


def test_two_models_of_one_joint_in_a_folder_are_both_named(tmp_path):
    from fricli.core import modelset

    data = modelfile.dumps(META | {"joint": 2}, {})
    (tmp_path / "joint_2.npz").write_bytes(data)
    (tmp_path / "copy of joint_2.npz").write_bytes(data)
    with pytest.raises(ModelFileError, match=r"two models of joint 2 \(copy of joint_2\.npz and joint_2\.npz\)"):
        modelset.listing(str(tmp_path))


def test_a_huge_time_bound_is_written_short():
    from fricli.core import timewindow

    assert timewindow.seconds_text(1714000059.9) == "1714000059.9"
    assert timewindow.seconds_text(1e300) == "1e+300"
    assert len(timewindow.seconds_text(-1.2345e30)) < 25


@pytest.mark.parametrize("column", ["q", "qd", "tau_m", "t", "tau_g"])
def test_an_input_column_marked_as_a_reference_is_refused(column):
    """Marked, q was left out silently (diagnose then failed inside), qd was derived instead of
    read, and tau_m or t were reported missing although the log has them."""
    table = make_table()
    i = table.schema.get_field_index(column)
    field = table.schema.field(i)
    table = table.set_column(i, field.with_metadata({**field.metadata, b"role": b"reference"}), table.column(i))
    with pytest.raises(LogError, match=rf"column '{column}' is marked as a reference .*but it is an input"):
        logs.from_table(table, name="x")


def test_a_reference_column_marked_as_one_is_read_as_before():
    table = make_table(tau_ext=np.ones(500))
    i = table.schema.get_field_index("tau_ext")
    table = table.set_column(i, table.schema.field(i).with_metadata({b"role": b"reference"}), table.column(i))
    assert logs.from_table(table, name="x").has("tau_ext")


def test_a_robot_record_as_fricli_writes_it_is_read():
    record = '{"urdf_sha256": "ab", "gravity": [0, 0, -9.81], "held": ["j7"], "rotor_inertia": null, "payload": null}'
    schema = make_table().schema.with_metadata({"fricli.dynamics": record})
    assert logs.held_of(schema) == ("j7",) and logs.gravity_of(schema) == (0, 0, -9.81)
    assert logs.robot_model(schema)["urdf_sha256"] == "ab"


@pytest.mark.parametrize("value", [0.0, 3.5])
def test_a_motor_torque_constant_while_the_joint_moves_both_ways_is_flagged(value):
    """A recorder writes zeros (or a last value) for a torque channel it did not record: the
    friction target built from it is meaningless."""
    table = make_table()
    table = table.set_column(3, table.schema.field(3), pa.array(np.full(500, value)))
    messages = []
    logs.from_table(table, name="x", warn=messages.append)
    assert [m for m in messages if "tau_m" in m] == [
        f"warning: x: 'tau_m' is {value:g} Nm on every one of the 500 rows while the joint moves both ways: not a "
        "measurement (a channel the recorder did not record?); the friction target and the external torque "
        "built from it are meaningless"]


def test_a_motor_torque_that_varies_or_a_joint_moving_one_way_is_not_flagged():
    messages = []
    logs.from_table(make_table(), name="x", warn=messages.append)
    one_way = make_table(n=50)   # 0.5 s of the sine: qd > 0 throughout
    one_way = one_way.set_column(3, one_way.schema.field(3), pa.array(np.zeros(50)))
    logs.from_table(one_way, name="x", warn=messages.append)
    assert not [m for m in messages if "tau_m" in m]


def _mapping(text):
    import tomllib

    from fricli.robot.mapping import parse_mapping

    return parse_mapping(tomllib.loads(text), "map.toml")


@pytest.mark.parametrize("joints,says", [
    ('[[joints]]\nname = 1\nq = 2\ntau_m = 2\n', "column 2 is mapped twice (joint 1's q and joint 1's tau_m)"),
    ('[[joints]]\nname = 1\nq = 2\ntau_m = 3\n[[joints]]\nname = 2\nq = 2\ntau_m = 4\n',
     "column 2 is mapped twice (joint 1's q and joint 2's q)"),
    ('[[joints]]\nname = 1\nq = 1\ntau_m = 3\n', "column 1 is mapped twice (the time and joint 1's q)")])
def test_a_column_mapped_to_two_signals_is_refused(joints, says):
    """A typo that maps the position column as the torque too imported the position as torque."""
    with pytest.raises(LogError, match=re.escape(says)):
        _mapping("time = 1\n" + joints)


def test_a_temperature_column_shared_by_the_joints_is_kept():
    mapping = _mapping("time = 1\n" + "".join(f"[[joints]]\nname = {j}\nq = {j + 1}\ntau_m = {j + 5}\ntemp = 9\n"
                                              for j in (1, 2, 3)))
    assert [jm.columns["temp"].ref for jm in mapping.joints] == [9, 9, 9]


RATED = HEADED.replace('time = {column = "t", unit = "s"}', "time = {rate = 100}")


@pytest.mark.parametrize("gap", ["\n", "  \n", "\t\r\n"])
def test_blank_lines_take_no_sample_time(gap):
    """With time = {rate = HZ} the k-th data line is at k / rate: a blank line is no data line
    (it counted as one, shifting every later row by a sample period, and a file written with a
    blank line after every row had its time doubled)."""
    lines = ROWS.splitlines(True)
    rec = recording_of("t,q,tau\n" + "".join(line + gap for line in lines), RATED)
    assert len(rec.lines) == 20 and not rec.defects
    np.testing.assert_allclose(rec.values[None], np.arange(20) / 100)


def test_a_garbage_line_keeps_its_sample_time():
    """A malformed line was a sample the recorder wrote badly: the rows after it keep their times."""
    lines = ROWS.splitlines(True)
    rec = recording_of("t,q,tau\n" + "".join(lines[:5]) + "1,2\n" + "".join(lines[6:]), RATED)
    np.testing.assert_allclose(rec.values[None], np.delete(np.arange(20), 5) / 100)


JOINED = """files = ["positions", "torques"]
time = {rate = 100}

[[joints]]
name = 1
q = {file = "positions", column = 1}
tau_m = {file = "torques", column = 1}
"""


@pytest.mark.parametrize("positions", [
    "".join(f"{k + 1}\n" + ("\n" if k == 4 else "") for k in range(20)),       # a blank line after row 5
    "# exported by the drive\n" + "".join(f"{k + 1}\n" for k in range(20)),   # a comment line first
    "".join(f"{k + 1}\n" for k in range(20))])
def test_files_joined_row_by_row_pair_their_kth_data_lines(positions):
    """Rows were paired by line number: a blank or comment line in one file paired every later
    row with the next row of the other file."""
    import tomllib

    from fricli.robot.joined import read_joined
    from fricli.robot.mapping import parse_mapping

    torques = "".join(f"{100 + k + 1}\n" for k in range(20))
    rec = read_joined([positions.encode(), torques.encode()], parse_mapping(tomllib.loads(JOINED)), ["p", "t"])
    q, tau = rec.values[1], rec.values[(1, 1)]
    assert len(q) == 20 and not rec.defects
    np.testing.assert_array_equal(tau - q, 100)
    np.testing.assert_allclose(rec.values[None], np.arange(20) / 100)


def test_blank_lines_between_rows_of_a_sample_rate_are_noted():
    from fricli.robot.importing import import_recording

    lines = ROWS.splitlines(True)
    data = ("t,q,tau\n" + "".join(line + "\n" for line in lines)).encode()
    import tomllib

    from fricli.robot.mapping import parse_mapping

    from fricli.robot.importing import _notices

    result = import_recording(data, parse_mapping(tomllib.loads(RATED)), "rec.csv")
    assert ("note", "note: rec.csv: 19 blank lines between the rows take no sample (rows are counted by data "
                    "line, without them)") in _notices(result.meta, "rec.csv", None)
    timed = import_recording(data, parse_mapping(tomllib.loads(HEADED)), "rec.csv")
    assert "blank_lines" not in timed.meta


def test_a_comment_above_the_header_is_not_taken_for_it():
    rec = recording_of("# a,b,c\nt,q,tau\n" + ROWS)
    assert len(rec.lines) == 20 and not rec.defects


def test_a_nan_joint_is_a_missing_joint():
    """A float joint column with NaN made a joint named 'nan' that selected no row ('the log is empty')."""
    table = make_table().append_column("joint", pa.array(np.where(np.arange(500) == 100, np.nan, 2.0)))
    with pytest.raises(LogError, match="the 'joint' column has missing values"):
        logs.joints_of(table, "x")


@pytest.mark.parametrize("head,names", [("# recorded by the cell\n\nt,q1,i1\n", ["t", "q1", "i1"]),
                                        ("# t,q1,i1\n", ["t", "q1", "i1"]), ("t,q1,i1\n", ["t", "q1", "i1"]),
                                        ("", None)])
def test_the_template_reads_the_columns_past_comment_lines(head, names):
    from fricli.robot.template import header_fields

    fields, count, delimiter = header_fields((head + "0.0,1.5,0.2\n0.01,1.6,0.3\n").encode(), "rec.csv")
    assert (fields, count, delimiter) == (names, 3, ",")


@pytest.mark.parametrize("t_scale,q_unit,qd_unit,ratio", [(1e3, "rad", "rad/s", 1e3), (1.0, "rad", "deg/s", 0.0175),
                                                           (1.0, "deg", "rad/s", 57.3), (1.0, "rad", "rad/s", None)])
def test_units_of_t_q_and_qd_that_disagree_are_flagged(t_scale, q_unit, qd_unit, ratio):
    """t in ms taken as s, or degrees taken as radians in one of q and qd: qd is no longer the
    rate of change of q, and every model reads the wrong one silently."""
    table = make_table(units={"q": q_unit, "qd": qd_unit})
    table = table.set_column(0, table.schema.field(0), pa.array(table.column("t").to_numpy() * t_scale))
    messages = []
    logs.from_table(table, name="x", warn=messages.append)
    flagged = [m for m in messages if "rate of change" in m]
    if ratio is None:
        assert not flagged, messages
    else:
        assert len(flagged) == 1 and f"qd is {ratio:.3g} times the rate of change of q over t" in flagged[0], messages


@pytest.mark.parametrize("arch", ["dissipative", "mlp"])
@pytest.mark.parametrize("value", [None, "x", -1.0])
def test_a_network_models_training_entry_of_the_wrong_type_is_a_damaged_model(arch, value, tmp_path):
    """A network model whose recorded learning rate is not a positive number: every command refuses
    the file as damaged (exit 4) instead of failing inside export's description of it."""
    from conftest import SAMPLE

    good, bad = tmp_path / "good.npz", tmp_path / "bad.npz"
    log = str(SAMPLE / "joint2_base.parquet")
    assert invoke("train-base", log, "-o", good, "--arch", arch, "--steps", "20", "-q").exit_code == 0
    meta, arrays = modelfile.read(str(good))
    meta["model"]["params"]["training"]["lr"] = value
    modelfile.write(str(bad), meta, arrays)
    for args in (("export", bad, "-o", tmp_path / "m.h"), ("predict", bad, log, "-o", tmp_path / "p.parquet")):
        done = invoke(*args)
        assert done.exit_code == 4 and "damaged" in done.output and "lr" in done.output, done.output


def test_predict_gives_a_joints_bad_row_as_the_files_row(tmp_path):
    """predict reads a log of several joints in batches, each joint's rows apart: a NaN in joint
    3's sixth row is the file's row 505, as the commands that read the log whole say."""
    from fricli import models
    from fricli.models.lugre import LuGreModel

    folder = tmp_path / "models"
    folder.mkdir()
    good = two_joints(make_table())
    for j in (2, 3):
        log = logs.from_table(good, name="good", joint=j)
        models.save_for_log(str(folder / f"j{j}.npz"), LuGreModel(5.0, 6.0, 0.05, 1.0, 10.0), log, rows_used=500)
    b = make_table()
    tau = b.column("tau_m").to_numpy().copy()
    tau[5] = np.nan
    bad = write(two_joints(b.set_column(3, "tau_m", pa.array(tau))), tmp_path / "bad.parquet")
    done = invoke("predict", folder, bad, "-o", tmp_path / "out.parquet")
    assert done.exit_code == 3 and "first at row 505" in done.output and "counted from" not in done.output, done.output


def test_predict_reads_a_log_whose_file_name_is_not_utf8(tmp_path):
    """A file name of bytes that are not UTF-8 (an old file system's Latin-1 name): predict reads
    it as identify does, instead of calling it "not a Parquet file"."""
    import os
    import shutil

    from conftest import SAMPLE
    from fricli import models
    from fricli.models.lugre import LuGreModel

    src = str(SAMPLE / "joint2_base.parquet")
    model = str(tmp_path / "m.npz")
    log = logs.load_log(src)
    models.save_for_log(model, LuGreModel(5.0, 6.0, 0.05, 1.0, 10.0), log, rows_used=len(log))
    odd = os.path.join(os.fsencode(str(tmp_path)), b"we\x80ird.parquet")
    shutil.copy(src, odd)
    done = invoke("predict", model, os.fsdecode(odd), "-o", tmp_path / "out.parquet", "-q")
    assert done.exit_code == 0, done.output


def test_a_joints_dead_torque_names_the_joint_in_a_file_of_several():
    """In a file of several joints, what one joint's rows show is said of that joint."""
    b = make_table()
    b = b.set_column(3, b.schema.field(3), pa.array(np.zeros(500)))
    messages = []
    logs.from_table(two_joints(b), name="x", joint=3, warn=messages.append)
    assert [m for m in messages if "tau_m" in m][0].startswith("warning: x, joint 3: 'tau_m' is 0 Nm")


def test_a_note_about_the_file_is_printed_once_for_all_its_joints(tmp_path):
    log = write(two_joints(make_table()).drop_columns(["tau_g", "tau_dyn"]), tmp_path / "two.parquet")
    result = invoke("identify", log, "--no-gravity", "--no-dynamics", "--kind", "linear", "-o", tmp_path / "m", "-q")
    assert result.exit_code == 0, result.output
    assert result.output.count("taken as 0, as declared") == 1
    again = invoke("identify", log, "--no-gravity", "--no-dynamics", "--kind", "linear", "-o", tmp_path / "m2", "-q")
    assert again.output.count("taken as 0, as declared") == 1   # once per command, not once per process
