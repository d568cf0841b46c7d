"""Batched prediction and external-torque estimation for any model kind.

``run_models`` reads a log in record batches (``pq.ParquetFile.iter_batches``), checks each
batch against the log contract (``t`` strictly increasing across batch boundaries too), predicts
with the model's state carried from one batch to the next (e.g. the LuGre bristle state), and
streams the log with ``tau_f_pred`` (and ``tau_ext_pred``) added to a Parquet writer. All
columns and their field and schema metadata are carried through. On a log of several joints
each joint covered gets its own model (the joint rule, fricli/core/joints.py), state and time check;
the rows keep their order. A model that reads other joints' velocities (a coupled group's member,
or a model over one) gets them from the same rows (``fricli.models.coupled.add_partners``).

The log is read whole instead, as one batch, when a batch-wise reading would change the result:
when ``qd`` or ``qdd`` must be derived from ``q`` (the zero-phase filter needs the whole series)
and when the external-torque estimate is low-passed (zero-phase, forwards and backwards).
"""

from __future__ import annotations

import dataclasses
import math
import mmap
import queue
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator

import numpy as np

from fricli import models
from fricli.core import files, joints, lazy, logs, logs_motion, timewindow
from fricli.core.atomic import Cuttable, atomic_open
from fricli.core.errors import DataError, LogError, ModelFileError, NoValidRows
from fricli.models import coupled
from fricli.models.base import FrictionModel
from fricli.numerics.nn.network import prediction_threads

pa = lazy.module("pyarrow")
pc = lazy.module("pyarrow.compute")
pq = lazy.module("pyarrow.parquet")

DEFAULT_BATCH_ROWS = 262_144


class ErrorSums:
    """MAE, RMSE and max of y_pred - y accumulated over batches (same figures as
    ``fricli.core.metrics.errors`` on the concatenated arrays)."""

    def __init__(self):
        self.n = 0
        self.abs_sum = 0.0
        self.sq_sum = 0.0
        self.max = 0.0

    def add(self, y: np.ndarray, y_pred: np.ndarray) -> None:
        e = np.subtract(y_pred, y, dtype=np.float64)
        if e.size == 0:
            return
        self.n += e.size
        self.sq_sum += float(np.einsum("i,i->", e, e))
        np.abs(e, out=e)
        self.abs_sum += float(np.sum(e))
        self.max = max(self.max, float(np.max(e)))

    def merge(self, other: "ErrorSums") -> None:
        self.n += other.n
        self.abs_sum += other.abs_sum
        self.sq_sum += other.sq_sum
        self.max = max(self.max, other.max)

    def result(self) -> dict:
        if self.n == 0:
            return {"mae": float("nan"), "rmse": float("nan"), "max": float("nan"), "n": 0}
        return {"mae": self.abs_sum / self.n, "rmse": math.sqrt(self.sq_sum / self.n), "max": self.max,
                "n": self.n}


@dataclasses.dataclass
class Result:
    rows: int                      # rows written
    joint: object                  # the joint predicted for (None: no joint column, or several joints)
    unit: str                      # unit of the torque columns (Nm or N)
    friction: dict                 # errors of tau_f_pred against the friction target
    external: dict | None          # errors of tau_ext_pred against the sensor column tau_ext
    batches: int
    read_whole: str | None         # why the log was read whole, or None
    dropped: int                   # rows dropped by --drop-invalid
    per_joint: dict | None = None  # several joints: {joint: {"rows", "model", "friction"[, "external"]}}
    extrapolation: dict | None = None   # rows outside the training envelope (None: no model has one)

    def as_json(self) -> dict:
        out = dataclasses.asdict(self)
        for key in ("external", "per_joint", "extrapolation"):
            if out[key] is None:
                del out[key]
        return out


def open_log(path: str) -> tuple[pq.ParquetFile, str]:
    """A ParquetFile for ``path`` (``-``: stdin, spooled to a temporary file) and its display name."""
    if path == "-":
        return logs.stdin_parquet(), "stdin"
    files.check_regular(path, LogError, "file", "log")
    try:
        pf = pq.ParquetFile(_source(path), **logs.STREAMING)
    except FileNotFoundError:
        raise LogError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise LogError(f"{path}: is a folder, not a log") from None
    except PermissionError:
        raise LogError(f"{path}: cannot read (permission denied)") from None
    except Exception:
        with open(path, "rb") as fh:
            raise LogError(logs.not_parquet(path, fh.read(4))) from None
    return logs.unique_columns(pf, path), path


