"""Reading and writing a log's Parquet bytes: a file, stdin (spooled for reading in batches), the
options fricli writes with. The log contract on top of them is ``fricli.core.logs``."""

from __future__ import annotations

import collections
import contextlib
import hashlib
import os
import signal
import sys
import tempfile
import weakref

import numpy as np

from fricli.core import files, lazy
from fricli.core.atomic import atomic_open
from fricli.core.errors import LogError

pa = lazy.module("pyarrow")
pq = lazy.module("pyarrow.parquet")


def read_bytes(path: str) -> bytes:
    """Whole file (or stdin for ``-``) as bytes; stdin may be a pipe, so it is read first."""
    if path == "-":
        return files.read_stdin(LogError)
    return files.read_bytes(path, LogError, "file", "log")


def parquet_file(data: bytes, name: str) -> pq.ParquetFile:
    if not data:
        raise LogError(f"{name}: empty input, not a Parquet log")
    try:
        # an Arrow buffer, not a Python file object: pyarrow's reader threads reading through
        # Python now and then abort the interpreter at exit ("terminate called without an active
        # exception"); pre_buffer would keep a second copy
        pf = pq.ParquetFile(pa.BufferReader(data), pre_buffer=False)
    except Exception:  # pyarrow raises several types for corrupt input
        raise LogError(not_parquet(name, data[:4])) from None
    return unique_columns(pf, name)


def unique_columns(pf: pq.ParquetFile, name: str) -> pq.ParquetFile:
    """``pf``, or LogError when a column name appears twice (no column could be told which)."""
    seen = collections.Counter(pf.schema_arrow.names)
    twice = [c for c, k in seen.items() if k > 1]
    if twice:
        raise LogError(f"{name}: column {twice[0]!r} appears {seen[twice[0]]} times")
    return pf


def not_parquet(name: str, head: bytes) -> str:
    """The message for input that is not Parquet; ``head``: its first bytes."""
    if not head:
        return f"{name}: empty input, not a Parquet log"
    if head == b"PAR1":   # a damaged Parquet file, not another format
        return f"{name}: not a Parquet file: damaged (truncated, or written only in part)"
    return f"{name}: not a Parquet file (convert a CSV or other text recording with fricli import, docs/robot-import.md)"


# Reading a large log in record batches: pyarrow's default pre_buffer keeps every column chunk
# read so far until the file is closed (a 20-million-row log would end up in memory whole), and
# without a buffer size a whole column chunk is read at once (a log written as one row group).
STREAMING = {"pre_buffer": False, "buffer_size": 1 << 20}


def stdin_parquet() -> pq.ParquetFile:
    """stdin as a ParquetFile for reading in batches. Parquet needs random access (its footer
    is at the end), so stdin is spooled to a temporary file in $TMPDIR rather than held in
    memory. pyarrow reads it as its own file (not through a Python file object, as in
    ``parquet_file``); the name is removed as soon as it is open, so nothing is left behind."""
    # SIGTERM or Ctrl-C between the file's creation and the try below would leave it behind:
    # held until the try (the handlers then run inside it, where the name is removed)
    mask = getattr(signal, "pthread_sigmask", None)
    held = mask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT}) if mask else None
    try:
        fd, spool = tempfile.mkstemp(prefix="fricli-stdin-")
    except OSError as exc:
        if held is not None:
            mask(signal.SIG_SETMASK, held)
        raise LogError(f"stdin: cannot spool the input to a temporary file ({exc.strerror or exc})") from None
    try:
        if held is not None:
            mask(signal.SIG_SETMASK, held)
        with os.fdopen(fd, "wb") as out:
            size = 0
            while chunk := sys.stdin.buffer.read(files.CHUNK):
                out.write(chunk)
                size += len(chunk)
                if size > files.SPOOL_LIMIT:
                    raise LogError(f"stdin: more than {files.SPOOL_LIMIT:,} bytes on stdin (the limit); write "
                                   "the log to a file and give its path")
        source = pa.OSFile(spool, "rb")
    except OSError as exc:
        raise LogError(f"stdin: cannot spool the input to a temporary file ({exc.strerror or exc})") from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(spool)
    if size == 0:
        source.close()
        raise LogError("stdin: empty input, not a Parquet log")
    try:
        pf = pq.ParquetFile(source, **STREAMING)
    except Exception:
        source.seek(0)
        message = not_parquet("stdin", source.read(4))
        source.close()
        raise LogError(message) from None
    weakref.finalize(pf, source.close)   # the ParquetFile reads the file but does not own it
    return unique_columns(pf, "stdin")


def read_table(path: str) -> tuple[pa.Table, str]:
    """The whole table and the sha256 of the file's bytes."""
    data = read_bytes(path)
    name = "stdin" if path == "-" else path
    pf = parquet_file(data, name)
    try:
        # every pyarrow read in fricli is single-threaded: its reader threads now and then abort
        # the interpreter at exit on a loaded machine (docs/reliability.md)
        table = pf.read(use_threads=False)
    except Exception as exc:
        raise LogError(f"{name}: cannot read Parquet data ({str(exc).splitlines()[0]})") from None
    return table, hashlib.sha256(data).hexdigest()


def parquet_options(schema: pa.Schema) -> dict:
    """How fricli writes a log: zstd, no dictionaries (signals rarely repeat a value), float
    columns byte-stream-split (about 40 % smaller for smooth signals, and faster to write)."""
    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    return {"compression": "zstd", "use_dictionary": False, "use_byte_stream_split": floats}


def write_table(table: pa.Table, path: str) -> None:
    """Write Parquet atomically (``-`` for stdout) with ``parquet_options``. Same table, same bytes."""
    with atomic_open(path, binary=True) as fh:
        pq.write_table(table, fh, **parquet_options(table.schema))


def table_from_arrays(columns: dict[str, np.ndarray], units: dict[str, str]) -> pa.Table:
    """A table with field metadata ``unit`` for every column named in ``units``."""
    fields, arrays = [], []
    for name, values in columns.items():
        arr = pa.array(values)
        unit = units.get(name)
        fields.append(pa.field(name, arr.type, metadata={"unit": unit} if unit else None))
        arrays.append(arr)
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))
