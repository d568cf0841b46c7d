"""The log contract: read a Parquet log, check it, convert units, derive what is missing.

A log holds one row per sample. Columns (SI units unless the Parquet field metadata key
``unit`` says otherwise; see docs/log-format.md):

    t [s]  q [rad]  qd [rad/s]  qdd [rad/s^2]  tau_m [Nm] (or i_m [A] with kt)
    tau_g [Nm]  tau_dyn [Nm]  tau_ext [Nm]  temp [degC]  tau_f_true [Nm]  joint

A linear axis uses m, m/s, m/s^2 and N in the same columns. Every model kind sees a log
through ``Log.signals``: float64 arrays of shape (n,) in canonical units.

Columns are inputs (``INPUTS``: what a controller has, the only ones a model, an effect term or
exported C reads) or references (``REFERENCES``, and any column whose field metadata ``role`` is
``reference``: what results are scored against). The robot-model columns tau_g and tau_dyn are
unknown when absent, not zero: they count as zero only when declared so (``from_table(zero=...)``,
the options --no-gravity/--no-dynamics, or the schema metadata key ``fricli.zero_columns``).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
from fricli.core import joints
from fricli.core.errors import DataError, InvalidRows, LogError, NoValidRows
from fricli.core.jsontext import is_finite_number
# reading and writing Parquet, and the motion's filter and derivatives, importable from here as before
from fricli.core.logs_io import (STREAMING, not_parquet, pa, parquet_file, parquet_options, pq,  # noqa: F401
                                 read_bytes, read_table, stdin_parquet, table_from_arrays, unique_columns, write_table)
from fricli.core.logs_motion import (_contradicts, dead_torque, derive_motion, implausible_step,  # noqa: F401
                                     lowpass, lowpass_applies, not_measured, rate_mismatch, wraps)

TORQUES = ("tau_m", "tau_g", "tau_dyn", "tau_ext", "tau_f_true")
KNOWN = ("t", "joint", "q", "qd", "qdd", "i_m", "temp") + TORQUES
# what a controller has: models read these only (i_m counts as tau_m with kt)
INPUTS = ("t", "q", "qd", "qdd", "tau_m", "i_m", "tau_g", "tau_dyn", "temp")
# what results are scored against, never a model input; a column marked with the field metadata
# ``role: reference`` is one too (it is carried through but not read into ``Log.signals``)
REFERENCES = ("tau_ext", "tau_f_true")
ROLE_KEY, REFERENCE_ROLE = b"role", b"reference"
# robot-model columns: unknown when absent; zero only when declared (option, schema metadata key)
ROBOT_MODEL = {"tau_g": ("--no-gravity", "the robot model's gravity torque",
                         "if the joint carries no gravity load (e.g. a horizontal axis)"),
               "tau_dyn": ("--no-dynamics", "the robot model's inertia and Coriolis torque",
                           "to take it as 0 (the inertia then stays in the friction target; diagnose finds it "
                           "as 'acceleration')")}
ZERO_KEY = b"fricli.zero_columns"   # schema metadata: JSON list of robot-model columns declared zero
DEFAULT_CUTOFF_HZ = 50.0
AUTO_CUTOFF = "auto"   # import/dynamics --cutoff auto: chosen from the data (fricli.robot.importing.choose_cutoff)

# unit spelling -> (dimension, factor to canonical)
_UNITS = {
    "s": ("time", 1.0), "ms": ("time", 1e-3), "us": ("time", 1e-6), "ns": ("time", 1e-9),
    "rad": ("angle", 1.0), "deg": ("angle", np.pi / 180), "m": ("length", 1.0), "mm": ("length", 1e-3),
    "rad/s": ("angle/s", 1.0), "deg/s": ("angle/s", np.pi / 180),
    "m/s": ("length/s", 1.0), "mm/s": ("length/s", 1e-3),
    "rad/s^2": ("angle/s2", 1.0), "deg/s^2": ("angle/s2", np.pi / 180),
    "m/s^2": ("length/s2", 1.0), "mm/s^2": ("length/s2", 1e-3),
    "Nm": ("torque", 1.0), "N": ("force", 1.0),
    "A": ("current", 1.0), "mA": ("current", 1e-3), "degC": ("temperature", 1.0),
}
_ALIASES = {"sec": "s", "radian": "rad", "rad/s2": "rad/s^2", "rad/s²": "rad/s^2",
            "deg/s2": "deg/s^2", "deg/s²": "deg/s^2", "m/s2": "m/s^2", "m/s²": "m/s^2",
            "mm/s2": "mm/s^2", "mm/s²": "mm/s^2", "N·m": "Nm", "N*m": "Nm", "N m": "Nm",
            "N.m": "Nm", "°": "deg", "°/s": "deg/s", "°/s²": "deg/s^2", "°C": "degC",
            "C": "degC", "celsius": "degC", "amp": "A", "µs": "us", "μs": "us"}
# column -> dimensions it may have, by axis kind
_EXPECTED = {
    "t": {"rotary": "time", "linear": "time"},
    "q": {"rotary": "angle", "linear": "length"},
    "qd": {"rotary": "angle/s", "linear": "length/s"},
    "qdd": {"rotary": "angle/s2", "linear": "length/s2"},
    "i_m": {"rotary": "current", "linear": "current"},
    "temp": {"rotary": "temperature", "linear": "temperature"},
    **{c: {"rotary": "torque", "linear": "force"} for c in TORQUES},
}
CANONICAL = {
    "rotary": {"q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau": "Nm"},
    "linear": {"q": "m", "qd": "m/s", "qdd": "m/s^2", "tau": "N"},
}


def canonical_unit(spelling: str) -> str:
    s = spelling.strip()
    s = _ALIASES.get(s, s)
    if s not in _UNITS:
        raise LogError(f"unknown unit {spelling!r}")
    return s


def column_unit(column: str, spelling: str) -> tuple[str | None, float]:
    """(axis kind, factor to the canonical unit) of ``spelling`` for a known column: the kind is
    ``rotary`` or ``linear`` for motion and torque columns, None for t, i_m and temp. LogError
    when the unit is unknown or does not fit the column."""
    dim, factor = _UNITS[canonical_unit(spelling)]
    for axis, expected in _EXPECTED[column].items():
        if dim == expected:
            return (None if expected == _EXPECTED[column]["linear"] == _EXPECTED[column]["rotary"] else axis), factor
    raise LogError(f"unit {spelling!r} does not fit column {column!r}")


def field_unit(field: pa.Field) -> str | None:
    meta = field.metadata or {}
    raw = meta.get(b"unit")
    return raw.decode("utf-8", "replace") if raw is not None else None


def _field_spelling(field: pa.Field, name: str) -> str:
    """The canonical spelling of a known column's unit; LogError naming the log and column."""
    unit = field_unit(field)
    try:
        return canonical_unit(unit)
    except LogError:
        raise LogError(f"{name}: column {field.name!r} has an unknown unit {unit!r} (docs/log-format.md)") from None


