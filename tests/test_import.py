"""fricli import: a delimited text recording + a TOML mapping -> a long-format log."""

import json
import re

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import ROOT, run_in, shared_data
from fricli.core import errors
from fricli.core.errors import DataError
from fricli.core.logs import friction_target, from_table
from fricli.robot import recording
from fricli.robot.importing import import_recording
from fricli.robot.mapping import apply_overrides, parse_mapping, parse_overrides

MAPPING = """
time = {column = 1, unit = "s"}

[[joints]]
name = 1
q = {column = 2, unit = "rad"}
qd = {column = 4, unit = "rad/s"}
i_m = {column = 6, unit = "A"}
kt = 2.0

[[joints]]
name = 2
q = 3
qd = 5
i_m = 7
kt = 4.0
"""


def rows(n=40):
    """Text rows: t, q1, q2, qd1, qd2, i1, i2, a status word (not mapped)."""
    t = 100.0 + np.arange(n) * 0.01
    out = []
    for k in range(n):
        q1, q2 = np.sin(t[k]), np.cos(t[k])
        out.append(f"{t[k]:.2f},{q1:.6f},{q2:.6f},{np.cos(t[k]):.6f},{-np.sin(t[k]):.6f},"
                   f"{0.5 + k / n:.4f},{-0.25 + k / n:.4f},ok")
    return out


def mapping(text=MAPPING):
    import tomllib

    return parse_mapping(tomllib.loads(text))


def parse(lines, text=MAPPING, end="\n", **kw):
    data = ("\n".join(lines) + end).encode()
    return import_recording(data, mapping(text), "rec.csv", **kw)


def run(*args, cwd, stdin=None):
    return run_in(cwd, *args, input=stdin)


def test_clean_recording_becomes_a_long_log_in_the_contract():
    lines = rows()
    result = parse(lines)
    table = result.table
    assert table.num_rows == 2 * len(lines)
    assert table.column_names == ["t", "joint", "q", "qd", "i_m", "tau_m"]
    assert table.column("joint").to_pylist() == [1] * 40 + [2] * 40
    units = {f.name: (f.metadata or {}).get(b"unit") for f in table.schema}
    assert units == {"t": b"s", "joint": None, "q": b"rad", "qd": b"rad/s", "i_m": b"A", "tau_m": b"Nm"}
    values = np.array([[float(v) for v in ln.split(",")[:7]] for ln in lines])
    np.testing.assert_array_equal(table.column("t").to_numpy()[40:], values[:, 0])
    np.testing.assert_array_equal(table.column("q").to_numpy()[40:], values[:, 2])
    np.testing.assert_allclose(table.column("tau_m").to_numpy()[40:], 4.0 * values[:, 6], rtol=1e-15)
    assert result.meta["dropped"] == {} and result.meta["kt"] == {"1": 2.0, "2": 4.0}
    assert result.meta["robot"] is None
    # the log reader takes it as it is, joint by joint
    log = from_table(table, name="out", joint="2")
    with pytest.raises(DataError, match="no 'tau_g' column.*--urdf"):   # without --urdf: unknown, not zero
        friction_target(log.signals)
    log = from_table(table, name="out", joint="2", zero=("tau_g", "tau_dyn"))
    np.testing.assert_allclose(friction_target(log.signals), 4.0 * values[:, 6], rtol=1e-15)


def test_header_names_units_and_string_joints_are_converted():
    text = """
header = true
delimiter = ";"
time = {column = "time_ms", unit = "ms"}
[[joints]]
name = "elbow"
q = {column = "pos", unit = "deg"}
tau_m = {column = "torque", unit = "Nm"}
temp = {column = "temp", unit = "C"}
"""
    data = "time_ms;pos;torque;temp\n0;90;1.5;30\n10;180;2.5;31\n20;270;3.5;32\n"
    table = import_recording(data.encode(), mapping(text), "rec.csv").table
    np.testing.assert_allclose(table.column("t").to_numpy(), [0.0, 0.01, 0.02])
    np.testing.assert_allclose(table.column("q").to_numpy(), [np.pi / 2, np.pi, 1.5 * np.pi])
    assert table.column("joint").to_pylist() == ["elbow"] * 3
    assert table.schema.field("temp").metadata[b"unit"] == b"degC"


