"""Property-based fuzzing of the two readers of untrusted files: the log reader and the model
loader. Random and corrupted input must give a clean ``FricliError`` (one line, an exit code)
or a valid result, never another exception, a crash or a hang.

The runs are derandomized and bounded so the file takes seconds; set FRICLI_FUZZ_EXAMPLES
(e.g. 5000) to explore longer with fresh random examples.
"""

import io
import json
import os
import zipfile

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner
from conftest import no_inertia
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fricli import models
from fricli.applying import predicting
from fricli.core import logs, modelfile
from fricli.cli import cli
from fricli.core.errors import FricliError
from fricli.models.lugre import LuGreModel

EXAMPLES = int(os.environ.get("FRICLI_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=EXAMPLES or 60, deadline=2000, derandomize=not EXAMPLES, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

PARAMS = dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0)
UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "temp": "degC"}


def small_log(n=400):
    t = np.arange(n) * 0.01
    qd = 0.3 * np.sign(np.sin(2.0 * t)) * (0.2 + np.abs(np.sin(0.1 * t)))
    q = np.cumsum(qd) * 0.01
    tau_g = 10 * np.sin(q)
    tau_m = tau_g + LuGreModel(**PARAMS).predict({"t": t, "qd": qd, "tau_g": tau_g})[0]
    return {"joint": np.full(n, 2), "t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_m": tau_m,
            "tau_g": tau_g, "temp": np.full(n, 30.0)}


def parquet_bytes(table, **kwargs):
    buf = io.BytesIO()
    pq.write_table(table, buf, **kwargs)
    return buf.getvalue()


VALID_LOG = parquet_bytes(no_inertia(logs.table_from_arrays(small_log(), UNITS)), row_group_size=128)


@st.composite
def corrupted(draw, data: bytes):
    """``data`` with a few random byte flips, a cut, an insertion or a deletion."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["flip", "overwrite", "truncate", "insert", "delete"]))
        if not out:
            break
        pos = draw(st.integers(0, len(out) - 1))
        if kind == "flip":
            out[pos] ^= 1 << draw(st.integers(0, 7))
        elif kind == "overwrite":
            chunk = draw(st.binary(min_size=1, max_size=8))
            out[pos:pos + len(chunk)] = chunk
        elif kind == "truncate":
            del out[pos:]
        elif kind == "insert":
            out[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        else:
            del out[pos:pos + draw(st.integers(1, 64))]
    return bytes(out)


def check_log(log: logs.Log) -> None:
    """What every Log the reader returns must satisfy (the log contract)."""
    sig = log.signals
    n = len(log)
    assert n >= 1 and log.axis in ("rotary", "linear")
    for name in ("t", "tau_m", "qd", "qdd"):
        assert name in sig
    for name, values in sig.items():
        assert values.dtype == np.float64 and values.shape == (n,), name
        assert np.isfinite(values).all(), name
    assert (np.diff(sig["t"]) > 0).all()
    assert log.table.num_rows == n


def read_log(data: bytes, tmp_path, **kwargs):
    path = tmp_path / "fuzz.parquet"
    path.write_bytes(data)
    try:
        log = logs.load_log(str(path), **kwargs)
    except FricliError as exc:
        assert str(exc).strip()  # the CLI prints it as one line (errors.one_line)
        return None
    check_log(log)
    return log


def predict_batched(data: bytes, tmp_path, model, meta):
    """The other log reader: predict's record batches, with the output streamed to a file."""
    path = tmp_path / "fuzz.parquet"
    path.write_bytes(data)
    out = tmp_path / "out.parquet"
    out.write_bytes(b"previous")
    try:
        result = predicting.run(model, meta, str(path), str(out), batch_rows=100)
    except FricliError as exc:
        assert str(exc).strip()  # the CLI prints it as one line (errors.one_line)
        assert out.read_bytes() == b"previous"
        assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []
        return
    table = pq.read_table(out)
    assert table.num_rows == result.rows
    # a flipped exponent bit in a value (qd = 1e304) is refused like a NaN; one in t (steps of
    # 1e-300 s) may still overflow the derived columns: the prediction need not be finite
    assert table.schema.field("tau_f_pred").type == pa.float64()


# ----------------------------------------------------------------------------- logs


@FUZZ
@given(data=st.binary(max_size=4096))
def test_random_bytes_are_not_a_log(tmp_path, data):
    assert read_log(data, tmp_path) is None


@FUZZ
@given(data=st.binary(max_size=512).map(lambda b: b"PAR1" + b + b"PAR1"))
def test_random_bytes_between_parquet_magic(tmp_path, data):
    assert read_log(data, tmp_path) is None


@FUZZ
@given(data=corrupted(VALID_LOG), drop=st.booleans())
def test_corrupted_parquet_log(tmp_path, data, drop):
    read_log(data, tmp_path, drop_invalid=drop, joint=2)