# ------------------------------------------------------------------------- the Log


@dataclasses.dataclass
class Log:
    """One joint's samples. ``table`` keeps the original columns (and field metadata);
    ``signals`` holds float64 arrays in canonical units, including derived qd/qdd."""

    table: pa.Table
    signals: dict[str, np.ndarray]
    axis: str                      # "rotary" or "linear"
    joint: object | None
    sha256: str
    name: str
    derived: dict                  # {"columns": [...], "cutoff_hz": float} when derived
    zero: tuple = ()               # robot-model columns the log lacks, declared zero (filled in signals)
    reading: dict = dataclasses.field(default_factory=dict)   # how it was read: the reading options
    window: dict | None = None     # the time window it was cut to (``Window.to_json``), when one was given
    source: object = None          # the table of every joint's rows it was read from (for a coupled group's
                                   # partners), when the caller keeps it

    @property
    def units(self) -> dict:
        return dict(CANONICAL[self.axis], temp="degC")

    def __len__(self) -> int:
        return len(self.signals["t"])

    def has(self, column: str) -> bool:
        return column in self.signals


def unitless_note(schema: pa.Schema, name: str) -> str | None:
    """A note when no column of the log carries a unit (field metadata ``unit``): every column is
    then read in SI units, which a log in degrees, millimetres or mNm silently breaks."""
    if any(field_unit(f) is not None for f in schema if f.name in _EXPECTED):
        return None
    return (f"note: {name}: no column carries a unit (Parquet field metadata 'unit'): read as SI (s, rad, rad/s, "
            "rad/s^2, Nm); a log in other units gives wrong figures (docs/log-format.md#units)")


