"""Read a delimited text recording: the columns a mapping names, with every defect found.

A clean file is parsed by pyarrow's CSV reader; a file with any bad row is read again row by
row to find each one. Fields are split at the delimiter (no quoting: numbers need none). Defects (docs/robot-import.md):

    wrong field count, non-numeric or non-finite value  -> row dropped (reported)
    unterminated last line that does not parse          -> dropped as truncated (reported)
    a value of absurd magnitude, a row of zeros         -> row dropped (reported)
    rows outside the longest consistent stretch of time -> dropped (reported; ``consistent_rows``)
    time equal to the previous kept row                 -> row dropped (reported)
    time going back a little                            -> refused, or dropped with drop_backward
"""

from __future__ import annotations

import collections
import dataclasses
import re

import numpy as np

from fricli.core import logs
from fricli.core.errors import LogError
from fricli.core.timewindow import seconds_text
from fricli.robot.mapping import Mapping

KINDS = {
    "field_count": "wrong number of fields",
    "malformed": "arrays of another length than its joint names",
    "missing_joints": "joints missing",
    "non_numeric": "non-numeric or non-finite value",
    "truncated": "truncated last line",
    "implausible": "a value of implausible magnitude",
    "zero_row": "all values zero",
    "spike": "a value far from its neighbours' (a spike of one or two samples)",
    "time_outside": "time not continuing the recording (before or after its longest consistent stretch)",
    "time_jump": "time far from its neighbours'",
    "duplicate_time": "same time as the previous row",
    "backward_time": "time going back",
    "unmatched": "no matching row in another of the recording's files",
}
MIN_ROWS = 3                # fewer usable rows are no recording: velocity needs three samples
STEP_FACTOR = 100.0        # a time step beyond this many median steps breaks the recording
MAGNITUDE_FACTOR = 1e4     # |value| beyond this many times its column's median |value| (at least 1) is garbage
MAGNITUDE_LIMIT = logs.MAGNITUDE_LIMIT   # ... and so is any |value| beyond the log contract's
LINK_WINDOW = 64           # stretches of consistent time looked back over when chaining them
SPIKE_FACTOR = 10.0        # a value this many times its column's 99th percentile |value| (at least 1) ...
SPIKE_SPAN = 2             # ... from the median of the rows this many before and after it is a spike


@dataclasses.dataclass
class Defect:
    count: int
    first_line: int        # 1-based line number in the file (message number in a bag)
    ranges: list | None = None   # [[first, last], ...] of the dropped lines, when known
    files: dict | None = None    # a recording in several files: {file name: Defect} (line numbers are each file's)
    example: str | None = None   # what is wrong with the first one, when it helps to see it


@dataclasses.dataclass
class Recording:
    """Columns named by the mapping, as float64 arrays of shape (n,) in the file's units,
    keyed by the mapping's column reference (``Column.key``; a time kept as a sample rate under
    None, in s); ``lines`` are the rows' 1-based line numbers."""

    values: dict[int | str, np.ndarray]
    lines: np.ndarray
    defects: dict[str, Defect]
    n_fields: int
    unterminated: int | None = None   # line number of a last line without line end, kept as complete
    rows: np.ndarray | None = None    # each row's data line: 0 for the first, blank lines not counted
    blank_lines: int = 0              # blank lines between the first and the last row (no sample)


def _refs(mapping: Mapping) -> list[int | str]:
    refs = [mapping.time.ref] if mapping.time.ref is not None else []
    refs += [c.ref for jm in mapping.joints for c in jm.columns.values()]
    return list(dict.fromkeys(refs))


def _signal_columns(mapping: Mapping) -> list:
    """The mapped columns other than time, each once."""
    seen = {}
    for jm in mapping.joints:
        for c in jm.columns.values():
            if c.ref != mapping.time.ref:
                seen.setdefault(c.ref, c)
    return list(seen.values())


def ranges(numbers: np.ndarray) -> list[list[int]]:
    """Sorted line numbers as [[first, last], ...] runs of consecutive numbers."""
    if len(numbers) == 0:
        return []
    cut = np.flatnonzero(np.diff(numbers) != 1) + 1
    firsts, lasts = numbers[np.r_[0, cut]], numbers[np.r_[cut - 1, len(numbers) - 1]]
    return [[int(a), int(b)] for a, b in zip(firsts, lasts)]