@FUZZ
@given(data=corrupted(VALID_LOG))
def test_corrupted_parquet_log_in_record_batches(tmp_path, lugre, data):
    predict_batched(data, tmp_path, *lugre)


COLUMN_NAMES = ["t", "q", "qd", "qdd", "tau_m", "i_m", "tau_g", "tau_dyn", "tau_ext", "temp", "tau_f_true",
                "joint", "extra", "note"]
UNIT_SPELLINGS = [None, "s", "ms", "rad", "deg", "m", "mm", "rad/s", "deg/s", "m/s", "rad/s^2", "Nm", "N", "A",
                  "degC", "°", "furlongs", "", "Nm\x00"]
FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64)


@st.composite
def columns_table(draw):
    """A table of random columns: known and unknown names, random types, values and units."""
    n = draw(st.integers(0, 40))
    names = draw(st.lists(st.sampled_from(COLUMN_NAMES), min_size=1, max_size=8, unique=True))
    if draw(st.booleans()):
        names = list(dict.fromkeys(["t", "qd", "tau_m"] + names))  # often close to a valid log
    fields, arrays = [], []
    for name in names:
        kind = draw(st.sampled_from(["increasing", "float", "int", "string", "bool", "null", "nullable"]))
        if kind == "increasing":
            values = pa.array(np.cumsum(draw(st.lists(st.floats(1e-6, 1.0), min_size=n, max_size=n))) if n else
                              np.zeros(0))
        elif kind == "float":
            values = pa.array(draw(st.lists(FLOATS, min_size=n, max_size=n)), pa.float64())
        elif kind == "int":
            values = pa.array(draw(st.lists(st.integers(-2**63, 2**63 - 1), min_size=n, max_size=n)), pa.int64())
        elif kind == "string":
            values = pa.array(draw(st.lists(st.text(max_size=3), min_size=n, max_size=n)), pa.string())
        elif kind == "bool":
            values = pa.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), pa.bool_())
        elif kind == "null":
            values = pa.nulls(n)
        else:
            values = pa.array(draw(st.lists(st.none() | st.floats(-10, 10), min_size=n, max_size=n)), pa.float64())
        unit = draw(st.sampled_from(UNIT_SPELLINGS))
        fields.append(pa.field(name, values.type, metadata=None if unit is None else {"unit": unit}))
        arrays.append(values)
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


@FUZZ
@given(table=columns_table(), drop=st.booleans(), kt=st.none() | st.floats(0.01, 10),
       cutoff=st.floats(0.1, 1000), joint=st.none() | st.sampled_from(["2", "0", "x"]))
def test_random_tables_into_the_reader(tmp_path, table, drop, kt, cutoff, joint):
    read_log(parquet_bytes(table), tmp_path, drop_invalid=drop, kt=kt, cutoff_hz=cutoff, joint=joint)
    # the same table straight into the contract check
    try:
        log = logs.from_table(table, name="fuzz", drop_invalid=drop, kt=kt, cutoff_hz=cutoff, joint=joint)
    except FricliError:
        return
    check_log(log)


@FUZZ
@given(table=columns_table())
def test_random_tables_in_record_batches(tmp_path, lugre, table):
    predict_batched(parquet_bytes(table), tmp_path, *lugre)


# ---------------------------------------------------------------------------- models


@pytest.fixture(scope="module")
def model_files(tmp_path_factory):
    """Real model files of every kind made by the commands: lugre, dissipative, mlp, selmic, nnacm, residual."""
    folder = tmp_path_factory.mktemp("models")
    log = folder / "log.parquet"
    log.write_bytes(VALID_LOG)
    runner = CliRunner()
    paths = {"lugre": folder / "lugre.npz"}
    models.save(str(paths["lugre"]), LuGreModel(**PARAMS), joint=2, axis="rotary",
                units=logs.CANONICAL["rotary"], provenance={})
    for arch in ("dissipative", "mlp", "selmic", "nnacm"):
        paths[arch] = folder / f"{arch}.npz"
        res = runner.invoke(cli, ["train-base", str(log), "-o", str(paths[arch]), "--arch", arch, "--steps", "3",
                                  "--hidden", {"dissipative": "4,4", "mlp": "4,4", "selmic": "12", "nnacm": "4"}[arch],
                                  "-q"])
        assert res.exit_code == 0, res.stderr
    paths["residual"] = folder / "residual.npz"
    res = runner.invoke(cli, ["adapt", str(paths["mlp"]), str(log), "-o", str(paths["residual"]), "--epochs", "1",
                              "--hidden", "3", "-q"])
    assert res.exit_code == 0, res.stderr
    return Files({kind: path.read_bytes() for kind, path in paths.items()})


class Files(dict):
    """Model file bytes by kind, with a short repr for hypothesis' reports."""

    def __repr__(self):
        return f"<model files: {', '.join(self)}>"


