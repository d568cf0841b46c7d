"""The model file contract."""

import io
import json
import zipfile

import numpy as np
import pytest

from fricli.core import modelfile
from fricli.core.atomic import atomic_open, atomic_write_bytes
from fricli.core.errors import ModelFileError

META = {"format": modelfile.FORMAT, "format_version": modelfile.FORMAT_VERSION, "kind": "x", "a": 1.5}


def test_round_trip_and_determinism():
    arrays = {"base/W0": np.arange(6, dtype=np.float32).reshape(2, 3), "fc": np.array(2.0)}
    data = modelfile.dumps(META, arrays)
    assert modelfile.dumps(META, arrays) == data
    meta, loaded = modelfile.loads(data)
    assert meta == META
    np.testing.assert_array_equal(loaded["base/W0"], arrays["base/W0"])
    assert loaded["base/W0"].dtype == np.float32


def test_pickled_object_refused():
    buf = io.BytesIO()
    np.savez(buf, meta=np.array(json.dumps(META)), evil=np.array([{"a": 1}], dtype=object))
    with pytest.raises(ModelFileError, match="pickled"):
        modelfile.loads(buf.getvalue())


@pytest.mark.parametrize("cut", [10, 100, 300, -20])
def test_truncated_file_refused(cut):
    data = modelfile.dumps(META, {"w": np.ones(100)})
    with pytest.raises(ModelFileError, match="not a fricli model file"):
        modelfile.loads(data[:cut])


def test_unknown_version_refused():
    data = modelfile.dumps(dict(META, format_version=99), {})
    with pytest.raises(ModelFileError, match="version 99"):
        modelfile.loads(data)


def test_other_npz_refused():
    buf = io.BytesIO()
    np.savez(buf, x=np.ones(3))
    with pytest.raises(ModelFileError, match="not a fricli model"):
        modelfile.loads(buf.getvalue())
    with pytest.raises(ModelFileError, match="not an .npz"):
        modelfile.loads(b"hello world")


def test_no_timestamps_in_archive():
    with zipfile.ZipFile(io.BytesIO(modelfile.dumps(META, {"w": np.ones(2)}))) as zf:
        assert {info.date_time for info in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}


def test_atomic_write_keeps_old_file_on_failure(tmp_path):
    target = tmp_path / "model.npz"
    atomic_write_bytes(str(target), b"old")
    with pytest.raises(RuntimeError):
        with atomic_open(str(target)) as fh:
            fh.write(b"half")
            raise RuntimeError("killed")
    assert target.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["model.npz"]


def test_atomic_write_removes_stale_temp(tmp_path):
    target = tmp_path / "m.npz"
    (tmp_path / ".m.npz.abc123.tmp").write_bytes(b"left by a killed job")
    atomic_write_bytes(str(target), b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]


@pytest.mark.parametrize("bad", [np.array([1 + 2j]), np.array(["text"])])
def test_arrays_of_other_types_refused(bad):
    data = modelfile.dumps(META, {"w": bad})
    with pytest.raises(ModelFileError, match="damaged model"):
        modelfile.loads(data)


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e300])
def test_arrays_of_absurd_values_refused(bad):
    """No fit writes them; loaded, they made every prediction NaN or inf (float32 networks overflow)."""
    data = modelfile.dumps(META, {"w": np.array([0.5, bad])})
    with pytest.raises(ModelFileError, match="array 'w' holds NaN, infinite or huge values"):
        modelfile.loads(data)
    assert modelfile.loads(modelfile.dumps(META, {"w": np.array([0.5, 3e38])}))[1]["w"][1] == 3e38