def _chain(t: np.ndarray, limit: float, places: np.ndarray | None = None) -> np.ndarray:
    """Mask of the longest chain of stretches of ``t`` (shape (m,)) in which time increases by at
    most ``limit`` a step: a stretch follows another when its first time after the other's end is
    at most ``limit`` per row skipped (+1) later; its rows at or before that end are left out.
    ``places`` (m,): each row's place in the file (its line number), so that rows dropped before
    (garbage, malformed lines) count as skipped; default: its index."""
    places = np.arange(len(t)) if places is None else np.asarray(places)
    ok = (np.diff(t) > 0) & (np.diff(t) <= limit)
    cut = np.flatnonzero(~ok) + 1
    starts, ends = np.r_[0, cut], np.r_[cut, len(t)] - 1
    best = ends - starts + 1
    head, prev = starts.copy(), np.full(len(starts), -1)
    for j in range(1, len(starts)):
        part = t[starts[j]:ends[j] + 1]
        for i in range(max(0, j - LINK_WINDOW), j):
            r = starts[j] + int(np.searchsorted(part, t[ends[i]], side="right"))
            if r > ends[j] or t[r] - t[ends[i]] > limit * (places[r] - places[ends[i]]):
                continue
            if best[i] + ends[j] - r + 1 > best[j]:
                best[j], head[j], prev[j] = best[i] + ends[j] - r + 1, r, i
    keep = np.zeros(len(t), dtype=bool)
    j = int(np.argmax(best))
    while j >= 0:
        keep[head[j]:ends[j] + 1] = True
        j = prev[j]
    return keep