def test_nanosecond_timestamps_and_milliamperes_are_converted():
    """A controller's clock in ns since 1970 (1.76e18: float64 keeps it to 256 ns) and a current in mA."""
    text = """
header = true
time = {column = "stamp", unit = "ns"}
[[joints]]
name = 1
q = "pos"
i_m = {column = "cur", unit = "mA"}
kt = 10.0
"""
    start = 1_764_000_000_000_000_000
    data = "stamp,pos,cur\n" + "".join(f"{start + k * 2_000_000},{0.01 * k},{1500 + k}\n" for k in range(50))
    table = import_recording(data.encode(), mapping(text), "rec.csv").table
    t = table.column("t").to_numpy()
    np.testing.assert_allclose(np.diff(t), 0.002, rtol=0, atol=5e-7)   # float64: 256 ns read, 2.4e-7 s stored
    np.testing.assert_allclose(table.column("i_m").to_numpy(), 1.5 + 0.001 * np.arange(50), rtol=1e-12)
    np.testing.assert_allclose(table.column("tau_m").to_numpy(), 15.0 + 0.01 * np.arange(50), rtol=1e-12)
    assert table.schema.field("i_m").metadata[b"unit"] == b"A"


@pytest.mark.parametrize("path", ["fast", "slow"])
def test_each_defect_is_dropped_and_reported_with_its_first_line(path):
    lines = rows()
    expected = list(range(len(lines)))
    if path == "slow":
        lines[4] = "100.04,0.1,0.2"                       # line 5: wrong number of fields
        lines[7] = lines[7].replace(",0.", ",x.", 1)      # line 8: non-numeric
        lines[20] = ",".join(["nan" if i == 5 else v for i, v in enumerate(lines[20].split(","))])
        lines[25] = lines[25] + ",extra"                  # line 26: wrong number of fields
        for k in (4, 7, 20, 25):
            expected.remove(k)
    lines[11] = lines[10]                                 # line 12: same time as line 11
    expected.remove(11)
    truncated = lines + [lines[-1][:12].replace("100.39", "100.40")]   # unterminated and cut short
    result = parse(truncated, end="")
    got = {k: (d.count, d.first_line) for k, d in result.recording.defects.items()}
    want = {"duplicate_time": (1, 12), "truncated": (1, 41)}
    if path == "slow":
        want.update(field_count=(2, 5), non_numeric=(2, 8))
    assert got == want
    assert list(result.recording.lines) == [k + 1 for k in expected]
    assert result.table.num_rows == 2 * len(expected)
    assert result.meta["dropped"]["truncated"] == {"count": 1, "first_line": 41, "what": "truncated last line"}


def test_a_non_numeric_value_in_an_unmapped_column_is_no_defect():
    lines = rows()
    lines[3] = lines[3].replace(",ok", ",fault")
    result = parse(lines)
    assert result.recording.defects == {} and result.table.num_rows == 80


def test_fast_and_slow_path_read_the_same_numbers():
    lines = rows()
    text = "\n".join(lines) + "\n"
    mp = mapping()
    fast = recording.read_recording(text.encode(), mp, "rec.csv")
    slow = recording.read_recording((text + "1,2\n").encode(), mp, "rec.csv")  # a bad row forces the slow path
    assert slow.defects["field_count"].first_line == 41 and not fast.defects
    for ref in fast.values:
        np.testing.assert_array_equal(fast.values[ref], slow.values[ref])
    np.testing.assert_array_equal(fast.lines, slow.lines)


def test_crlf_line_ends_read_like_lf():
    lines = rows()
    lf = parse(lines)
    crlf = import_recording(("\r\n".join(lines) + "\r\n").encode(), mapping(), "rec.csv")
    assert crlf.table.equals(lf.table.replace_schema_metadata(crlf.table.schema.metadata))


def test_an_unterminated_complete_last_line_is_kept():
    result = parse(rows(), end="")
    assert result.recording.defects == {} and result.recording.unterminated == 40
    assert result.table.num_rows == 80 and result.meta["unterminated_last_line"] == 40


def test_time_going_back_is_refused_unless_dropped():
    lines = rows()
    lines[30], lines[31] = lines[31], lines[30]     # line 32 goes back
    with pytest.raises(errors.LogError, match="time goes back at line 32"):
        parse(lines)
    result = parse(lines, drop_backward=True)
    assert {k: (d.count, d.first_line) for k, d in result.recording.defects.items()} == {"backward_time": (1, 32)}
    t = result.table.column("t").to_numpy()[:39]
    assert np.all(np.diff(t) > 0)


