"""Read a delimited text recording: the columns a mapping names, with every defect found.

A clean file is parsed by pyarrow's CSV reader; a file with any bad row is read again row by
row to find each one. Fields are split at the delimiter (no quoting: numbers need none). Defects (docs/robot-import.md):

    wrong field count, non-numeric or non-finite value  -> row dropped (reported)
    unterminated last line that does not parse          -> dropped as truncated (reported)
    time equal to the previous kept row                 -> row dropped (reported)
    time going back                                     -> refused, or dropped with drop_backward
"""

from __future__ import annotations

import collections
import dataclasses
import io
import re

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


def _line_bounds(data: bytes) -> tuple[np.ndarray, np.ndarray, bool]:
    """Start and end offsets of every line (without its line end) and whether the last line
    has a line end."""
    arr = np.frombuffer(data, dtype=np.uint8)
    breaks = np.flatnonzero(arr == 10)
    terminated = data.endswith(b"\n")
    starts = np.concatenate([[0], breaks + 1])
    ends = np.concatenate([breaks, [len(data)]])
    if terminated:
        starts, ends = starts[:-1], ends[:-1]
    if len(arr):
        ends = ends - ((ends > starts) & (arr[np.maximum(ends - 1, 0)] == 13))   # CRLF
    return starts, ends, terminated


def _fields(line: bytes, delimiter: str) -> list[bytes]:
    """Fields of one line: plain splitting (no quoting; numbers need none)."""
    return line.split(delimiter.encode())


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
            parse_options=pcsv.ParseOptions(delimiter=delimiter, quote_char=False, invalid_row_handler=invalid),
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


_NUMBER = r"^[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?$"


def _careful(data, starts, ends, start, stop, n_fields, wanted, delimiter, defect):
    """Lines ``start:stop``, reporting the wrong field counts and non-numbers; vectorised (numpy
    for the field counts, pyarrow for the numbers), so a few bad rows cost little more."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    starts, ends = starts[start:stop], ends[start:stop]
    numbers = np.arange(start, stop) + 1
    filled = ends > starts
    starts, ends, numbers = starts[filled], ends[filled], numbers[filled]
    marks = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == ord(delimiter))
    fields = np.searchsorted(marks, ends) - np.searchsorted(marks, starts) + 1
    wrong = fields != n_fields
    if wrong.any():
        defect("field_count", int(numbers[wrong][0]), int(wrong.sum()))
        starts, ends, numbers = starts[~wrong], ends[~wrong], numbers[~wrong]
    if len(numbers) == 0:
        return {c: np.empty(0) for c in wanted}, numbers
    body = b"\n".join([data[a:b] for a, b in zip(starts.tolist(), ends.tolist())]) + b"\n"
    names = [f"c{i}" for i in range(n_fields)]
    table = pcsv.read_csv(
        io.BytesIO(body), read_options=pcsv.ReadOptions(column_names=names),
        parse_options=pcsv.ParseOptions(delimiter=delimiter, quote_char=False, ignore_empty_lines=False),
        convert_options=pcsv.ConvertOptions(column_types={names[i]: pa.string() for i in wanted},
                                            include_columns=[names[i] for i in wanted]))
    if table.num_rows != len(numbers):  # not expected: every line is one row here
        raise LogError("the recording's lines could not be told apart")
    texts = {i: pc.utf8_trim_whitespace(table.column(names[i])) for i in wanted}
    ok = np.ones(len(numbers), dtype=bool)
    for text in texts.values():
        ok &= np.asarray(pc.match_substring_regex(text, _NUMBER).to_numpy(zero_copy_only=False), dtype=bool)
    if not ok.all():
        defect("non_numeric", int(numbers[~ok][0]), int((~ok).sum()))
    keep = pa.array(ok)
    cols = {i: pc.cast(pc.filter(text, keep), pa.float64()).to_numpy() for i, text in texts.items()}
    return cols, numbers[ok]


def _parse_row(fields: list[bytes], n_fields: int, wanted: list[int]) -> tuple[str | None, list[float]]:
    """One line (the unterminated last one) checked like ``_careful`` checks the others."""
    if len(fields) != n_fields:
        return "field_count", []
    texts = [fields[i].strip().decode("ascii", "replace") for i in wanted]
    if not all(re.match(_NUMBER, text) for text in texts):
        return "non_numeric", []
    return None, [float(text) for text in texts]


def read_recording(data: bytes, mapping: Mapping, name: str, *, drop_backward: bool = False) -> Recording:
    """Parse ``data`` (the file's bytes) with ``mapping``. LogError (exit 3) when nothing is
    usable, a named column is missing, or time goes back without ``drop_backward``."""
    if data.count(b"\r") != data.count(b"\r\n"):
        raise LogError(f"{name}: holds carriage returns that are not part of a CRLF line end (old Mac line "
                       "ends?): convert the file to LF or CRLF line ends")
    starts, ends, terminated = _line_bounds(data)
    line = lambda i: data[starts[i]:ends[i]]  # noqa: E731
    n_lines = len(starts)
    first = next((i for i in np.flatnonzero(ends > starts) if line(i).strip()), None)
    if first is None:
        raise LogError(f"{name}: the recording is empty")
    header = None
    start = int(first)
    if mapping.header:
        header = [f.strip().decode("utf-8", "replace") for f in _fields(line(start), mapping.delimiter)]
        n_fields = len(header)
        start += 1
    else:
        sample = (line(i) for i in range(start, min(start + 200, n_lines)))
        counts = collections.Counter(len(_fields(ln, mapping.delimiter)) for ln in sample if ln.strip())
        n_fields = counts.most_common(1)[0][0]
    index = _indices(_refs(mapping), header, n_fields, name)
    wanted = sorted(set(index.values()))

    defects: dict[str, Defect] = {}

    def defect(kind: str, line_number: int, count: int = 1) -> None:
        if kind in defects:
            defects[kind].count += count
        else:
            defects[kind] = Defect(count, line_number)

    # an unterminated last line is parsed on its own: a truncated one is a defect of its own kind
    n_body = n_lines - 1 if not terminated and n_lines > start else n_lines
    numbers = np.flatnonzero(ends[start:n_body] > starts[start:n_body]) + start + 1   # 1-based, non-empty
    fast = None
    if len(numbers):
        body_end = starts[n_body] if n_body < n_lines else len(data)
        fast = _fast(data[starts[start]:body_end], n_fields, index, mapping.delimiter)
    if fast is not None and fast[1] == len(numbers):
        cols, _ = fast
    else:  # slow path: find every bad row
        cols, numbers = _careful(data, starts, ends, start, n_body, n_fields, wanted, mapping.delimiter, defect)
    unterminated = None
    if n_body < n_lines and line(n_lines - 1).strip():
        kind, row = _parse_row(_fields(line(n_lines - 1), mapping.delimiter), n_fields, wanted)
        if kind:
            defect("truncated", n_lines)
        else:
            cols = {c: np.append(cols[c], row[k]) for k, c in enumerate(wanted)}
            numbers = np.append(numbers, n_lines)
            unterminated = n_lines
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
