"""Read a delimited text recording: the columns a mapping names, with every defect found.

A clean file is parsed by pyarrow's CSV reader; a file with any bad row is read again row by
row to find each one. Defects (docs/robot-import.md):

    wrong field count, non-numeric or non-finite value  -> row dropped (reported)
    unterminated last line that does not parse          -> dropped as truncated (reported)
    time equal to the previous kept row                 -> row dropped (reported)
    time going back                                     -> refused, or dropped with drop_backward
"""

from __future__ import annotations

import collections
import csv
import dataclasses
import io

import numpy as np

from fricli.errors import LogError
from fricli.robot.mapping import Mapping

KINDS = {
    "field_count": "wrong number of fields",
    "non_numeric": "non-numeric or non-finite value",
    "truncated": "truncated last line",
    "duplicate_time": "same time as the previous row",
    "backward_time": "time going back",
}


@dataclasses.dataclass
class Defect:
    count: int
    first_line: int        # 1-based line number in the file


@dataclasses.dataclass
class Recording:
    """Columns named by the mapping, as float64 arrays of shape (n,) in the file's units,
    keyed by the mapping's column reference; ``lines`` are the rows' 1-based line numbers."""

    values: dict[int | str, np.ndarray]
    lines: np.ndarray
    defects: dict[str, Defect]
    n_fields: int
    unterminated: int | None = None   # line number of a last line without line end, kept as complete


def _refs(mapping: Mapping) -> list[int | str]:
    refs = [mapping.time.ref] + [c.ref for jm in mapping.joints for c in jm.columns.values()]
    return list(dict.fromkeys(refs))


def _split_lines(data: bytes) -> tuple[list[bytes], bool]:
    """Lines without their end, and whether the last line had one."""
    lines = data.split(b"\n")
    terminated = lines[-1] == b""
    if terminated:
        lines.pop()
    return [ln[:-1] if ln.endswith(b"\r") else ln for ln in lines], terminated


def _fields(line: bytes, delimiter: str) -> list[str]:
    text = line.decode("utf-8", "replace")
    return next(csv.reader([text], delimiter=delimiter), [])


def _indices(refs, header: list[str] | None, n_fields: int, name: str) -> dict[int | str, int]:
    out = {}
    for ref in refs:
        if isinstance(ref, int):
            if ref > n_fields:
                raise LogError(f"{name}: the mapping names column {ref}, but rows have {n_fields} fields")
            out[ref] = ref - 1
        else:
            if header is None:
                raise LogError(f"{name}: the mapping names column {ref!r} but has header = false: use an index")
            if ref not in header:
                raise LogError(f"{name}: no column {ref!r} in the header line")
            if header.count(ref) > 1:
                raise LogError(f"{name}: column {ref!r} appears twice in the header line")
            out[ref] = header.index(ref)
    return out