@pytest.mark.parametrize("content, message", [
    ("", "the recording is empty"),
    ("\n\n", "the recording is empty"),
    ("a,b,c,d,e,f,g,h\nx,y,z,w,v,u,s,r\n", "no usable rows (2 with non-numeric"),
    ("1,2,3,4,5,6,7,8\r1,2,3,4,5,6,7,8\r", "carriage returns that are not part of a CRLF"),
])
def test_nothing_usable_is_one_clear_error(content, message):
    with pytest.raises(errors.LogError, match=message.replace("(", r"\(")):
        import_recording(content.encode(), mapping(), "rec.csv")


@pytest.mark.parametrize("change, message", [
    (("kt = 4.0", "kt = -4.0"), "must be positive"),
    (("kt = 4.0", ""), "no drive gain"),
    (("q = 3", "q = 9"), "names column 9, but rows have 8 fields"),
    (("q = 3", "q = 0"), "1-based index"),
    (("q = 3", 'q = "pos"'), "header = false"),
    (('unit = "rad"}', 'unit = "furlong"}'), "unknown unit 'furlong'"),
    (('unit = "rad"}', 'unit = "A"}'), "does not fit column 'q'"),
    (("name = 2", "name = 1"), "joint 1 appears twice"),
    (("name = 2", 'name = "two"'), "all integers or all strings"),
    (("kt = 4.0", "kt = 4.0\ngain = 4.0"), "unknown key 'gain'"),
    (("i_m = 7", "tau_m = 7"), "kt applies to a current column"),
])
def test_mapping_mistakes_are_input_errors(change, message):
    text = MAPPING.replace(*change)
    assert text != MAPPING
    with pytest.raises(errors.LogError, match=message):
        import_recording(("\n".join(rows()) + "\n").encode(), mapping(text), "rec.csv")


def test_kt_options_override_the_mapping():
    mp = apply_overrides(mapping(), kt=parse_overrides(["2=5.5"], "--kt"))
    table = import_recording(("\n".join(rows()) + "\n").encode(), mp, "rec.csv").table
    i_m, tau_m = table.column("i_m").to_numpy()[40:], table.column("tau_m").to_numpy()[40:]
    np.testing.assert_allclose(tau_m, 5.5 * i_m, rtol=1e-15)
    for bad in (["2"], ["2=abc"], ["2=-1"], ["=3"]):
        with pytest.raises(errors.LogError, match="JOINT=VALUE"):
            parse_overrides(bad, "--kt")
    with pytest.raises(errors.LogError, match="no joint 7"):
        apply_overrides(mapping(), kt={"7": 1.0})


# ---------------------------------------------------------------------- the command