def spikes(values: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Rows (n,) bool of the ``usable`` rows of ``values`` (n, columns) where a value departs from
    the median of the SPIKE_SPAN usable rows before and after it by more than SPIKE_FACTOR times
    its column's 99th percentile magnitude (at least 1 in the canonical unit): a spike of one
    or two samples, which no joint's position, velocity, current or torque makes (it cannot leave
    and come back by ten times its largest values within two samples). A glitch of a velocity
    (500 rad/s in a joint moving at 1) would otherwise become the log's top speed, and every row
    would be at rest."""
    out = np.zeros(len(values), dtype=bool)
    rows = np.flatnonzero(usable)
    if len(rows) <= 2 * SPIKE_SPAN:
        return out
    x = values[rows]
    sample = x[::max(1, len(x) // 20_000)]          # the percentile of 20,000 rows at most
    scale = np.maximum(np.percentile(np.abs(sample), 99.0, axis=0), 1.0)
    # a departure beyond SPIKE_FACTOR * scale needs a value beyond half of it in the window:
    # the medians are taken only there (none on a clean log)
    big = np.flatnonzero((np.abs(x) > 0.5 * SPIKE_FACTOR * scale).any(axis=1))
    near = np.unique(np.clip(big[:, None] + np.arange(-SPIKE_SPAN, SPIKE_SPAN + 1), 0, len(x) - 1))
    if len(near):
        window = np.clip(near[:, None] + np.arange(-SPIKE_SPAN, SPIKE_SPAN + 1), 0, len(x) - 1)
        local = np.median(x[window], axis=1)
        out[rows[near]] = (np.abs(x[near] - local) > SPIKE_FACTOR * scale).any(axis=1)
    return out


def consistent_rows(t: np.ndarray, signals: list[np.ndarray], numbers: np.ndarray, *, name: str,
                    drop_backward: bool = False, unit: str = "line", shown_from: float = 0.0,
                    places: np.ndarray | None = None) -> tuple[np.ndarray, dict[str, Defect]]:
    """Which rows to keep: not of implausible magnitude, not all zero, no spike (``spikes``), and in
    the longest chain of consistent time (``_chain``: strictly increasing, steps within STEP_FACTOR
    median steps).
    ``t`` [s] and each of ``signals`` (canonical units) have shape (n,); ``numbers`` are the rows'
    line (or message) numbers; ``places`` (n,) the rows' places among the file's rows (default:
    ``numbers``), so that the rows dropped before (malformed lines) count as skipped in the chain of
    stretches. Returns the mask of shape (n,) and the defects found; LogError when
    time goes back within STEP_FACTOR median steps inside the recording and not ``drop_backward``
    (its message gives times from ``shown_from``)."""
    n = len(t)
    garbage = {kind: np.zeros(n, dtype=bool) for kind in ("implausible", "zero_row", "spike")}
    if signals:
        stacked = np.column_stack(signals)
        values = np.abs(stacked)
        bound = np.minimum(MAGNITUDE_FACTOR * np.maximum(1.0, np.median(values, axis=0)), MAGNITUDE_LIMIT)
        garbage["implausible"] = (values > bound).any(axis=1)
        garbage["zero_row"] = (values == 0).all(axis=1) & ~garbage["implausible"]
        garbage["spike"] = spikes(stacked, ~(garbage["implausible"] | garbage["zero_row"]))
    rest = np.flatnonzero(~np.logical_or.reduce(list(garbage.values())))
    kinds = np.full(n, "", dtype=object)
    for kind, mask in garbage.items():
        kinds[mask] = kind
    same = np.zeros(len(rest), dtype=bool)                 # a sample written twice: the first is kept
    same[1:] = t[rest][1:] == t[rest][:-1]
    kinds[rest[same]] = "duplicate_time"
    rest = rest[~same]
    steps = np.diff(t[rest])
    if len(rest) > 1 and not (steps > 0).any():
        raise LogError(f"{name}: time never increases from one {unit} to the next")
    if len(rest) > 1:
        limit = STEP_FACTOR * float(np.median(steps[steps > 0]))
        chained = _chain(t[rest], limit, (numbers if places is None else places)[rest])
        kept, dropped = rest[chained], rest[~chained]
        at = np.searchsorted(kept, dropped) - 1            # the kept row before each dropped one
        before = np.where(at >= 0, t[kept[np.maximum(at, 0)]], np.nan)
        inside = (at >= 0) & (at < len(kept) - 1)
        kinds[dropped] = np.select(
            [t[dropped] == before, ~inside, (t[dropped] < before) & (before - t[dropped] <= limit)],
            ["duplicate_time", "time_outside", "backward_time"], "time_jump")
    defects = {}
    for kind in KINDS:
        where = np.flatnonzero(kinds == kind)
        if len(where):
            defects[kind] = Defect(len(where), int(numbers[where[0]]), ranges(numbers[where]))
    back = defects.get("backward_time")
    if back and not drop_backward:
        at = int(np.flatnonzero(kinds == "backward_time")[0])
        latest = t[:at][kinds[:at] == ""].max()
        raise LogError(f"{name}: time goes back at {unit} {numbers[at]} (t = {seconds_text(t[at] - shown_from)} after "
                       f"{seconds_text(latest - shown_from)}; "
                       f"{back.count} {unit}{'s' if back.count != 1 else ''} before the latest time): use "
                       "--drop-backward to drop them")
    return kinds == "", defects


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


def _filled(data: bytes, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Whether each line holds more than spaces, tabs and carriage returns (bool, as ``starts``):
    vectorised, with a closer look only at the lines that start with one of those."""
    filled = ends > starts
    first = np.frombuffer(data, dtype=np.uint8)[np.minimum(starts, max(len(data) - 1, 0))] if len(data) else starts
    for i in np.flatnonzero(filled & np.isin(first, (9, 13, 32))):
        filled[i] = bool(data[starts[i]:ends[i]].strip())
    return filled


def _fields(line: bytes, delimiter: str) -> list[bytes]:
    """Fields of one line: plain splitting (no quoting; numbers need none)."""
    return line.split(delimiter.encode())


_DELIMITERS = {",": ",", ";": ";", "\t": "\\t", "|": "|", " ": " "}   # a space last: other marks win


def _delimiter_hint(sample: bytes, delimiter: str, name: str) -> None:
    """LogError naming the delimiter the lines hold when they hold no ``delimiter`` but another."""
    for mark, spelled in _DELIMITERS.items():
        if mark != delimiter and mark.encode() in sample:
            raise LogError(f"{name}: rows have 1 field when split at {delimiter!r}, and they hold {mark!r}: "
                           f'set delimiter = "{spelled}" in the mapping')


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
                shown = ", ".join(repr(h) for h in header[:12]) + (", ..." if len(header) > 12 else "")
                raise LogError(f"{name}: no column {ref!r} in the header line (it has {shown})")
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
            pa.BufferReader(body),
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


# a field that reads as a number (also import --template's rule)
NUMBER = r"^[-+]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][-+]?[0-9]+)?$"
# a field in double quotes (as writers that quote every field write numbers): read without them
QUOTED = r'^"(.*)"$'