def axis_of(schema: pa.Schema, name: str) -> str:
    """``rotary`` or ``linear`` from the units of the motion and torque columns."""
    kinds = set()
    for field in schema:
        unit = field_unit(field)
        if unit is None or field.name not in _EXPECTED or len(set(_EXPECTED[field.name].values())) == 1:
            continue
        dim = _UNITS[_field_spelling(field, name)][0]
        if dim in ("angle", "angle/s", "angle/s2", "torque"):
            kinds.add("rotary")
        elif dim in ("length", "length/s", "length/s2", "force"):
            kinds.add("linear")
    if len(kinds) > 1:
        raise LogError(f"{name}: mixes rotary (rad, Nm) and linear (m, N) units")
    return kinds.pop() if kinds else "rotary"


# pyarrow's conversions between Arrow and Python or numpy objects (to_numpy, pa.array,
# pa.scalar) import pandas on first use, half a second; these go through the buffers instead.


def float64_values(col) -> np.ndarray:
    """float64 (n,) of a numeric Arrow array or chunked array without nulls: float64 chunks are
    viewed (read-only), others cast by Arrow."""
    chunks = col.chunks if isinstance(col, pa.ChunkedArray) else [col]
    parts = []
    for chunk in chunks:
        if chunk.type != pa.float64():
            chunk = chunk.cast(pa.float64(), safe=False)
        parts.append(np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=len(chunk), offset=8 * chunk.offset))
    if not parts:
        return np.empty(0)
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def float64_array(values: np.ndarray) -> pa.Array:
    """An Arrow float64 array over the numpy values (n,) (no copy when already float64)."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    return pa.Array.from_buffers(pa.float64(), len(values), [None, pa.py_buffer(values)])


def take_rows(table: pa.Table, keep: np.ndarray) -> pa.Table:
    """The rows of ``table`` where the bool mask ``keep`` (n,) is set."""
    idx = np.flatnonzero(keep).astype(np.int64)
    return table.take(pa.Array.from_buffers(pa.int64(), len(idx), [None, pa.py_buffer(idx)]))


def is_number(typ) -> bool:
    """Whether an Arrow type holds numbers a log's signal reads (as float64): float, integer or
    decimal (a database's fixed-point export)."""
    return pa.types.is_floating(typ) or pa.types.is_integer(typ) or pa.types.is_decimal(typ)


def _numeric(table: pa.Table, column: str, name: str, rows: np.ndarray | None = None,
             drop_invalid: bool = False) -> np.ndarray:
    """float64 (n,) of a numeric column; missing values (nulls) refused, or with ``drop_invalid``
    read as NaN, which ``check_signals`` drops with the other invalid rows. ``rows``: the log's
    row number of each row (n,), for the message (default: 0..n-1)."""
    col = table.column(column)
    typ = col.type
    if not is_number(typ):
        raise LogError(f"{name}: column {column!r} has type {typ}, expected numbers")
    if col.null_count:
        if drop_invalid:
            import pyarrow.compute as pc

            return float64_values(pc.fill_null(col.cast(pa.float64()), np.nan))
        first = _log_row(rows, int(np.flatnonzero(np.asarray(col.is_null()))[0]))
        raise InvalidRows(f"{name}: column {column!r} has {col.null_count} missing values (first at row {first})",
                          "use --drop-invalid to drop their rows")
    return float64_values(col)


def table_signals(table: pa.Table, axis: str, name: str, kt: float | None = None,
                  drop_invalid: bool = False, rows: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Numeric columns of ``table`` as float64 arrays in canonical units (no derivation); missing
    values are NaN with ``drop_invalid`` (``_numeric``; ``rows`` as there)."""
    out: dict[str, np.ndarray] = {}
    for field in table.schema:
        column = field.name
        if is_marked_reference(field) and column in INPUTS:
            raise LogError(f"{name}: column {column!r} is marked as a reference (field metadata role), but it is an "
                           "input of the log contract: remove the mark (docs/log-format.md#inputs-and-references)")
        if column == "joint" or (is_marked_reference(field) and column not in REFERENCES):
            continue
        typ = field.type
        if column not in KNOWN and not is_number(typ):
            continue  # non-numeric extra columns are carried through, not used
        values = _numeric(table, column, name, rows=rows, drop_invalid=drop_invalid)
        unit = field_unit(field)
        if unit is not None and column in _EXPECTED:
            dim, factor = _UNITS[_field_spelling(field, name)]
            if dim != _EXPECTED[column][axis]:
                raise LogError(f"{name}: column {column!r} has unit {unit!r}, not a unit of {_EXPECTED[column][axis]}")
            if factor != 1.0:
                values = values * factor
        out[column] = values
    if "tau_m" not in out and "i_m" in out:
        if kt is None:
            raise LogError(f"{name}: the log has motor current 'i_m' but no 'tau_m': give --kt (Nm/A)")
        out["tau_m"] = out["i_m"] * kt
    return out


def is_marked_reference(field: pa.Field) -> bool:
    """Whether the field metadata marks the column as a reference (``role: reference``)."""
    return (field.metadata or {}).get(ROLE_KEY, b"").strip().lower() == REFERENCE_ROLE


def missing_robot_model(column: str) -> str:
    """The one-line refusal for a robot-model column the log lacks and nobody declared zero."""
    option, meaning, when = ROBOT_MODEL[column]
    return (f"the log has no '{column}' column ({meaning}): unknown, not zero; add it with "
            f"'fricli dynamics LOG --urdf URDF' (or 'fricli import ... --urdf'), or give {option} {when}")


def require_robot_model(schema: pa.Schema, name: str, zero=()) -> None:
    """DataError (one line, with the fix) when the log lacks tau_g or tau_dyn and neither the
    options (``zero``) nor the log's metadata declare it zero: checked once before any joint is
    fitted or predicted; not for a log without a required column (``check_signals`` says that)."""
    if not {"t"} <= set(schema.names) or not {"tau_m", "i_m"} & set(schema.names) or not {"q", "qd"} & set(schema.names):
        return
    declared = declared_zero(schema, name, zero)
    for column in ROBOT_MODEL:
        if column not in schema.names and column not in declared:
            raise DataError(f"{name}: {missing_robot_model(column)}")


def declared_zero(schema: pa.Schema, name: str, zero=()) -> tuple[str, ...]:
    """Robot-model columns declared zero: ``zero`` (the options) and the schema metadata key
    ``fricli.zero_columns`` (a JSON list). LogError for a name that is not tau_g or tau_dyn."""
    import json

    found = list(zero)
    raw = (schema.metadata or {}).get(ZERO_KEY)
    if raw is not None:
        try:
            listed = json.loads(raw)
        except ValueError:
            listed = None
        if not isinstance(listed, list):
            raise LogError(f"{name}: the metadata key fricli.zero_columns is not a JSON list of column names")
        found += listed
    bad = [c for c in found if not isinstance(c, str) or c not in ROBOT_MODEL]
    if bad:
        raise LogError(f"{name}: only tau_g and tau_dyn can be declared zero, not {bad[0]!r}")
    return tuple(c for c in ROBOT_MODEL if c in found)


# No robot signal reaches this magnitude in canonical units (rad, m, rad/s, Nm, N, A, degC);
# a value beyond it is garbage (uninitialised memory), and squares of it would overflow
MAGNITUDE_LIMIT = 1e9


DEFAULT_GRAVITY = (0.0, 0.0, -9.81)   # m/s^2 in the URDF's base frame, as a level-mounted arm sees it


def gravity_of(schema: pa.Schema, given=None) -> tuple:
    """Gravity for the log's robot model: ``given`` (an option), else what import/dynamics recorded
    with the log's tau_g (a tilted base), else ``DEFAULT_GRAVITY``."""
    if given:
        return tuple(float(g) for g in given)
    return tuple(robot_record(schema).get("gravity") or DEFAULT_GRAVITY)


def robot_record(schema: pa.Schema) -> dict:
    """What the log's tau_g and tau_dyn came from, as ``fricli dynamics`` (preferred: it replaces
    them) or ``fricli import --urdf`` recorded it in the schema metadata; {} when unrecorded (or
    when the record has another shape than fricli writes: not an object, a gravity that is not
    three numbers, held joints that are not a list of names)."""
    meta = schema.metadata or {}
    for key in (b"fricli.dynamics", b"fricli.import"):
        if key in meta:
            try:
                record = json.loads(meta[key])
            except ValueError:
                continue
            if key == b"fricli.import" and isinstance(record, dict):
                record = record.get("robot", record)
            if isinstance(record, dict) and _record_fits(record):
                return record
    return {}


def _record_fits(record: dict) -> bool:
    """Whether a robot-model record's gravity (3 finite numbers) and held joints (names) are as fricli writes them."""
    gravity, held = record.get("gravity"), record.get("held")
    numbers = isinstance(gravity, list) and len(gravity) == 3 and all(is_finite_number(g) for g in gravity)
    return ((gravity is None or numbers)
            and (held is None or (isinstance(held, list) and all(isinstance(h, str) for h in held))))


def robot_model(schema: pa.Schema) -> dict | None:
    """The robot model of a log's tau_g and tau_dyn: its URDF's sha256, gravity, rotor inertias,
    payload and held joints (what changes them); None when the log does not record one."""
    record = robot_record(schema)
    if not record.get("urdf_sha256"):
        return None
    return {k: record.get(k) for k in ("urdf_sha256", "gravity", "rotor_inertia", "payload")} | (
        {"held": record["held"]} if record.get("held") else {})


def held_of(schema: pa.Schema) -> tuple[str, ...]:
    """The URDF joints a log's robot model holds at their zero position (``--hold``), as recorded."""
    return tuple(robot_record(schema).get("held") or ())


def _other_case(sig: dict, *wanted: str) -> str:
    """A hint naming a column of ``sig`` that differs from a wanted one in case only (`` (the log has
    'TAU_M': column names are case-sensitive)``); else an empty string."""
    found = [c for c in sig if c.lower() in wanted and c not in wanted]
    return f" (the log has {found[0]!r}: column names are case-sensitive)" if found else ""


def _log_row(rows: np.ndarray | None, i: int) -> int:
    """The log's row number of row ``i`` of the rows read (``rows``: theirs, None: the same)."""
    return i if rows is None else int(rows[i])


def check_signals(sig: dict[str, np.ndarray], name: str, drop_invalid: bool = False,
                  warn=None, rows: np.ndarray | None = None, time_stored=None) -> np.ndarray | None:
    """Check finiteness and time order. Returns a row mask when rows were dropped. ``rows``: the
    log's row number of each row (n,) for the messages (default: 0..n-1), e.g. of one joint's rows;
    ``time_stored``: (Arrow type, factor to s) of the column ``t`` was read from (a time order error
    says when that type is too coarse)."""
    if "t" not in sig:
        raise LogError(f"{name}: missing required column 't'{_other_case(sig, 't')}")
    if "tau_m" not in sig:
        raise LogError(f"{name}: missing required column 'tau_m' (or 'i_m' with --kt)"
                       f"{_other_case(sig, 'tau_m', 'i_m')}")
    if "q" not in sig and "qd" not in sig:
        raise LogError(f"{name}: needs at least one of the columns 'q', 'qd'{_other_case(sig, 'q', 'qd')}")
    n = len(sig["t"])
    if n == 0:
        raise LogError(f"{name}: the log is empty")
    bad = np.zeros(n, dtype=bool)
    cols = []
    with np.errstate(invalid="ignore"):
        for column, values in sig.items():
            # t may be large (absolute time stamps) but not infinite
            limit = np.finfo(np.float64).max if column == "t" else MAGNITUDE_LIMIT
            # max and min propagate NaN, which fails both comparisons; only then look row by row
            if not (values.max() <= limit and values.min() >= -limit):
                invalid = ~(np.abs(values) <= limit)
                if invalid.any():
                    bad |= invalid
                    cols.append(column)
    mask = None
    if bad.any():
        first = _log_row(rows, int(np.flatnonzero(bad)[0]))
        cols = sorted(cols)
        what = f"NaN, infinite or absurd values (beyond {MAGNITUDE_LIMIT:g} in magnitude)"
        if not drop_invalid:
            raise InvalidRows(f"{name}: {int(bad.sum())} rows hold {what} (first at row {first}, columns "
                              f"{', '.join(cols)})", "use --drop-invalid to drop them")
        mask = ~bad
        rows = np.flatnonzero(mask) if rows is None else rows[mask]
        if warn:
            warn(f"warning: dropped {int(bad.sum())} of {n} rows with missing, {what} ({', '.join(cols)})")
        for column in sig:
            sig[column] = sig[column][mask]
        if len(sig["t"]) == 0:
            raise NoValidRows(f"{name}: no valid rows left after dropping invalid ones")
    dt = np.diff(sig["t"])
    for what, wrong in (("duplicate timestamps", dt == 0), ("'t' is not increasing", dt < 0)):
        if wrong.any():
            row = int(np.flatnonzero(wrong)[0]) + 1
            t = sig["t"][row]
            raise LogError(f"{name}: {what} (first at row {_log_row(rows, row)}, t = {t:.15g} s)"
                           f"{_coarse_time(time_stored, t, sig['t'][row - 1])}")
    return mask


def _time_stored(table: pa.Table, name: str) -> tuple | None:
    """(Arrow type, factor to s) of the log's column ``t``; None without it."""
    if "t" not in table.schema.names:
        return None
    field = table.schema.field("t")
    unit = field_unit(field)
    return field.type, (_UNITS[_field_spelling(field, name)][1] if unit is not None else 1.0)


def _coarse_time(time_stored, t: float, before: float) -> str:
    """'; t is stored as float32, ...' when ``t`` [s] was stored (``time_stored``: Arrow type, factor
    to s) as a float type too coarse to tell it from the row ``before`` apart (seconds since 1970
    in float32 are 128 s apart); else ''."""
    if time_stored is None or not pa.types.is_floating(time_stored[0]) or time_stored[0].bit_width >= 64:
        return ""
    dtype, factor = np.dtype(f"float{time_stored[0].bit_width}"), time_stored[1]
    step = float(np.spacing(dtype.type(abs(t) / factor))) * factor
    if abs(t - before) > 4 * step:
        return ""
    return f"; 't' is stored as {dtype.name}, whose steps are {step:.3g} s at this time: write it as float64"


def _joint_values(table: pa.Table) -> np.ndarray:
    col = table.column("joint")
    if pa.types.is_integer(col.type) and not col.null_count:
        # from the buffers: a cast would load pyarrow.compute and to_numpy pandas (0.1 s of start-up)
        kind = "u" if pa.types.is_unsigned_integer(col.type) else "i"
        dtype = np.dtype(f"{kind}{col.type.bit_width // 8}")
        parts = [np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c), offset=dtype.itemsize * c.offset)
                 for c in col.chunks if len(c)]
        return np.concatenate(parts + [np.empty(0, dtype=dtype)]).astype(np.int64)
    return np.array(col.to_pylist(), dtype=object)


