"""The model file contract: a ``.npz`` with a ``meta`` JSON string and namespaced arrays.

    meta            0-d unicode array: JSON (format, format_version, kind, model spec tree,
                    joint, axis, units, inputs, provenance, fit, versions); sorted keys
    <path>/<name>   float arrays of the model and its parts, e.g. ``base/W0``, ``add/W0``

Files load with ``allow_pickle=False`` and are written atomically. The zip entries carry a
fixed timestamp, so the same model gives the same bytes.
"""

from __future__ import annotations

import io
import json
import math
import zipfile

import numpy as np

from fricli import __version__
from fricli.core import files
from fricli.core.atomic import atomic_write_bytes
from fricli.core.errors import FitError, ModelFileError

FORMAT = "fricli-model"
FORMAT_VERSION = 1
_EPOCH = (1980, 1, 1, 0, 0, 0)


def dumps(meta: dict, arrays: dict[str, np.ndarray]) -> bytes:
    """Serialise ``meta`` and ``arrays`` to npz bytes, deterministically."""
    buf = io.BytesIO()
    try:
        text = json.dumps(meta, sort_keys=True, allow_nan=False)
    except ValueError:
        raise FitError(f"the model is not written: its {_non_finite(meta)} is not a finite number") from None
    entries = {"meta": np.array(text)}
    entries.update(arrays)
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(entries):
            arr = np.asarray(entries[name])
            if arr.dtype == object:
                raise ValueError(f"array {name!r} has dtype object")
            info = zipfile.ZipInfo(name + ".npy", date_time=_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with zf.open(info, "w") as fh:
                np.lib.format.write_array(fh, arr if arr.flags.c_contiguous else arr.copy(), allow_pickle=False)
    return buf.getvalue()


def _non_finite(obj, path: str = "meta") -> str | None:
    """Where the first NaN or infinite float in ``obj`` is, e.g. ``meta.fit.mae``."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return path
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, (list, tuple)) else ()
    for key, value in items:
        found = _non_finite(value, f"{path}.{key}")
        if found:
            return found
    return None


# Deflate packs the float arrays of a model by a few percent; an archive that unpacks to many
# times its own size holds runs of one byte (a decompression bomb), not a model.
MAX_EXPANSION = 32
MIN_UNPACKED = 16 << 20


def decompressed_limit(file_size: int) -> int:
    """Bytes a model file of ``file_size`` bytes may unpack to (``MAX_ARRAY_BYTES`` at most)."""
    return min(MAX_ARRAY_BYTES, MIN_UNPACKED + MAX_EXPANSION * file_size)


_PICKLED = "holds a pickled object; refused (model files never load pickles)"
MAX_ARRAY_BYTES = 1 << 30   # fricli models hold kilobytes to a few megabytes


def _check_entries(data: bytes, name: str) -> None:
    """Refuse, before numpy allocates anything, an archive whose arrays claim more bytes than
    their entries hold (or than any model needs) and arrays of Python objects."""
    total = 0
    limit = decompressed_limit(len(data))
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        declared = sum(info.file_size for info in zf.infolist())
        if declared > limit:
            raise ModelFileError(f"{name}: not a fricli model file: its entries unpack to {declared:,} bytes, "
                                 f"more than {limit:,} for a file of {len(data):,} bytes")
        for info in zf.infolist():
            with zf.open(info) as fh:
                version = np.lib.format.read_magic(fh)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
                elif version == (2, 0):
                    shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
                else:
                    raise ModelFileError(f"{name}: not a fricli model file (array format {version})")
                if dtype.hasobject:
                    raise ModelFileError(f"{name}: {_PICKLED}")
                size = math.prod(shape) * dtype.itemsize
                total += size
                if size > info.file_size - fh.tell() or total > MAX_ARRAY_BYTES:
                    raise ModelFileError(f"{name}: not a fricli model file (or truncated): "
                                         f"{info.filename} claims more data than it holds")


def loads(data: bytes, name: str = "model") -> tuple[dict, dict[str, np.ndarray]]:
    """Parse npz bytes into (meta, arrays); refuses pickles and unknown versions."""
    if not data.startswith(b"PK\x03\x04"):
        raise ModelFileError(f"{name}: not a fricli model file (not an .npz archive)")
    try:
        _check_entries(data, name)
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
    except ModelFileError:
        raise
    except ValueError as exc:
        if "pickle" in str(exc).lower():
            raise ModelFileError(f"{name}: {_PICKLED}") from None
        raise ModelFileError(f"{name}: not a fricli model file (or truncated)") from None
    except Exception:  # zip, EOF and format errors from corrupt or truncated files
        raise ModelFileError(f"{name}: not a fricli model file (or truncated)") from None
    if "meta" not in arrays:
        raise ModelFileError(f"{name}: not a fricli model file (no 'meta' entry)")
    try:
        meta = json.loads(str(arrays.pop("meta").reshape(-1)[0]))
    except Exception:
        raise ModelFileError(f"{name}: not a fricli model file (meta is not JSON)") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ModelFileError(f"{name}: not a fricli model file")
    version = meta.get("format_version")
    if type(version) is not int or version != FORMAT_VERSION:   # true and 1.0 are no version
        shown = version if isinstance(version, int) and not isinstance(version, bool) else json.dumps(version)
        raise ModelFileError(f"{name}: model format version {shown} is not supported "
                             f"(this fricli reads version {FORMAT_VERSION})")
    _check_shapes(meta, name)
    bad = _beyond_float32(meta.get("model"))
    if bad is not None:
        raise ModelFileError(f"{name}: damaged model (parameter {bad[0]!r} is {bad[1]!r}: NaN, infinite or huge)")
    for key, arr in arrays.items():
        if arr.dtype.kind not in "biuf":  # model arrays are real numbers
            raise ModelFileError(f"{name}: damaged model (array {key!r} has type {arr.dtype})")
        # finite, and within float32 (the precision networks predict in): no fit writes others
        if arr.dtype.kind == "f" and not (np.abs(arr) <= _FLOAT32_MAX).all():
            raise ModelFileError(f"{name}: damaged model (array {key!r} holds NaN, infinite or huge values)")
    return meta, arrays


_SCALAR = (str, int, float)
# meta key -> (what its value must be when present, how a message says it)
_SHAPES = {
    "kind": (lambda v: isinstance(v, str), "a name"),
    "joint": (lambda v: v is None or isinstance(v, _SCALAR), "a joint name or number"),
    "joints": (lambda v: isinstance(v, list) and all(isinstance(j, _SCALAR) for j in v), "a list of joints"),
    "inputs": (lambda v: isinstance(v, list) and all(isinstance(c, str) for c in v), "a list of column names"),
    "envelope": (lambda v: v is None or isinstance(v, dict), "an object"),
    **{key: (lambda v: isinstance(v, dict), "an object") for key in ("model", "units", "provenance", "fit")},
}


_FLOAT32_MAX = np.finfo(np.float32).max   # a float32: a float16 array is compared in float32, without overflow


def _beyond_float32(value, key: str = "") -> tuple[str, float] | None:
    """(key, value) of the first number in the model spec ``value`` (nested dicts and lists) that is
    not finite or beyond float32's range, as the arrays are checked: no fit writes one."""
    if isinstance(value, dict):
        found = (_beyond_float32(v, k) for k, v in value.items())
    elif isinstance(value, list):
        found = (_beyond_float32(v, key) for v in value)
    elif isinstance(value, (int, float)) and not isinstance(value, bool) and not abs(value) <= float(_FLOAT32_MAX):
        return key, value
    else:
        return None
    return next((f for f in found if f is not None), None)


def _check_shapes(meta: dict, name: str) -> None:
    """ModelFileError when a top-level meta entry every reader relies on has another JSON type
    (a file edited or written by another tool), instead of an error deep inside a command."""
    for key, (fits, expected) in _SHAPES.items():
        if key in meta and not fits(meta[key]):
            raise ModelFileError(f"{name}: damaged model (meta '{key}' is {json.dumps(meta[key])[:40]}, "
                                 f"expected {expected})")


def read(path: str) -> tuple[dict, dict[str, np.ndarray]]:
    if path == "-":
        raise ModelFileError("-: a model is read from a file, not from stdin (give the model file's path)")
    return loads(files.read_bytes(path, ModelFileError, "file", "model file"), path)


def write(path: str, meta: dict, arrays: dict[str, np.ndarray]) -> None:
    atomic_write_bytes(path, dumps(meta, arrays), binary=True)


def base_meta() -> dict:
    return {"format": FORMAT, "format_version": FORMAT_VERSION,
            "fricli_version": __version__, "numpy_version": np.__version__}