def _source(path: str):
    """``path`` itself for Arrow, which takes UTF-8 paths; a name of other bytes is mapped into
    memory here and read from there (not through a Python file object, which Arrow's reader
    threads must not use)."""
    try:
        path.encode("utf-8")
        return path
    except UnicodeEncodeError:
        with open(path, "rb") as fh:
            return pa.BufferReader(pa.py_buffer(mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)))


def file_joints(pf: pq.ParquetFile, name: str) -> list | None:
    """The joints in the file's ``joint`` column in order of appearance (None without the column),
    read row group by row group: the whole column of a large log is hundreds of MB."""
    if "joint" not in pf.schema_arrow.names:
        return None
    found: dict = {}
    try:
        for group in range(pf.num_row_groups):
            column = pf.read_row_group(group, columns=["joint"], use_threads=False).column("joint")
            found.update(dict.fromkeys(pc.unique(column).to_pylist()))
    except Exception as exc:
        raise LogError(f"{name}: cannot read Parquet data ({str(exc).splitlines()[0]})") from None
    return joints.named(list(found), name)


def whole_reason(schema: pa.Schema, lowpass_hz: float | None, qdd: bool = True) -> str | None:
    """Why the log must be read whole (None: in record batches); ``qdd``: whether a model reads
    the acceleration (``logs.from_table``'s)."""
    names = set(schema.names)
    if lowpass_hz:
        return "the low-pass filter is zero-phase"
    missing = [c for c in ("qd", "qdd") if c not in names
               and (c == "qd" or logs_motion.derives_qdd("qd" in names, False, qdd))]
    if missing:
        return f"{' and '.join(missing)} derived with a zero-phase filter"
    return None


def _batches(pf: pq.ParquetFile, name: str, batch_rows: int, whole: bool) -> Iterator[tuple[int, pa.Table]]:
    """(row offset, table) pieces of the file, keeping field and schema metadata."""
    schema = pf.schema_arrow
    try:
        if whole:
            yield 0, pf.read(use_threads=False)
            return
        offset = 0
        for batch in pf.iter_batches(batch_size=batch_rows, use_threads=False):
            table = pa.Table.from_batches([batch])
            if table.schema.metadata != schema.metadata:
                table = table.replace_schema_metadata(schema.metadata)
            yield offset, table
            offset += batch.num_rows
    except LogError:
        raise
    except Exception as exc:
        raise LogError(f"{name}: cannot read Parquet data ({str(exc).splitlines()[0]})") from None