def _not_a_number(text: str, column: str) -> str:
    """The first non-number of a column, and what it looks like when that is telling."""
    hint = ""
    if re.fullmatch(r"[-+]?[0-9]*,[0-9]+", text):
        hint = ': a decimal comma (set decimal = "," in the mapping)'
    elif re.search(r"[0-9]-[0-9]", text) and ":" in text:
        hint = ": a date and time (map a time in seconds, or give the sample rate: docs/robot-import.md)"
    return f"{text[:40]!r} in column {column}{hint}"


def _careful(data, starts, ends, start, stop, n_fields, wanted, delimiter, defect, label=str):
    """Lines ``start:stop``, reporting the wrong field counts and non-numbers; vectorised (numpy
    for the field counts, pyarrow for the numbers), so a few bad rows cost little more."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    starts, ends = starts[start:stop], ends[start:stop]
    numbers = np.arange(start, stop) + 1
    filled = _filled(data, starts, ends)
    starts, ends, numbers = starts[filled], ends[filled], numbers[filled]
    marks = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == ord(delimiter))
    fields = np.searchsorted(marks, ends) - np.searchsorted(marks, starts) + 1
    wrong = fields != n_fields
    if wrong.any():
        first = int(np.flatnonzero(wrong)[0])
        example = f"{fields[first]} fields, {n_fields} expected"
        if data[ends[first] - 1:ends[first]] == delimiter.encode():
            example += " (a delimiter ends the line)"
        defect("field_count", int(numbers[first]), int(wrong.sum()), example)
        starts, ends, numbers = starts[~wrong], ends[~wrong], numbers[~wrong]
    if len(numbers) == 0:
        return {c: np.empty(0) for c in wanted}, numbers
    body = b"\n".join([data[a:b] for a, b in zip(starts.tolist(), ends.tolist())]) + b"\n"
    names = [f"c{i}" for i in range(n_fields)]
    table = pcsv.read_csv(
        pa.BufferReader(body), read_options=pcsv.ReadOptions(column_names=names, use_threads=False),
        parse_options=pcsv.ParseOptions(delimiter=delimiter, quote_char=False, ignore_empty_lines=False),
        convert_options=pcsv.ConvertOptions(column_types={names[i]: pa.string() for i in wanted},
                                            include_columns=[names[i] for i in wanted]))
    if table.num_rows != len(numbers):  # not expected: every line is one row here
        raise LogError("the recording's lines could not be told apart")
    texts = {i: pc.replace_substring_regex(pc.utf8_trim_whitespace(table.column(names[i])), QUOTED, r"\1")
             for i in wanted}
    ok = np.ones(len(numbers), dtype=bool)
    for text in texts.values():
        ok &= np.asarray(pc.match_substring_regex(text, NUMBER).to_numpy(zero_copy_only=False), dtype=bool)
    if not ok.all():
        row = int(np.flatnonzero(~ok)[0])
        bad = next(i for i, text in texts.items() if not re.match(NUMBER, text[row].as_py() or ""))
        defect("non_numeric", int(numbers[row]), int((~ok).sum()), _not_a_number(texts[bad][row].as_py() or "", label(bad)))
    keep = pa.array(ok)
    cols = {i: pc.cast(pc.filter(text, keep), pa.float64()).to_numpy() for i, text in texts.items()}
    return cols, numbers[ok]


def _names(text: bytes, delimiter: str) -> bool:
    """Whether every field of a line is a name (text with a letter, no number): a header line."""
    fields = [f.strip().strip(b'"').decode("ascii", "replace") for f in _fields(text, delimiter)]
    return all(f and re.search("[A-Za-z]", f) and not re.match(NUMBER, f) for f in fields)


def _parse_row(fields: list[bytes], n_fields: int, wanted: list[int]) -> tuple[str | None, list[float]]:
    """One line (the unterminated last one) checked like ``_careful`` checks the others."""
    if len(fields) != n_fields:
        return "field_count", []
    texts = [re.sub(QUOTED, r"\1", fields[i].strip().decode("ascii", "replace")) for i in wanted]
    if not all(re.match(NUMBER, text) for text in texts):
        return "non_numeric", []
    return None, [float(text) for text in texts]


_ASCII = bytes(range(128)) + b"?" * 128
_ASCII_COMMA = _ASCII.replace(b",", b".")     # a decimal comma read as a decimal point


def listing(defects: dict[str, Defect], unit: str = "line") -> str:
    """'3 with all values zero (first at line 1); ...': what was dropped, for a refusal's message."""
    return "; ".join(f"{d.count} with {KINDS[k]} (first at {unit} {d.first_line}"
                     f"{': ' + d.example if d.example else ''})" for k, d in defects.items())