def joints_of(table: pa.Table, name: str = "log") -> list | None:
    """The joints in the log's ``joint`` column in order of appearance; None without the column
    (or with one of nulls only, ``joints.named``)."""
    if "joint" not in table.column_names:
        return None
    values = _joint_values(table)
    if len(values):
        values = values[np.concatenate([[0], np.flatnonzero(values[1:] != values[:-1]) + 1])]
    return joints.named(list(dict.fromkeys(values.tolist())), name)


def select_joint(table: pa.Table, joint, name: str) -> tuple[pa.Table, object]:
    """Rows of one joint by the joint rule (``fricli.core.joints``): ``joint=None`` means the only
    joint; several need a choice; ``--joint`` on a log without a joint column is refused."""
    return select_joint_rows(table, joint, name)[:2]


def select_joint_rows(table: pa.Table, joint, name: str) -> tuple[pa.Table, object, np.ndarray | None]:
    """``select_joint`` and the log's row numbers of the rows selected (None: every row)."""
    found = joints_of(table, name)
    if found is None:
        return table, joints.select(None, joint, name)[0], None   # refuses --joint
    if not found:  # no rows: refused as empty later
        return table, joint, None
    covered = joints.select(found, joint, name)
    if len(covered) > 1:
        raise joints.several(found, name)
    if len(found) == 1:
        return table, covered[0], None
    keep = _joint_values(table) == covered[0]
    return take_rows(table, keep), covered[0], np.flatnonzero(keep)