class _Prefetch:
    """Iterates over ``items`` one step ahead in a background thread (at most one item waiting)."""

    _END = object()

    def __init__(self, items: Iterator):
        self._items, self._queue = items, queue.Queue(maxsize=1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._pull, daemon=True)
        self._thread.start()

    def _pull(self) -> None:
        try:
            for item in self._items:
                if not self._put((item, None)):
                    return
        except BaseException as exc:  # handed over to the consumer
            self._put((None, exc))
            return
        self._put((self._END, None))

    def _put(self, entry) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(entry, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def __iter__(self):
        while True:
            item, exc = self._queue.get()
            if exc is not None:
                raise exc
            if item is self._END:
                return
            yield item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


@dataclasses.dataclass
class _Stream:
    """One joint's model and what carries from one batch to the next."""

    joint: object
    model: FrictionModel
    meta: dict
    model_name: str
    env: object = None             # the training envelope (fricli.core.envelope), None for older files
    state: object = None
    t_last: float | None = None
    outside: int = 0
    rows: int = 0
    read: int = 0                  # rows of the log read for this joint (valid or not)
    fric: ErrorSums = dataclasses.field(default_factory=ErrorSums)
    ext: ErrorSums = dataclasses.field(default_factory=ErrorSums)


_ROW = "__fricli_row"   # the file's row numbers (messages; the order of several joints' rows)


@dataclasses.dataclass(frozen=True)
class Reading:
    """How ``run_models`` reads a log: the joint rule's ``joint``, ``kt`` [Nm/A], ``cutoff_hz``
    and ``drop_invalid`` as ``logs.from_table``, the time ``window`` (fricli.core.timewindow) and the
    rows per record batch."""

    joint: object = None
    kt: float | None = None
    cutoff_hz: float = logs.DEFAULT_CUTOFF_HZ
    drop_invalid: bool = False
    window: timewindow.Window | None = None
    batch_rows: int = DEFAULT_BATCH_ROWS
    zero: tuple = ()               # robot-model columns declared zero (logs.from_table)


@dataclasses.dataclass(frozen=True)
class Outputs:
    """What ``run_models`` adds besides ``tau_f_pred``: ``tau_ext_pred`` when ``external``
    (low-passed at ``lowpass_hz`` [Hz] when given), and the boolean column ``extrapolating`` (the
    row lies outside its model's training envelope) when ``flag_extrapolation``."""

    external: bool = False
    lowpass_hz: float | None = None
    flag_extrapolation: bool = False


def run(model: FrictionModel, meta: dict, log_path: str, out_path: str, *, model_name: str = "model",
        outputs: Outputs = Outputs(), warn: Callable[[str], None] | None = None, **reading) -> Result:
    """``run_models`` with one model in memory (its recorded joint applies, docs/joints.md);
    ``reading``: the fields of ``Reading``."""
    source = joints.Source(model_name, {meta.get("joint"): model_name})
    return run_models(source, log_path, out_path, reading=Reading(**reading), outputs=outputs, warn=warn,
                      load=lambda _path: (model, meta))


def run_models(source: joints.Source, log_path: str, out_path: str, *, reading: Reading = Reading(),
               outputs: Outputs = Outputs(), warn: Callable[[str], None] | None = None,
               on_rows: Callable[[int, int], None] | None = None,
               load: Callable[[str], tuple] = models.load) -> Result:
    """Predict friction on the log at ``log_path`` with each joint's model of ``source`` (a model
    file or a model set, paired by the joint rule) and write it with ``tau_f_pred`` (and
    ``outputs``) added to ``out_path`` (``-``: stdout). Rows keep their order; rows of joints the
    run does not cover are left out, and rows outside ``reading.window``. A log without tau_g or
    tau_dyn is refused unless ``reading.zero`` declares it zero. ``on_rows(rows, total)``
    is called as each record batch of ``rows`` of the log's ``total`` is read (progress).
    Returns the figures."""
    joint, window, batch_rows = reading.joint, reading.window, reading.batch_rows
    pf, name = open_log(log_path)
    logs.require_robot_model(pf.schema_arrow, name, reading.zero)
    limits = timewindow.limits_of_file(pf, window, name, warn=warn) if window else None
    found = file_joints(pf, name)
    streams = {}
    for j, path in joints.pair(source, found, joint, name):
        model, meta = load(path)
        streams[j] = _Stream(j, coupled.view(model, j), meta, path, env=models.envelope(meta, path))
    several = len(streams) > 1
    filtered = found is not None and len(found) > len(streams)
    reason = whole_reason(pf.schema_arrow, outputs.lowpass_hz if outputs.external else None,
                          any(models.reads_acceleration(st.model) for st in streams.values()))
    if reason is None and any(coupled.partners_read(st.model) for st in streams.values()):
        reason = "the joints of a coupled group are predicted together"
    warnings: list[str] = []
    fric, ext_err = ErrorSums(), ErrorSums()
    rows = batches = dropped = 0
    unit = None
    has_ext = False
    total = pf.metadata.num_rows
    for st in streams.values():
        if outputs.flag_extrapolation and st.env is None:
            raise ModelFileError(f"{st.model_name}: the model file records no training envelope (written by an "
                                 "older fricli): --flag-extrapolation needs one")
    any_env = any(st.env is not None for st in streams.values())
    with atomic_open(out_path, binary=True) as fh, ThreadPoolExecutor(max_workers=1) as io:
        # the next batch is read and the last one written (pyarrow releases the GIL while it
        # decompresses and compresses) while this one is checked and predicted
        writer = pending = None
        sink = Cuttable(fh)   # after a failure, stdout or a pipe gets no footer: never a shorter valid log
        batches_read = _Prefetch(_batches(pf, name, batch_rows, reason is not None))
        try:
            for offset, table in batches_read:
                if on_rows is not None:
                    on_rows(table.num_rows, total)
                table = table.append_column(_ROW, pa.array(np.arange(offset, offset + table.num_rows)))
                if limits is not None:
                    table = timewindow.slice_batch(table, *limits)
                outs, tallies = [], []
                for j, st in streams.items():
                    part = table
                    if several or filtered:
                        jcol = table.column("joint")
                        part = table.filter(pc.equal(jcol, pa.scalar(j, jcol.type)))
                    if part.num_rows == 0:
                        continue
                    out, n_in = _predict_part(st, part, name, reading, outputs, warn, warnings, table, tallies)
                    st.read += n_in
                    if out is None:            # every row of the piece dropped (--drop-invalid)
                        dropped += n_in
                        continue
                    unit = unit or out.schema.field("tau_f_pred").metadata[b"unit"].decode()
                    dropped += n_in - out.num_rows
                    outs.append(out)
                if not outs:
                    continue
                out = outs[0] if len(outs) == 1 else pa.concat_tables(outs)
                if several:
                    out = out.take(pc.sort_indices(out.column(_ROW)))
                out = out.drop_columns([_ROW])
                if writer is None:
                    writer = pq.ParquetWriter(sink, out.schema, **logs.parquet_options(out.schema))
                if pending is not None:
                    pending.result()
                pending = io.submit(_tally_and_write, tallies, writer, out)
                rows += out.num_rows
                batches += 1
            for st in streams.values():
                if st.read and not st.rows:
                    of = f" of joint {st.joint}" if several else ""
                    raise LogError(f"{name}: no valid rows{of} left after dropping invalid ones")
            if writer is None:
                raise LogError(f"{name}: the log is empty")
            pending.result()
        except BaseException:
            sink.cut()
            raise
        finally:
            batches_read.close()
            if pending is not None:
                pending.exception()   # wait: the writer must not close under a write
            if writer is not None:
                writer.close()
    if warnings and warn:
        if dropped:
            warn(f"warning: dropped {dropped} rows with NaN, infinite or absurd values")
        for message in dict.fromkeys(warnings):
            if not dropped or not message.startswith("warning: dropped "):
                warn(message)
    per_joint = None
    n_outside = sum(st.outside for st in streams.values())
    for st in streams.values():
        fric.merge(st.fric)
        ext_err.merge(st.ext)
        has_ext = has_ext or st.ext.n > 0
    if several:
        per_joint = {str(j): {"rows": st.rows, "model": st.model_name, "friction": st.fric.result(),
                              **({"external": st.ext.result()} if st.ext.n else {}),
                              **({"outside": st.outside} if st.env is not None else {})}
                     for j, st in streams.items()}
    only = next(iter(streams)) if not several else None
    return Result(rows=rows, joint=only, unit=unit or "Nm", friction=fric.result(),
                  external=ext_err.result() if has_ext else None, batches=batches, read_whole=reason,
                  dropped=dropped, per_joint=per_joint,
                  extrapolation=None if not any_env else {"rows": n_outside, "of": rows,
                                                          "share": n_outside / rows if rows else 0.0})


def _tally_and_write(tallies: list[Callable[[], None]], writer, out: pa.Table) -> None:
    """Run a batch's ``tallies`` (error sums, rows outside the envelope) and write ``out``: on the
    writer's thread, which has time to spare while the next batch is predicted."""
    for tally in tallies:
        tally()
    writer.write_table(out)


def _predict_part(st: _Stream, table: pa.Table, name: str, reading: Reading, outputs: Outputs, warn,
                  warnings: list, whole: pa.Table, tallies: list) -> tuple[pa.Table | None, int]:
    """One joint's rows of one batch with tau_f_pred (and ``outputs``) added (None when
    ``--drop-invalid`` left none of them); the rows it had. What only adds to the figures (the
    stream's error sums and rows outside its envelope) is appended to ``tallies``, to run before
    the batch is written.
    ``whole``: the batch's rows of every joint (where the velocities of a coupled group's other
    joints come from)."""
    # the rows are this joint's already: set the joint column aside (cheaper to check)
    jpos = table.schema.get_field_index("joint")
    jfield = table.schema.field(jpos) if jpos >= 0 else None
    if jfield is not None:
        jcol = table.column(jpos)
        table = table.remove_column(jpos)
    rows = table.column(_ROW).to_numpy()   # the file's row numbers of these rows
    try:
        log = logs.from_table(table, name=name, kt=reading.kt, cutoff_hz=reading.cutoff_hz,
                              drop_invalid=reading.drop_invalid, warn=warnings.append, zero=reading.zero, rows=rows,
                              later_batch=st.t_last is not None, qdd=models.reads_acceleration(st.model))
    except NoValidRows:        # the rows of the other batches may be valid: judged once all are read
        return None, table.num_rows
    log.joint = st.joint
    coupled.add_partners(st.model, log, whole, kt=reading.kt, cutoff_hz=reading.cutoff_hz,
                         drop_invalid=reading.drop_invalid, zero=reading.zero)
    if st.t_last is None:
        models.check_log(st.meta, log, st.model_name)
        note = models.robot_model_note(st.meta, log)
        if note:
            warnings.append(note)
    sig = log.signals
    t = sig["t"]
    if st.t_last is not None and not t[0] > st.t_last:
        what = "duplicate timestamps" if t[0] == st.t_last else "'t' is not increasing"
        where = f" of joint {st.joint}" if st.joint is not None else ""
        raise LogError(f"{name}: {what}{where} (at row {int(rows[0])} between two batches, t = {t[0]:g} s)")
    st.t_last = float(t[-1])
    with prediction_threads(1):   # the reader and writer threads keep the other core busy
        try:
            tau_f, st.state = st.model.predict(sig, st.state)
        except DataError as exc:      # a column the model reads is missing: name the files
            raise DataError(f"{name}: {exc} ({st.model_name})") from None
    unit = log.units["tau"]
    out = log.table
    if jfield is not None:
        same = len(jcol) == out.num_rows   # the joint column as read, unless rows were dropped
        out = out.add_column(jpos, jfield, jcol if same else
                             pa.repeat(pa.scalar(st.joint, jfield.type), out.num_rows))
    out = logs.with_column(out, "tau_f_pred", tau_f, unit)
    tallies.append(lambda: st.fric.add(logs.friction_target(sig), tau_f))
    if outputs.external:
        est = external_estimate(sig, tau_f, outputs.lowpass_hz, warn)
        out = logs.with_column(out, "tau_ext_pred", est, unit)
        if "tau_ext" in sig:
            tallies.append(lambda: st.ext.add(sig["tau_ext"], est))
    if st.env is not None:
        if outputs.flag_extrapolation:
            outside = st.env.outside(sig)
            out = out.append_column(pa.field("extrapolating", pa.bool_()), pa.array(outside))
            tallies.append(lambda: _count_outside(st, outside))
        else:
            tallies.append(lambda: _count_outside(st, st.env.outside(sig)))
    if _ROW in out.column_names:   # keep it last, where the joints' pieces expect it
        col = out.column(_ROW)
        out = out.drop_columns([_ROW]).append_column(_ROW, col)
    st.rows += out.num_rows
    return out, table.num_rows


def _count_outside(st: _Stream, outside: np.ndarray) -> None:
    st.outside += int(np.count_nonzero(outside))


def external_estimate(signals: dict[str, np.ndarray], tau_f_pred: np.ndarray, lowpass_hz: float | None = None,
                      warn=None) -> np.ndarray:
    """tau_ext_pred = tau_g + tau_dyn + tau_f_pred - tau_m (n,) [Nm], optionally low-passed."""
    est = logs.external_torque(signals, tau_f_pred)
    if lowpass_hz:
        est = lowpass_external(est, signals["t"], lowpass_hz, warn)
    return est


def lowpass_external(est: np.ndarray, t: np.ndarray, cutoff_hz: float, warn=None) -> np.ndarray:
    """Zero-phase Butterworth low-pass (4th order) of tau_ext_pred (n,) at ``cutoff_hz``."""
    fs = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    if warn and (len(t) < 16 or cutoff_hz >= 0.5 * fs):
        warn(f"warning: --lowpass {cutoff_hz:g} Hz not applied (at or above the Nyquist frequency "
             f"{0.5 * fs:g} Hz, or too few rows)")
    logs_motion.check_lowpass_period(t, cutoff_hz)
    return logs.lowpass(est, t, cutoff_hz)