_BOM = "\ufeff".encode()


def _header_line(line, comments: list[int], first: int, delimiter: str) -> tuple[bytes, int]:
    """(the header line's text, the index of the first line after it). The header is the first
    line that is not a comment, or the last comment line without its '#' when it names as many
    fields as the line after it, which holds numbers (``numpy.savetxt(header=...)`` writes
    '# t,q,tau' above the rows)."""
    def number(text: bytes) -> bool:
        return bool(re.match(NUMBER, text.strip().decode("ascii", "replace")))

    if comments:
        names, row = _fields(line(comments[-1]).lstrip()[1:].strip(), delimiter), \
            _fields(line(first), delimiter)
        if 1 < len(names) == len(row) and not number(names[0]) and number(row[0]):
            return line(comments[-1]).lstrip()[1:], first
    return line(first), first + 1


def _trailing_delimiter(header: list[str], sample: list[bytes], delimiter: str) -> list[str]:
    """The header's names, matched to rows whose lines end with a delimiter and the header's not
    (an empty name added), or the other way round (its empty last name left out): an export's
    line-end artefact, not a column. ``sample``: the lines after the header."""
    counts = collections.Counter(len(_fields(ln, delimiter)) for ln in sample if ln.strip())
    if not counts:
        return header
    common = counts.most_common(1)[0][0]
    if common == len(header) - 1 and header[-1] == "":
        return header[:-1]
    ends = [ln.rstrip().endswith(delimiter.encode()) for ln in sample if ln.strip()]
    if common == len(header) + 1 and sum(ends) > len(ends) / 2:
        return header + [""]
    return header


def one_space(data: bytes) -> bytes:
    """``data`` with each run of spaces and tabs as one space and none at a line's start or end:
    columns aligned with spaces (as MATLAB's ``save -ascii`` writes them) split at a space."""
    return re.sub(rb"(?m)^ | (?=\r?$)", b"", re.sub(rb"[ \t]+", b" ", data))