def from_table(table: pa.Table, *, name: str, sha256: str = "", joint=None, kt: float | None = None,
               cutoff_hz: float = DEFAULT_CUTOFF_HZ, drop_invalid: bool = False, warn=None, zero=(),
               rows: np.ndarray | None = None, later_batch: bool = False, qdd: bool = True) -> Log:
    """Check ``table`` against the contract and build a ``Log`` for one joint. ``zero``: robot-model
    columns (tau_g, tau_dyn) declared zero when the log lacks them (``declared_zero``); they are
    filled with zeros in ``signals``, with a note through ``warn``. ``rows``: the file's row number
    of each row of ``table`` (for messages), when it holds one joint's rows of a larger file.
    ``later_batch``: ``table`` follows an earlier record batch of the same file and joint, whose
    reading checked the units of t, q and qd (the file-wide notes are not repeated per batch).
    ``Log.reading`` keeps these options (the names of the options of
    ``fricli.fitting.optionspec.READING``). ``qdd`` False: a missing acceleration is not derived
    where qd is measured (for a reader that reads none; ``logs_motion.derive_motion``)."""
    joint_given, declared = joint, tuple(zero)
    table, joint, selected = select_joint_rows(table, joint, name)
    rows = selected if selected is not None or rows is None else np.asarray(rows)
    axis = axis_of(table.schema, name)
    note = unitless_note(table.schema, name)
    if note and warn:
        warn(note)
    sig = table_signals(table, axis, name, kt=kt, drop_invalid=drop_invalid, rows=rows)
    mask = check_signals(sig, name, drop_invalid=drop_invalid, warn=warn, rows=rows,
                         time_stored=_time_stored(table, name))
    if mask is not None:
        table = take_rows(table, mask)
    # the first 100,000 steps tell the sample period (and cost a millisecond on a log of any length)
    step = float(np.median(np.diff(sig["t"][:100_001]))) if len(sig["t"]) > 1 and not later_batch else None
    if warn and implausible_step(step):
        warn(f"warning: {name}: the median time step is {step:.3g} s, which no controller samples at: check the "
             "unit of 't' (Parquet field metadata 'unit': s, ms, us or ns; docs/log-format.md)")
    where = name if selected is None else f"{name}, joint {joint}"   # what one joint's rows show
    for column, note in not_measured(sig, qdd):
        del sig[column]
        if warn:
            warn(f"note: {where}: {note}")
    mismatch = None if later_batch else rate_mismatch(sig)
    if mismatch and warn:
        warn(f"warning: {where}: {mismatch}")
    derived = derive_motion(sig, cutoff_hz, qdd, rotary=axis == "rotary")
    if derived.get("unwrapped") and warn:
        warn(f"note: {where}: the position jumps by a turn where it wraps: qd is derived from it unwrapped")
    dead = dead_torque(sig, CANONICAL[axis]["tau"])
    if dead and warn:
        warn(f"warning: {where}: {dead}")
    zero = tuple(c for c in declared_zero(table.schema, name, zero) if c not in sig)
    for column in zero:
        sig[column] = np.zeros(len(sig["t"]))
    if zero and warn:
        warn(f"note: {name}: no {' and no '.join(zero)} column: taken as 0, as declared")
    reading = {"joint": joint_given, "kt": kt, "cutoff": cutoff_hz, "drop_invalid": drop_invalid,
               **{flag: column in declared for flag, column in (("no_gravity", "tau_g"), ("no_dynamics", "tau_dyn"))}}
    return Log(table=table, signals=sig, axis=axis, joint=joint, sha256=sha256, name=name, derived=derived,
               zero=zero, reading=reading)


