"""A recording in several files (``files`` in the mapping): each read with its own columns, and
their rows paired row by row (the k-th data line of each file) or by equal time (``join = "time"``,
a time column in every file).

Every file's defects are found and reported as for one file (``fricli.robot.recording``); a row
dropped from one file is dropped from all, and a row that has no partner in another file (a
file longer than the others, a time missing in one) is reported as ``unmatched``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core.errors import LogError
from fricli.robot.mapping import Column, JointMap, Mapping
from fricli.robot.recording import Defect, Recording, ranges, read_recording

_ROW_INDEX = Column(ref=None, unit="s", factor=1.0, kind=None, rate=1.0)   # rows of a file without time


def _file_mapping(mapping: Mapping, f: int) -> Mapping:
    """The part of ``mapping`` that reads file ``f``: its columns, and the time."""
    time = mapping.time
    if time.ref is not None and mapping.join == "rows" and time.file != f:
        time = _ROW_INDEX
    elif time.ref is not None:
        time = dataclasses.replace(time, file=0)
    joints = [JointMap(jm.name, {s: dataclasses.replace(c, file=0) for s, c in jm.columns.items() if c.file == f})
              for jm in mapping.joints]
    return dataclasses.replace(mapping, time=time, joints=[jm for jm in joints if jm.columns], files=())


def _merge(defects: dict, found: dict, name: str) -> None:
    """Add file ``name``'s defects ``found`` to ``defects``: per kind the total, and each file's own."""
    for kind, d in found.items():
        files = {**(defects[kind].files if kind in defects else {}), name: d}
        defects[kind] = Defect(sum(f.count for f in files.values()), min(f.first_line for f in files.values()),
                               None, files)


def read_joined(datas: list[bytes], mapping: Mapping, names: list[str], *, drop_backward: bool = False) -> Recording:
    """The rows of the files ``datas`` (their bytes, in the order of ``mapping.files``) paired up;
    values keyed by ``Column.key``. LogError when a file is missing or nothing pairs up."""
    if len(datas) != len(mapping.files):
        raise LogError(f"the mapping names {len(mapping.files)} files ({', '.join(mapping.files)}), but "
                       f"{len(datas)} {'was' if len(datas) == 1 else 'were'} given")
    recs = [read_recording(data, _file_mapping(mapping, f), name, drop_backward=drop_backward)
            for f, (data, name) in enumerate(zip(datas, names))]
    if mapping.join == "rows":   # the k-th data line of each file (blank and comment lines are none)
        keys = [rec.rows for rec in recs]
    else:
        keys = [rec.values[mapping.time.ref] for rec in recs]
    common = keys[0]
    for k in keys[1:]:
        common = np.intersect1d(common, k)
    defects: dict[str, Defect] = {}
    for rec, name in zip(recs, names):
        _merge(defects, rec.defects, name)
    values: dict = {}
    lines = None
    ends = [int(k[-1]) for k in keys]
    for f, (rec, k) in enumerate(zip(recs, keys)):
        keep = np.isin(k, common)
        # row by row, a row dropped from another file for a defect of its own is reported there
        alone = ~keep if mapping.join == "time" else ~keep & (k > min(ends[:f] + ends[f + 1:]))
        if alone.any():
            gone = rec.lines[alone]
            _merge(defects, {"unmatched": Defect(len(gone), int(gone[0]), ranges(gone))}, names[f])
        for ref, v in rec.values.items():
            values[ref if f == 0 else (f, ref)] = v[keep]
        lines = rec.lines[keep] if lines is None else lines
    if mapping.time.ref is None or mapping.join == "time":
        values[mapping.time.key] = recs[0].values[mapping.time.ref][np.isin(keys[0], common)]
    if len(common) == 0:
        raise LogError(f"{', '.join(names)}: no row pairs up across the files")
    from fricli.robot.recording import KINDS
    defects = dict(sorted(defects.items(), key=lambda kv: list(KINDS).index(kv[0])))
    return Recording(values=values, lines=lines, defects=defects, n_fields=recs[0].n_fields,
                     unterminated=recs[0].unterminated if recs[0].unterminated in lines else None,
                     blank_lines=sum(rec.blank_lines for rec in recs) if mapping.join == "rows" else 0)