def read_recording(data: bytes, mapping: Mapping, name: str, *, drop_backward: bool = False) -> Recording:
    """Parse ``data`` (the file's bytes) with ``mapping``. LogError (exit 3) when nothing is
    usable, a named column is missing, or time goes back without ``drop_backward``."""
    if data[:2] == b"\x1f\x8b":
        raise LogError(f"{name}: a gzip file, not a text recording: decompress it first (gunzip)")
    if data[:4] == b"PAR1":
        raise LogError(f"{name}: a Parquet file, not a text recording: fricli's commands read Parquet logs "
                       "directly (docs/log-format.md)")
    if data[:4] == b"PK\x03\x04":
        raise LogError(f"{name}: a zip archive (a spreadsheet workbook?), not a text recording: "
                       "extract it, or save the sheet as CSV")
    if data[:2] in (b"\xff\xfe", b"\xfe\xff"):   # "Unicode text" as spreadsheets on Windows save it
        try:
            data = data.decode("utf-16").encode("utf-8")
        except UnicodeDecodeError:
            raise LogError(f"{name}: starts like UTF-16 text but is not: save it as UTF-8") from None
    data = data.removeprefix(_BOM)   # a UTF-8 byte order mark, as spreadsheets save CSV
    if b"\x00" in data[:65536]:
        raise LogError(f"{name}: a binary file (it holds NUL bytes), not a text recording")
    if data.count(b"\r") != data.count(b"\r\n"):
        raise LogError(f"{name}: holds carriage returns that are not part of a CRLF line end (old Mac line "
                       "ends?): convert the file to LF or CRLF line ends")
    if mapping.delimiter == " ":
        data = one_space(data)
    starts, ends, terminated = _line_bounds(data)
    line = lambda i: data[starts[i]:ends[i]]  # noqa: E731
    n_lines = len(starts)
    filled = _filled(data, starts, ends)   # blank lines hold nothing: no row, no sample time
    non_blank = (int(i) for i in np.flatnonzero(filled))
    comments = []   # leading lines starting with '#': a recorder's preamble, skipped like empty lines
    while (first := next(non_blank, None)) is not None and line(first).lstrip().startswith(b"#"):
        comments.append(first)
    if first is None:
        raise LogError(f"{name}: the recording is empty" + (" (it holds comment lines only)" if comments else ""))
    header = None
    start = first
    if mapping.header:
        top, start = _header_line(line, comments, first, mapping.delimiter)
        header = [f.strip().decode("utf-8", "replace") for f in _fields(top, mapping.delimiter)]
        header = [re.sub(QUOTED, r"\1", h) for h in header]   # "name", as R writes it
        header = _trailing_delimiter(header, [line(i) for i in range(start, min(start + 200, n_lines))],
                                     mapping.delimiter)
        n_fields = len(header)
    else:
        sample = (line(i) for i in range(start, min(start + 200, n_lines)))
        counts = collections.Counter(len(_fields(ln, mapping.delimiter)) for ln in sample if ln.strip())
        n_fields = counts.most_common(1)[0][0]
    if n_fields == 1:
        _delimiter_hint(line(int(first)), mapping.delimiter, name)
    index = _indices(_refs(mapping), header, n_fields, name)
    wanted = sorted(set(index.values()))
    # numbers are ASCII: any other byte (a text column in another encoding, a damaged line) becomes
    # "?", so such a field is not a number and nothing reads it as text; offsets do not change
    data = data.translate(_ASCII_COMMA if mapping.decimal == "," else _ASCII)

    defects: dict[str, Defect] = {}

    def defect(kind: str, line_number: int, count: int = 1, example: str | None = None) -> None:
        if kind in defects:
            defects[kind].count += count
        else:
            defects[kind] = Defect(count, line_number, example=example)

    # an unterminated last line is parsed on its own: a truncated one is a defect of its own kind
    n_body = n_lines - 1 if not terminated and n_lines > start else n_lines
    numbers = np.flatnonzero(filled[start:n_body]) + start + 1   # 1-based, non-blank
    fast = None
    if len(numbers):
        body_end = starts[n_body] if n_body < n_lines else len(data)
        fast = _fast(data[starts[start]:body_end], n_fields, index, mapping.delimiter)
    if fast is not None and fast[1] == len(numbers):
        cols, _ = fast
    else:  # slow path: find every bad row
        cols, numbers = _careful(data, starts, ends, start, n_body, n_fields, wanted, mapping.delimiter, defect,
                                 label=lambda i: repr(header[i]) if header else str(i + 1))
        names = defects.get("non_numeric")
        if names is not None and names.first_line == first + 1 and not mapping.header and _names(line(first), mapping.delimiter):
            names.example += ": the first line names the columns (set header = true in the mapping)"
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
        raise LogError(f"{name}: no usable rows" + (f" ({listing(defects)})" if defects else ""))

    signals = [c.values(cols[index[c.ref]]) * c.factor for c in _signal_columns(mapping)]
    count = np.cumsum(filled)   # non-blank lines up to each line, itself included
    rows = (count - 1 - (count[start] - filled[start]))[numbers - 1]   # data lines before each, from ``start`` on
    if mapping.time.ref is None:   # a sample rate: the k-th data line after the first is at k / rate
        index[None] = -1
        cols[-1] = rows / mapping.time.rate
    keep, found = consistent_rows(mapping.time.values(cols[index[mapping.time.ref]]) * mapping.time.factor, signals,
                                  numbers, name=name, drop_backward=drop_backward, places=rows)
    for kind, d in found.items():
        defects[kind] = d
    if keep.sum() < MIN_ROWS:
        count = int(keep.sum())
        usable = f"only {count} usable row{'s' if count > 1 else ''}" if count else "no usable rows"
        raise LogError(f"{name}: {usable}" + (f" ({listing(defects)})" if defects else ""))
    if not keep.all():
        cols = {c: v[keep] for c, v in cols.items()}
        numbers, rows = numbers[keep], rows[keep]
    defects = dict(sorted(defects.items(), key=lambda kv: list(KINDS).index(kv[0])))
    return Recording(values={ref: cols[i] for ref, i in index.items()}, lines=numbers, defects=defects,
                     n_fields=n_fields, unterminated=unterminated if unterminated in numbers else None, rows=rows,
                     blank_lines=int(np.count_nonzero(~filled[numbers[0] - 1:numbers[-1]])))