def _fast(body: bytes, n_fields: int, index: dict, delimiter: str):
    """All wanted columns via pyarrow, or None when any row is bad (the slow path finds it)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    bad = []

    def invalid(row):
        bad.append(row)
        return "skip"

    wanted = sorted(set(index.values()))
    names = [f"c{i}" for i in range(n_fields)]
    try:
        table = pcsv.read_csv(
            io.BytesIO(body),
            read_options=pcsv.ReadOptions(column_names=names, use_threads=False),
            parse_options=pcsv.ParseOptions(delimiter=delimiter, invalid_row_handler=invalid),
            convert_options=pcsv.ConvertOptions(column_types={names[i]: pa.float64() for i in wanted},
                                                include_columns=[names[i] for i in wanted]))
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None
    if bad:
        return None
    cols = {}
    for i in wanted:
        col = table.column(names[i])
        if col.null_count:
            return None
        values = col.to_numpy()
        if not np.isfinite(values).all():
            return None
        cols[i] = values
    return cols, table.num_rows


def _parse_row(fields: list[str], n_fields: int, wanted: list[int]) -> tuple[str | None, list[float]]:
    if len(fields) != n_fields:
        return "field_count", []
    try:
        row = [float(fields[i]) for i in wanted]
    except ValueError:
        return "non_numeric", []
    if not all(np.isfinite(row)):
        return "non_numeric", []
    return None, row


def read_recording(data: bytes, mapping: Mapping, name: str, *, drop_backward: bool = False) -> Recording:
    """Parse ``data`` (the file's bytes) with ``mapping``. LogError (exit 3) when nothing is
    usable, a named column is missing, or time goes back without ``drop_backward``."""
    lines, terminated = _split_lines(data)
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise LogError(f"{name}: the recording is empty")
    header = None
    start = first
    if mapping.header:
        header = [f.strip() for f in _fields(lines[first], mapping.delimiter)]
        n_fields = len(header)
        start = first + 1
    else:
        counts = collections.Counter(len(_fields(ln, mapping.delimiter)) for ln in lines[start:start + 200] if ln.strip())
        n_fields = counts.most_common(1)[0][0]
    index = _indices(_refs(mapping), header, n_fields, name)
    wanted = sorted(set(index.values()))

    defects: dict[str, Defect] = {}

    def defect(kind: str, line: int, count: int = 1) -> None:
        if kind in defects:
            defects[kind].count += count
        else:
            defects[kind] = Defect(count, line)

    # an unterminated last line is parsed on its own: a truncated one is a defect of its own kind
    last, unterminated = None, None
    body_lines = lines
    if not terminated and len(lines) > start:
        last, body_lines = lines[-1], lines[:-1]
    body = b"\n".join(body_lines[start:]) + b"\n"
    numbers = np.array([i + 1 for i in range(start, len(body_lines)) if body_lines[i].strip()], dtype=np.int64)
    fast = _fast(body, n_fields, index, mapping.delimiter) if len(numbers) else ({i: np.empty(0) for i in wanted}, 0)
    if fast is not None and fast[1] == len(numbers):
        cols, _ = fast
    else:  # slow path: row by row, to find every bad row
        rows, kept = [], []
        for i in range(start, len(body_lines)):
            if not body_lines[i].strip():
                continue
            kind, row = _parse_row(_fields(body_lines[i], mapping.delimiter), n_fields, wanted)
            if kind:
                defect(kind, i + 1)
            else:
                rows.append(row)
                kept.append(i + 1)
        matrix = np.array(rows, dtype=np.float64).reshape(len(rows), len(wanted))
        cols = {c: matrix[:, k] for k, c in enumerate(wanted)}
        numbers = np.array(kept, dtype=np.int64)
    if last is not None and last.strip():
        kind, row = _parse_row(_fields(last, mapping.delimiter), n_fields, wanted)
        if kind:
            defect("truncated", len(lines))
        else:
            cols = {c: np.append(cols[c], row[k]) for k, c in enumerate(wanted)}
            numbers = np.append(numbers, len(lines))
            unterminated = len(lines)
    if len(numbers) == 0:
        found = "; ".join(f"{d.count} with {KINDS[k]} (first at line {d.first_line})" for k, d in defects.items())
        raise LogError(f"{name}: no usable rows" + (f" ({found})" if found else ""))

    # time order: a row must come after every row kept before it
    t = cols[index[mapping.time.ref]]
    before = np.maximum.accumulate(t)
    late = np.zeros(len(t), dtype=bool)
    late[1:] = t[1:] <= before[:-1]
    if late.any():
        same = np.zeros(len(t), dtype=bool)
        same[1:] = late[1:] & (t[1:] == before[:-1])
        back = late & ~same
        if back.any():
            at = int(np.flatnonzero(back)[0])
            if not drop_backward:
                raise LogError(f"{name}: time goes back at line {numbers[at]} (t = {t[at]:g} after {before[at - 1]:g}; "
                               f"{int(back.sum())} rows before the latest time): use --drop-backward to drop them")
            defect("backward_time", int(numbers[at]), int(back.sum()))
        if same.any():
            defect("duplicate_time", int(numbers[np.flatnonzero(same)[0]]), int(same.sum()))
        keep = ~late
        cols = {c: v[keep] for c, v in cols.items()}
        numbers = numbers[keep]
    defects = dict(sorted(defects.items(), key=lambda kv: list(KINDS).index(kv[0])))
    return Recording(values={ref: cols[i] for ref, i in index.items()}, lines=numbers, defects=defects,
                     n_fields=n_fields, unterminated=unterminated if unterminated in numbers else None)