@pytest.fixture(scope="module")
def lugre(model_files):
    meta, arrays = modelfile.loads(model_files["lugre"])
    return models.from_parts(meta["model"], arrays), meta


SIGNALS = {k: v for k, v in small_log(50).items() if k != "joint"}


def load_model(data: bytes, tmp_path):
    """Load ``data`` as a model file: a clean error, or a model that predicts (n,) values."""
    path = tmp_path / "fuzz.npz"
    path.write_bytes(data)
    try:
        model, meta = models.load(str(path))
    except FricliError as exc:
        assert str(exc).strip()  # the CLI prints it as one line (errors.one_line)
        return None
    assert isinstance(meta, dict) and meta["format_version"] == modelfile.FORMAT_VERSION
    try:
        pred, _ = model.predict(SIGNALS)
    except FricliError:
        return model
    assert np.shape(pred) == (50,)
    return model


@FUZZ
@given(data=st.binary(max_size=4096))
def test_random_bytes_are_not_a_model(tmp_path, data):
    assert load_model(data, tmp_path) is None


@FUZZ
@given(data=st.binary(max_size=2048).map(lambda b: b"PK\x03\x04" + b))
def test_random_bytes_after_zip_magic(tmp_path, data):
    assert load_model(data, tmp_path) is None


@FUZZ
@given(kind=st.sampled_from(["lugre", "dissipative", "mlp", "selmic", "nnacm", "residual"]), data=st.data())
def test_corrupted_model_file(tmp_path, model_files, kind, data):
    load_model(data.draw(corrupted(model_files[kind])), tmp_path)


JSON = st.recursive(st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False) |
                    st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner,
                                                                                max_size=4),
                    max_leaves=12)


def _swap_json(meta, path, value):
    """``meta`` with the entry at ``path`` (a list of keys) replaced by ``value``."""
    out = json.loads(json.dumps(meta))
    node = out
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return out


def _paths(node, prefix=()):
    if isinstance(node, dict):
        for key, value in node.items():
            yield prefix + (key,)
            yield from _paths(value, prefix + (key,))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield prefix + (i,)
            yield from _paths(value, prefix + (i,))


@FUZZ
@given(kind=st.sampled_from(["lugre", "dissipative", "mlp", "selmic", "nnacm", "residual"]), data=st.data())
def test_model_meta_with_a_random_value(tmp_path, model_files, kind, data):
    """A well-formed file whose meta has one entry replaced by random JSON."""
    meta, arrays = modelfile.loads(model_files[kind])
    paths = sorted(_paths(meta), key=str)
    path = data.draw(st.sampled_from(paths))
    value = data.draw(JSON)
    try:
        content = modelfile.dumps(_swap_json(meta, path, value), arrays)
    except FricliError:  # the writer refuses non-finite numbers
        return
    load_model(content, tmp_path)


@FUZZ
@given(kind=st.sampled_from(["dissipative", "mlp", "selmic", "nnacm", "residual"]), data=st.data())
def test_model_arrays_with_random_shapes_and_values(tmp_path, model_files, kind, data):
    """A well-formed file whose arrays are dropped, reshaped, retyped or filled with odd values."""
    meta, arrays = modelfile.loads(model_files[kind])
    name = data.draw(st.sampled_from(sorted(arrays)))
    change = data.draw(st.sampled_from(["drop", "shape", "dtype", "nan", "huge", "empty", "string"]))
    arr = arrays[name]
    if change == "drop":
        del arrays[name]
    elif change == "shape":
        shape = data.draw(st.lists(st.integers(0, 6), min_size=0, max_size=3))
        arrays[name] = np.ones(shape)
    elif change == "dtype":
        arrays[name] = arr.astype(data.draw(st.sampled_from([np.int8, np.float16, np.complex128, np.bool_])))
    elif change == "nan":
        arrays[name] = np.full(arr.shape, np.nan)
    elif change == "huge":
        arrays[name] = np.full(arr.shape, 1e308)
    elif change == "empty":
        arrays[name] = np.zeros((0,))
    else:
        arrays[name] = np.array(["x"] * max(arr.size, 1))
    load_model(modelfile.dumps(meta, arrays), tmp_path)


def test_an_npy_header_claiming_a_huge_array_is_refused(tmp_path, model_files):
    """A tiny file whose array header claims 10^12 values must not make fricli allocate them."""
    buf = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(model_files["lugre"])) as src, zipfile.ZipFile(buf, "w") as dst:
        for info in src.infolist():
            dst.writestr(info, src.read(info))
        header = io.BytesIO()
        np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False,
                                                      "shape": (10**12,)})
        dst.writestr("huge.npy", header.getvalue() + b"\0" * 64)
    with pytest.raises(FricliError, match="huge.npy claims more data than it holds"):
        modelfile.loads(buf.getvalue())