def imported_with_a_short_row(tmp_path, output):
    """rec.csv (a short row at line 5) and map.toml in ``tmp_path``, imported with --kt 1=3 to
    ``output``: (the recording's lines, the command's result)."""
    lines = rows()
    lines[4] = "100.04,0.1"
    (tmp_path / "rec.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "map.toml").write_text(MAPPING)
    res = run("import", "rec.csv", "--mapping", "map.toml", "--kt", "1=3", "-o", output, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    return lines, res


def test_command_reports_defects_and_writes_atomically(tmp_path):
    lines, res = imported_with_a_short_row(tmp_path, "out.parquet")
    assert "warning: rec.csv: dropped 1 row with wrong number of fields (first at line 5: 2 fields, 8 expected)" \
        in res.stderr
    assert "imported 39 rows x 2 joints from rec.csv -> out.parquet" in res.stderr
    table = pq.read_table(tmp_path / "out.parquet")
    meta = json.loads(table.schema.metadata[b"fricli.import"])
    assert meta["kt"] == {"1": 3.0, "2": 4.0} and meta["rows"] == 39
    assert meta["dropped"]["field_count"]["first_line"] == 5
    # a refused recording leaves the previous output untouched
    before = (tmp_path / "out.parquet").read_bytes()
    lines[30], lines[31] = lines[31], lines[30]
    (tmp_path / "rec.csv").write_text("\n".join(lines) + "\n")
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == errors.INPUT
    assert res.stderr.startswith("fricli: error: rec.csv: time goes back at line 32")
    assert len(res.stderr.splitlines()) == 1
    assert (tmp_path / "out.parquet").read_bytes() == before


def test_command_reads_stdin_and_refuses_a_missing_mapping(tmp_path):
    (tmp_path / "map.toml").write_text(MAPPING)
    res = run("import", "-", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path,
              stdin="\n".join(rows()) + "\n")
    assert res.returncode == 0, res.stderr
    assert pq.read_table(tmp_path / "out.parquet").num_rows == 80
    res = run("import", "-", "--mapping", "none.toml", "-o", "out.parquet", cwd=tmp_path, stdin="")
    assert res.returncode == errors.INPUT and "none.toml: no such mapping file" in res.stderr
    (tmp_path / "bad.toml").write_text("time = [\n")
    res = run("import", "-", "--mapping", "bad.toml", "-o", "out.parquet", cwd=tmp_path, stdin="")
    assert res.returncode == errors.INPUT and "not a valid TOML mapping" in res.stderr


def test_every_ur10e_recording_imports(tmp_path):
    folder = shared_data("ur10e")
    from fricli.robot.mapping import load_mapping

    mp = load_mapping(str(ROOT / "docs" / "ur10e-mapping.toml"))
    files = sorted(folder.glob("*/*.csv"))
    assert len(files) == 21
    unterminated = []
    for path in files:
        data = path.read_bytes()
        result = import_recording(data, mp, path.name)
        lines = data.count(b"\n") + (not data.endswith(b"\n"))
        dropped = sum(d.count for d in result.recording.defects.values())
        assert result.meta["rows"] + dropped == lines, path.name   # every line is kept or reported
        assert result.recording.defects == {}, path.name            # as docs/robot-import.md says
        if result.recording.unterminated:
            unterminated.append(path.name)
        assert result.table.num_rows == 6 * result.meta["rows"]
        log = from_table(result.table, name=path.name, joint="2", zero=("tau_g", "tau_dyn"))
        assert np.isfinite(friction_target(log.signals)).all()
    assert unterminated == ["ur-20_02_19_14harm50sec.csv"]


# ---------------------------------------------------------------------- controller dumps with garbage rows

# what a controller's dump holds before (or after) the recording proper: t, q1, q2, qd1, qd2, i1, i2, status
GARBAGE = [
    "0,0,0,0,0,0,0,ok",                              # rows of zeros
    "0,0,0,0,0,0,0,ok",
    "8.5e+150,1e150,-3e150,0,7e149,0,0,ok",          # uninitialised memory
    "-3.2,0.5,0.5,0.1,0.1,0.2,0.2,ok",               # time far before the recording
    "1e9,0.5,0.5,0.1,0.1,0.2,0.2,ok",                # and far after it
]


@pytest.fixture
def dump():
    """A recording of 60 rows after the five garbage rows of a controller's dump (lines 1-5)."""
    return GARBAGE + rows(60)


def dropped(result):
    return {k: d["lines"] for k, d in result.meta["dropped"].items()}


@pytest.mark.parametrize("drop_backward", [False, True])
def test_garbage_rows_before_a_recording_are_dropped_and_reported(dump, drop_backward):
    result = parse(dump, drop_backward=drop_backward)
    assert dropped(result) == {"implausible": [[3, 3]], "zero_row": [[1, 2]], "time_outside": [[4, 5]]}
    assert list(result.recording.lines) == list(range(6, 66))
    clean = parse(rows(60)).table
    assert result.table.replace_schema_metadata(None).equals(clean.replace_schema_metadata(None))


def test_garbage_rows_inside_and_after_a_recording_are_dropped_and_reported():
    lines = rows(80)
    lines[29] = "1e9" + lines[29][6:]                      # line 30: time far ahead
    lines[49] = "0,0,0,0,0,0,0,ok"                         # line 50: zeros
    lines[59] = lines[59].replace(",0.", ",1e+200", 1)     # line 60: an absurd position
    lines[69] = "-5" + lines[69][6:]                       # line 70: time far back
    lines += ["3.0,0.1,0.1,0.1,0.1,0.1,0.1,ok", "0,0,0,0,0,0,0,ok", "1e300,1,1,1,1,1,1,ok"]   # lines 81-83
    result = parse(lines)
    assert dropped(result) == {"implausible": [[60, 60]], "zero_row": [[50, 50], [82, 82]],
                               "time_outside": [[81, 81], [83, 83]], "time_jump": [[30, 30], [70, 70]]}
    kept = [k for k in range(1, 81) if k not in (30, 50, 60, 70)]
    assert list(result.recording.lines) == kept
    t = result.table.column("t").to_numpy()[:len(kept)]
    np.testing.assert_array_equal(t, [float(lines[k - 1].split(",")[0]) for k in kept])


def test_a_dump_interrupted_by_garbage_keeps_the_rows_on_both_sides():
    """The dump wrote zeros over 150 samples and then 30 lines of text: the time steps over the
    lines they took, so the recording goes on across them (the rows before are not a shorter
    recording of their own)."""
    lines = rows(400)
    lines[100:250] = ["0,0,0,0,0,0,0,ok"] * 150
    lines[250:280] = ["ERROR: buffer overrun"] * 30
    result = parse(lines)
    assert result.meta["dropped"]["field_count"]["count"] == 30
    assert {k: d["lines"] for k, d in result.meta["dropped"].items() if k != "field_count"} == {"zero_row": [[101, 250]]}
    assert list(result.recording.lines) == list(range(1, 101)) + list(range(281, 401))


def test_a_spike_of_one_or_two_samples_is_dropped_and_a_burst_is_kept():
    """A velocity glitch of 500 rad/s in a joint moving at 1 (one sample at line 100, two at lines
    200-201) would become the log's top speed, and every row would count as at rest; they are
    dropped and reported. Five samples of the same size are a burst: kept."""
    def with_qd1(lines, at, value):
        f = lines[at].split(",")
        f[3] = value
        lines[at] = ",".join(f)

    lines = rows(400)
    for at in (99, 199, 200):
        with_qd1(lines, at, "500.0")
    result = parse(lines)
    assert dropped(result) == {"spike": [[100, 100], [200, 201]]}
    assert float(np.abs(result.table.column("qd").to_numpy()).max()) < 1.01
    burst = rows(400)
    for at in range(99, 104):
        with_qd1(burst, at, "500.0")
    assert parse(burst).meta["dropped"] == {}


def test_the_longest_consistent_stretch_wins_over_a_shorter_one():
    lines = rows(30) + [ln.replace("100.", "500.", 1) for ln in rows(50)]     # a jump of 400 s at line 31
    result = parse(lines)
    assert dropped(result) == {"time_outside": [[1, 30]]}
    assert list(result.recording.lines) == list(range(31, 81))


def test_the_command_reports_garbage_rows_with_their_lines(tmp_path, dump):
    (tmp_path / "rec.csv").write_text("\n".join(dump) + "\n")
    (tmp_path / "map.toml").write_text(MAPPING)
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert res.stderr.splitlines() == [
        "warning: rec.csv: dropped 1 row with a value of implausible magnitude (line 3)",
        "warning: rec.csv: dropped 2 rows with all values zero (lines 1-2)",
        "warning: rec.csv: dropped 2 rows with time not continuing the recording (before or after its longest "
        "consistent stretch) (lines 4-5)",
        "imported 60 rows x 2 joints from rec.csv -> out.parquet"]
    meta = json.loads(pq.read_table(tmp_path / "out.parquet").schema.metadata[b"fricli.import"])
    assert meta["dropped"]["zero_row"] == {"count": 2, "first_line": 1, "what": "all values zero", "lines": [[1, 2]]}


@pytest.mark.parametrize("mark, spelled", [(";", ";"), ("\t", "\\t"), (" ", " ")])   # " ": UR's RTDE recorder
def test_another_delimiter_than_the_mappings_is_named(mark, spelled):
    data = ("\n".join(ln.replace(",", mark) for ln in rows()) + "\n").encode()
    with pytest.raises(errors.LogError, match=re.escape(f'they hold {mark!r}: set delimiter = "{spelled}" in the '
                                                         "mapping")):
        import_recording(data, mapping(), "rec.csv")
    text = MAPPING.replace("time =", f'delimiter = "{spelled}"\ntime =')
    table = import_recording(data, mapping(text), "rec.csv").table
    assert table.replace_schema_metadata(None).equals(parse(rows()).table.replace_schema_metadata(None))


def test_a_ur10e_recording_keeps_every_row_with_or_without_a_garbage_head():
    path = shared_data("ur10e") / "identification" / "ur-20_02_12-50sec_12harm.csv"
    from fricli.robot.mapping import load_mapping

    mp = load_mapping(str(ROOT / "docs" / "ur10e-mapping.toml"))
    data = path.read_bytes()
    every = np.loadtxt(path, delimiter=",")
    result = import_recording(data, mp, path.name)
    assert result.meta["dropped"] == {} and result.meta["rows"] == len(every)
    n = len(every)
    np.testing.assert_array_equal(result.table.column("t").to_numpy()[:n], every[:, 0])
    np.testing.assert_array_equal(result.table.column("q").to_numpy().reshape(6, n).T, every[:, 1:7])
    np.testing.assert_array_equal(result.table.column("i_m").to_numpy().reshape(6, n).T, every[:, 13:19])
    head = [",".join(["0"] * 31), ",".join(["1e150"] * 31), ",".join(["-7.5"] + ["0.1"] * 30)]
    dirty = import_recording(("\n".join(head) + "\n").encode() + data, mp, path.name)
    assert {k: d["lines"] for k, d in dirty.meta["dropped"].items()} == {
        "implausible": [[2, 2]], "zero_row": [[1, 1]], "time_outside": [[3, 3]]}
    assert dirty.table.replace_schema_metadata(None).equals(result.table.replace_schema_metadata(None))


# --------------------------------------------------------------------------- what controllers also dump

def test_a_recording_of_zero_rows_is_refused_with_what_was_dropped():
    with pytest.raises(recording.LogError, match=r"rec.csv: no usable rows \(40 with all values zero"):
        parse(["%.2f,0,0,0,0,0,0,ok" % (100 + k * 0.01) for k in range(40)])


def test_too_few_usable_rows_are_refused_with_what_was_dropped():
    with pytest.raises(recording.LogError, match=r"only 1 usable row \(39 with same time as the previous row"):
        parse([rows(1)[0]] * 40)


def test_a_byte_that_is_not_ascii_makes_a_field_non_numeric():
    lines = rows(60)
    text = "\n".join(lines).encode().split(b"\n")
    text[19] = text[19].replace(b"0.", b"\xe9.", 1)        # line 20: a Latin-1 byte in a mapped field
    text[29] = text[29] + b",\xff\xfe"                       # line 30: and one field too many, not UTF-8
    result = import_recording(b"\n".join(text) + b"\n", mapping(), "rec.csv")
    assert {k: (d["count"], d["first_line"]) for k, d in result.meta["dropped"].items()} == {
        "field_count": (1, 30), "non_numeric": (1, 20)}
    assert len(result.recording.lines) == 58


def test_a_byte_order_mark_before_a_header_is_ignored():
    header = MAPPING.replace("column = 1", 'column = "t"').replace("time = ", "header = true\ntime = ")
    data = "\ufefft,q1,q2,qd1,qd2,i1,i2,status\n" + "\n".join(rows()) + "\n"
    result = import_recording(data.encode("utf-8"), mapping(header), "rec.csv")
    assert len(result.recording.lines) == 40


def test_what_is_wrong_with_the_first_bad_row_is_shown():
    """A decimal comma, a date, a delimiter ending the line: the refusal shows the first one."""
    header = MAPPING.replace("column = 1", 'column = "t"').replace("time = ", "header = true\ntime = ")
    head = "t,q1,q2,qd1,qd2,i1,i2,status\n"
    semicolon = head.replace(",", ";") + "\n".join(r.replace(",", ";").replace(".", ",") for r in rows()) + "\n"
    dates = head + "\n".join(f"2026-11-25T10:00:{k:02d}," + r.split(",", 1)[1] for k, r in enumerate(rows())) + "\n"
    trailing = head + "\n".join(r + ",," for r in rows()) + "\n"   # one delimiter at the end is no field
    for data, text, says in ((semicolon, 'delimiter = ";"\n' + header, "'100,00' in column 't': a decimal comma (set decimal = \",\" in the mapping)"),
                             (dates, header, "'2026-11-25T10:00:00' in column 't': a date and time"),
                             (trailing, header, "first at line 2: 10 fields, 8 expected (a delimiter ends the line)")):
        with pytest.raises(recording.LogError, match=re.escape(says)):
            import_recording(data.encode(), mapping(text), "rec.csv")
    quoted = head.replace("t,", '"t",')
    assert len(import_recording((quoted + "\n".join(rows()) + "\n").encode(), mapping(header), "rec.csv")
               .recording.lines) == 40                                       # "t" as R writes a header
    with pytest.raises(recording.LogError, match=re.escape("no column 't' in the header line (it has 'time', 'q1'")):
        import_recording((head.replace("t,", "time,") + "\n".join(rows()) + "\n").encode(), mapping(header), "x")


def test_a_decimal_comma_is_read_when_the_mapping_says_so():
    """European controllers and spreadsheets write 0,5 and separate fields by ';': decimal = ","."""
    header = MAPPING.replace("column = 1", 'column = "t"').replace("time = ", "header = true\ntime = ")
    head = "t,q1,q2,qd1,qd2,i1,i2,status\n"
    plain = import_recording((head + "\n".join(rows()) + "\n").encode(), mapping(header), "rec.csv")
    lines = [r.replace(",", ";").replace(".", ",") for r in rows()]
    lines[5] = lines[5].replace(";", ";x", 1)                  # a bad field among them: still found and reported
    data = (head.replace(",", ";") + "\n".join(lines) + "\n").encode()
    result = import_recording(data, mapping('delimiter = ";"\ndecimal = ","\n' + header), "rec.csv")
    assert result.recording.defects["non_numeric"].first_line == 7
    keep = plain.recording.lines != 7
    for key, values in plain.recording.values.items():
        np.testing.assert_array_equal(result.recording.values[key], values[keep])
    for bad, says in (('decimal = ","\n', "the decimal mark ',' is also the delimiter"),
                      ('delimiter = ";"\ndecimal = "comma"\n', 'decimal: expected "." or ","')):
        with pytest.raises(recording.LogError, match=re.escape(says)):
            mapping(bad + header)


def test_a_single_glitch_of_absurd_current_is_dropped():
    lines = rows(60)
    fields = lines[29].split(",")
    fields[6] = "1e5"                                        # line 30: 100 kA in a current of about 1 A
    lines[29] = ",".join(fields)
    assert dropped(parse(lines)) == {"implausible": [[30, 30]]}


def test_a_file_of_uninitialised_memory_is_refused():
    with pytest.raises(recording.LogError, match="no usable rows .*implausible magnitude"):
        parse(["%.2f,1e150,-3e150,2e150,1e150,7e149,5e150,ok" % (100 + k * 0.01) for k in range(40)])


def test_files_that_are_not_text_recordings_are_named():
    """Each kind is refused with what it is; UTF-16 text (a spreadsheet's "Unicode text") is read."""
    m = mapping(MAPPING)
    for data, what in ((b"PAR1" + bytes(200), "a Parquet file"), (b"PK\x03\x04" + bytes(200), "a zip archive"),
                       (bytes(range(256)) * 8, "a binary file"), (b"\xff\xfe\x00\xd8", "starts like UTF-16")):
        with pytest.raises(recording.LogError, match=what):
            recording.read_recording(data, m, "rec.csv")
    text = "\r\n".join(rows()) + "\r\n"
    for codec in ("utf-16", "utf-16-be"):
        data = text.encode(codec)
        if codec == "utf-16-be":
            data = b"\xfe\xff" + data
        got = recording.read_recording(data, m, "rec.csv")
        want = recording.read_recording(text.encode(), m, "rec.csv")
        assert not got.defects and got.lines.tolist() == want.lines.tolist()
        assert all(np.array_equal(got.values[k], want.values[k]) for k in want.values)


def test_controller_dump_defects_in_the_command(tmp_path):
    """Not text, bad option values: one line each, with the documented code."""
    import gzip

    (tmp_path / "map.toml").write_text(MAPPING)
    (tmp_path / "rec.csv").write_text("\n".join(rows()) + "\n")
    (tmp_path / "rec.csv.gz").write_bytes(gzip.compress((tmp_path / "rec.csv").read_bytes()))
    res = run("import", "rec.csv.gz", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == errors.INPUT and res.stderr == (
        "fricli: error: rec.csv.gz: a gzip file, not a text recording: decompress it first (gunzip)\n")
    for bad in (["--kt", "2=abc"], ["--payload-mass", "nan", "--payload-frame", "tool0"],
                ["--gravity", "nan", "0", "0"], ["--cutoff", "inf"]):
        res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", *bad, cwd=tmp_path)
        assert res.returncode == errors.USAGE, (bad, res.stderr)
        assert res.stderr.splitlines()[-1].startswith(f"Error: Invalid value for '{bad[0]}'"), res.stderr
    assert not (tmp_path / "out.parquet").exists()


def test_a_time_step_no_controller_samples_at_is_flagged(tmp_path):
    (tmp_path / "map.toml").write_text(MAPPING.replace('unit = "s"', 'unit = "s", scale = 1e6'))   # a wrong scale
    (tmp_path / "rec.csv").write_text("\n".join(rows()) + "\n")
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0 and res.stderr.startswith(
        "warning: rec.csv: the median time step is 1e+04 s, which no controller samples at"), res.stderr
    (tmp_path / "map.toml").write_text(MAPPING)
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0 and "median time step" not in res.stderr


def test_numbers_in_double_quotes_are_read_without_them():
    """A writer that quotes every field ("0.01","0.5",...): the same log as the plain file, the
    unterminated last line too."""
    quoted = ['"' + ln.replace(",", '","') + '"' for ln in rows(60)]
    result = parse(quoted, end="")
    assert result.meta["dropped"] == {} and result.meta["rows"] == 60
    assert result.table.replace_schema_metadata(None).equals(parse(rows(60)).table.replace_schema_metadata(None))


def test_columns_aligned_with_spaces_read_as_the_csv():
    """delimiter = " " takes a run of spaces and tabs as one delimiter and none at a line's start
    or end: columns aligned as MATLAB's save -ascii writes them ("   1.0000000e-02  -5.0e-01"),
    with CRLF line ends, give the CSV's log."""
    aligned = ["".join(f"{float(f):16.7e}" if k < 7 else "  ok\t" for k, f in enumerate(ln.split(","))) for ln in rows(60)]
    result = parse(aligned, MAPPING.replace("time =", 'delimiter = " "\ntime ='), end="\r\n")
    assert result.meta["dropped"] == {}
    plain = parse(rows(60)).table
    for name in ("t", "q", "qd", "i_m"):
        np.testing.assert_allclose(result.table.column(name).to_numpy(), plain.column(name).to_numpy(), rtol=1e-6, atol=1e-7)


def test_a_velocity_that_is_not_the_rate_of_the_position_is_flagged(tmp_path):
    """Time in ms mapped as s: a step of 10 "s" is one a controller could take, but each joint's
    velocity is then 100 times the rate of change of its position; import says so, per joint, and
    where to fix it."""
    (tmp_path / "map.toml").write_text(MAPPING.replace('unit = "s"', 'unit = "s", scale = 1000'))
    (tmp_path / "rec.csv").write_text("\n".join(rows(400)) + "\n")
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    for joint in (1, 2):
        assert f"warning: rec.csv, joint {joint}: qd is 1e+03 times the rate of change of q over t" in res.stderr
    assert res.stderr.count("check the units of the time, q and qd in the mapping") == 2
    meta = json.loads(pq.read_table(tmp_path / "out.parquet").schema.metadata[b"fricli.import"])
    assert sorted(meta["rate_mismatch"]) == ["1", "2"]
    (tmp_path / "map.toml").write_text(MAPPING)
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0 and "rate of change" not in res.stderr, res.stderr


def test_the_python_call_is_the_command(tmp_path, monkeypatch):
    """``fricli.import_log`` writes the command's bytes, says what it says on stderr, and refuses
    what it refuses (OptionError naming the option, before anything is written)."""
    import fricli
    from fricli.fitting.optionspec import OptionError

    _, res = imported_with_a_short_row(tmp_path, "cmd.parquet")
    monkeypatch.chdir(tmp_path)
    done = fricli.import_log("rec.csv", "map.toml", kt={"1": 3.0}, output="call.parquet")
    cmd = pq.read_table(tmp_path / "cmd.parquet")
    call = pq.read_table(tmp_path / "call.parquet")
    assert call.equals(cmd) and done.table.equals(cmd) and done.meta["rows"] == 39
    assert call.schema.metadata == cmd.schema.metadata
    assert [line for _, line in done.notices] == [line for line in res.stderr.splitlines() if line.startswith(
        ("warning:", "note:"))]
    for kwargs, option in (({"mapping": None}, "mapping"), ({"topic": "/joint_states"}, "topic"),
                           ({"held": ("wrist",)}, "held"), ({"payload_mass": 2.0}, "payload_frame")):
        args = {"mapping": str(tmp_path / "map.toml"), **kwargs}
        with pytest.raises(OptionError) as err:
            fricli.import_log(str(tmp_path / "rec.csv"), output=str(tmp_path / "refused.parquet"), **args)
        assert err.value.option == option
    assert not (tmp_path / "refused.parquet").exists()


def test_a_folder_that_is_no_bag_is_named_before_the_mapping_is_read_as_a_bag_s(tmp_path):
    """A folder is read as a ROS bag: with a text recording's mapping, the folder's being no bag
    is the error, not the mapping's keys that a bag's mapping does not have."""
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "a.csv").write_text("t,q\n0,0\n")
    (tmp_path / "map.toml").write_text('delimiter = ","\n[time]\ncolumn = 0\n')
    res = run_in(tmp_path, "import", "run", "--mapping", "map.toml", "-o", "out.parquet")
    assert res.returncode == errors.INPUT and "not a ROS bag" in res.stderr, res.stderr
    assert len(res.stderr.splitlines()) == 1 and not (tmp_path / "out.parquet").exists()