def load_log(path: str, **kwargs) -> Log:
    """Read and check a log file (``-`` for stdin). Keyword arguments as ``from_table``."""
    table, digest = read_table(path)
    return from_table(table, name="stdin" if path == "-" else path, sha256=digest, **kwargs)


# ------------------------------------------------------------------------- targets


def friction_target(sig: dict[str, np.ndarray]) -> np.ndarray:
    """tau_f = tau_m + tau_ext - tau_g - tau_dyn [Nm]: the torque lost to friction, positive along
    the motion. A training and scoring target, not a model input: it reads the reference tau_ext
    where the log measures it (a log without it is taken to move free of external torque). A
    missing tau_g or tau_dyn is refused (``column``) unless declared zero when the log was read."""
    return sig["tau_m"] + column(sig, "tau_ext") - column(sig, "tau_g") - column(sig, "tau_dyn")


def external_torque(sig: dict[str, np.ndarray], tau_f_pred: np.ndarray) -> np.ndarray:
    """tau_ext_pred = tau_g + tau_dyn + tau_f_pred - tau_m [Nm]: inputs only."""
    return tau_f_pred - sig["tau_m"] + column(sig, "tau_g") + column(sig, "tau_dyn")


def column(sig: dict[str, np.ndarray], name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
    """Rows start:stop of a signal. A missing tau_ext (a reference: no external torque measured)
    gives zeros; a missing robot-model column (tau_g, tau_dyn) is unknown: DataError with the fix."""
    if name in sig:
        return sig[name][start:stop]
    if name == "tau_ext":
        rows = next((len(v) for v in sig.values()), 0)
        return np.zeros(len(range(rows)[start:stop]))
    if name in ROBOT_MODEL:
        raise DataError(missing_robot_model(name))
    raise DataError(f"the log has no column {name!r}")


# ------------------------------------------------------------------------- writing


def with_column(table: pa.Table, name: str, values: np.ndarray, unit: str | None) -> pa.Table:
    """``table`` with a float64 column set (replaced if present), keeping field metadata."""
    field = pa.field(name, pa.float64(), metadata={"unit": unit} if unit else None)
    array = float64_array(values)
    idx = table.schema.get_field_index(name)
    if idx >= 0:
        return table.set_column(idx, field, array)
    return table.append_column(field, array)


