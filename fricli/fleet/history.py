"""The fleet history: a Parquet dataset, partitioned by robot (``HISTORY/robot=NAME/*.parquet``).

Every run that did work appends one file per robot, ``run-<UTC time>-<id>.parquet``, with one row
per job that ran (ok or failed; unchanged jobs add nothing), written atomically (temporary file
and rename). Any Parquet dataset reader understands it (hive partitioning, e.g.
``pandas.read_parquet(HISTORY)``); ``read`` below keeps robot names as strings.
"""

from __future__ import annotations

import os

import pyarrow as pa

from fricli.core import atomic
from fricli.core.errors import LogError, OutputError

# LuGre parameters kept as columns (NaN for model kinds without them), with their units for a rotary joint.
PARAMETERS = {"fc": "Nm", "fs": "Nm", "vs": "rad/s", "delta": "-", "fv": "Nm s/rad", "kc": "Nm/Nm",
              "ks": "Nm/Nm", "sigma0": "Nm/rad", "sigma1": "Nm s/rad"}
ERRORS = {"mae": "Nm", "rmse": "Nm", "max_error": "Nm"}


def _field(name: str, type_: pa.DataType, unit: str | None = None, doc: str = "") -> pa.Field:
    meta = {b"doc": doc.encode()}
    if unit:
        meta[b"unit"] = unit.encode()
    return pa.field(name, type_, metadata=meta)


SCHEMA = pa.schema(
    [_field("joint", pa.string(), doc="joint name"),
     _field("date", pa.date32(), doc="day the log's data is from"),
     _field("run", pa.string(), doc="run id (UTC start time and a random suffix)"),
     _field("run_time", pa.timestamp("s", tz="UTC"), doc="when the run started"),
     _field("status", pa.string(), doc="ok or failed"),
     _field("reason", pa.string(), doc="why the job failed (empty when ok)"),
     _field("pipeline", pa.string(), doc="identify, train-base or adapt"),
     _field("model_kind", pa.string(), doc="kind of the model written"),
     _field("log", pa.string(), doc="log file"),
     _field("log_sha256", pa.string(), doc="sha256 of the log's bytes"),
     _field("model", pa.string(), doc="model file written"),
     _field("seconds", pa.float64(), "s", "run time of the job")]
    + [_field(name, pa.float64(), unit, f"identified LuGre parameter {name}") for name, unit in PARAMETERS.items()]
    + [_field(name, pa.float64(), unit, f"friction error ({name}) of the model over the log's rows in motion "
                                        "(fricli.core.metrics.in_motion), every pipeline alike")
       for name, unit in ERRORS.items()]
    + [_field("effects", pa.string(), doc="effects the model misses, comma-separated (diagnose; empty when not run)")]
)


def row(job, result: dict, run: str, run_time) -> dict:
    """One history row for a job (``fricli.fleet.manifest.Job``) and its result (``pipelines.run``)."""
    import datetime as dt

    params = result.get("parameters") or {}
    errs = result.get("errors") or {}
    out = {"robot": job.robot, "joint": job.joint, "date": dt.date.fromisoformat(job.date), "run": run,
           "run_time": run_time, "status": result["status"], "reason": result.get("reason", ""),
           "pipeline": job.pipeline, "model_kind": result.get("kind"), "log": job.log,
           "log_sha256": result.get("sha256", ""), "model": job.model if result["status"] == "ok" else "",
           "seconds": float(result.get("seconds", float("nan"))), "effects": ",".join(result.get("effects", []))}
    for name in PARAMETERS:
        value = params.get(name)
        out[name] = float(value) if value is not None else float("nan")
    out["mae"], out["rmse"], out["max_error"] = (float(errs[k]) if errs.get(k) is not None else float("nan")
                                                 for k in ("mae", "rmse", "max"))
    return out


def append(history: str, rows: list[dict], run: str) -> list[str]:
    """Append ``rows`` (from ``row``) as one file per robot; returns the files written."""
    by_robot: dict[str, list[dict]] = {}
    for r in rows:
        by_robot.setdefault(r["robot"], []).append(r)
    written = []
    for robot, items in sorted(by_robot.items()):
        folder = os.path.join(history, f"robot={robot}")
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"cannot write the history {history}: {exc.strerror}") from None
        columns = {f.name: [r[f.name] for r in items] for f in SCHEMA}
        table = pa.Table.from_pydict(columns, schema=SCHEMA)
        path = os.path.join(folder, f"run-{run}.parquet")

        def write(fh, table=table):
            import pyarrow.parquet as pq

            pq.write_table(table, fh, compression="zstd")

        atomic.atomic_write_with(path, write)
        written.append(path)
    return written


def read(history: str, *, partitioned: bool = False) -> pa.Table:
    """The whole history as one table (robot as a string column); LogError when it cannot be read,
    and with ``partitioned`` when the folder holds no ``robot=NAME`` folder (not a history: fleet
    writes one as it records the first row).

    Reads file by file with ``pq.ParquetFile`` (not pyarrow's threaded dataset reader)."""
    import glob

    import pyarrow.parquet as pq

    if not os.path.isdir(history):
        raise LogError(f"{history}: no such history folder")
    tables = []
    folders = sorted(glob.glob(os.path.join(glob.escape(history), "robot=*")))
    if partitioned and not folders:
        raise LogError(f"{history}: not a fleet history (no robot=NAME folder in it: the history is the folder "
                       "of the manifest's [fleet] history, once fricli fleet has recorded a job)")
    for folder in folders:
        robot = os.path.basename(folder).removeprefix("robot=")
        for path in sorted(glob.glob(os.path.join(glob.escape(folder), "*.parquet"))):
            try:
                table = pq.ParquetFile(path).read(use_threads=False)
            except (pa.ArrowInvalid, OSError) as exc:
                raise LogError(f"{path}: cannot read this part of the history ({str(exc).splitlines()[0]})") from None
            missing = [f.name for f in SCHEMA if f.name not in table.column_names]
            if missing:
                raise LogError(f"{path}: not a fricli history file (no column {missing[0]})")
            try:   # columns of other types, and dates Python cannot hold, are no history of fricli's
                table = table.select([f.name for f in SCHEMA]).cast(SCHEMA)
                table.column("date").to_pylist()
                table.column("run_time").to_pylist()
            except (pa.ArrowException, OverflowError, ValueError, TypeError) as exc:
                raise LogError(f"{path}: not a fricli history file ({str(exc).splitlines()[0]})") from None
            empty = [c for c in ("joint", "date", "run_time", "status") if table.column(c).null_count]
            if empty:
                raise LogError(f"{path}: not a fricli history file (missing values in column {empty[0]})")
            tables.append(table.append_column(pa.field("robot", pa.string()), pa.array([robot] * table.num_rows,
                                                                                      pa.string())))
    if not tables:
        return SCHEMA.append(pa.field("robot", pa.string())).empty_table()
    return pa.concat_tables(tables)
