"""The one way a log becomes models: this log, these options, these joints (or coupled groups) ->
one model per joint or group, each made by ``fricli.fitting.runs`` (which holds the output's
lock and skips an output that is up to date).

``fit_log`` reads the log (or takes it read), checks it once (``runs.check_table``), chooses the
joints by the joint rule (``fricli.core.joints``, ``fricli.core.modelset.plan``), groups the
joints that share motors when the options ask for ``coupling``, pairs each joint with its input
model (adapt, diagnose) and runs each unit. It never prints and never exits: what it made comes
back as ``Outcome``s (also given to ``done`` as each unit ends), what it warns of goes to
``warn``. The commands identify, train-base, adapt and diagnose --fix, the fleet and the demo
all make their models here, so the same log and options give the same bytes.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable

from fricli.core import jobs, joints, logs, modelset, timewindow
from fricli.core.errors import LogError
from fricli.fitting import runs


@dataclasses.dataclass
class Outcome:
    """One unit of a run: the model ``made`` (``runs.Made``), or None when ``output`` was up to
    date and left untouched. ``label``: the joint (None for a log without a joint column), or
    the joints of a coupled group as "a, b" (``group`` true); ``digest``: the log's sha256;
    ``base``: the input model file (adapt, diagnose)."""

    label: object
    output: str
    digest: str
    made: runs.Made | None
    group: bool = False
    base: str | None = None

    @property
    def unchanged(self) -> bool:
        return self.made is None


@dataclasses.dataclass
class Run:
    """The outcomes of ``fit_log`` in the order of the units, and the folder the models went
    into (None: one model file at the output)."""

    outcomes: list
    folder: str | None

    @property
    def unchanged(self) -> bool:
        """True when no output was written: every one was up to date."""
        return not any(o.made is not None for o in self.outcomes)


@dataclasses.dataclass
class _Unit:
    label: object
    joint: object                 # the joint, or the first joint of a coupled group
    output: str
    base: str | None = None
    group: object = None          # a coupled group's transmission (``Transmission.sub``)


def log_name(log: str) -> str:
    return "stdin" if log == "-" else log


def read_log(log: str, window: timewindow.Window | None = None, warn: Callable | None = None) -> tuple:
    """(table, sha256) of ``log`` (- for stdin) with the rows of ``window``; the sha256 is the
    whole file's (the window is recorded with the options)."""
    table, digest = logs.read_table(log)
    return timewindow.slice_table(table, window, log_name(log), warn=warn), digest


def _source(inputs) -> joints.Source | None:
    if inputs is None or isinstance(inputs, joints.Source):
        return inputs
    return modelset.source(inputs)


def _plan(pipeline: str, table, name: str, output: str, opts: dict, source) -> tuple[list, str | None]:
    """The units of a run and its output folder (None: one file at ``output``)."""
    if opts.get("coupling") and pipeline in runs.GROUP_FIT:
        return _plan_coupled(table, name, output, opts)
    pairs, folder = modelset.plan(logs.joints_of(table, name), opts.get("joint"), output, name, source)
    return [_Unit(j, j, modelset.path_for(folder, j) if folder else output, pairs[j]) for j in pairs], folder


def _plan_coupled(table, name: str, output: str, opts: dict) -> tuple[list, str | None]:
    """With --coupling: a joint of a coupled group of the log's transmission brings its whole
    group into one unit (DIR/joints_<a>_<b>.npz); the other joints are units of their own."""
    from fricli.core import transmission

    try:
        tr = transmission.of_schema(table.schema.metadata)
    except ValueError as exc:
        raise LogError(f"{name}: {exc}") from None
    if tr is None:
        raise LogError(f"{name}: --coupling needs the log's transmission (written by fricli import from a mapping "
                       "with a transmission, docs/drives.md); the log records none")
    log_joints = logs.joints_of(table, name)
    groups = [tr.sub(g) for g in tr.coupled_groups()]
    found, seen = [], set()
    for j in joints.select(log_joints, opts.get("joint"), name):
        group = next((g for g in groups if any(joints.same(j, x) for x in g.joints)), None)
        key = tuple(map(str, group.joints)) if group else (str(j),)
        if key not in seen:
            seen.add(key)
            found.append((j, group))
    folder = modelset.output_folder(output, [j for j, _ in found], log_joints, name)   # a group alone: one file
    units = []
    for j, group in found:
        if group is None:
            units.append(_Unit(j, j, modelset.path_for(folder, j) if folder else output))
            continue
        missing = [x for x in group.joints if not any(joints.same(x, y) for y in log_joints)]
        if missing:
            raise LogError(f"{name}: joint {j} shares motors with joints {joints.listed(missing)}, which the log "
                           "does not hold: the coupled group needs every joint's rows")
        out = os.path.join(folder, modelset.group_file_name(group.joints)) if folder else output
        units.append(_Unit(", ".join(map(str, group.joints)), j, out, group=group))
    return units, folder


def fit_log(pipeline: str, log: str, output: str, opts: dict, *, inputs=None, read: tuple | None = None,
            window: timewindow.Window | None = None, if_changed: bool = False, refit: bool = False,
            warn: Callable | None = None, progress: Callable | None = None,
            done: Callable | None = None) -> Run:
    """Make ``pipeline``'s model (identify, train-base, adapt, diagnose) of every joint of ``log``
    the options cover: one model file at ``output``, or one per joint (or coupled group) in the
    folder ``output`` (``fricli.core.modelset``).

    ``opts``: the pipeline's options (``runs.options``; ``joint`` selects a joint, ``coupling``
    groups the joints that share motors, ``no_gravity``/``no_dynamics`` declare columns zero);
    ``inputs``: the input models of adapt and diagnose (a file, a model folder or a
    ``joints.Source``), each joint paired with its own; ``read``: (table, sha256) of ``log``
    when already read (``window`` already applied), else ``log`` (- for stdin) is read and cut
    to ``window`` (``fricli.core.timewindow``), which is recorded with the options;
    ``if_changed``: leave an output made from the same log bytes by the same job untouched;
    ``refit``: diagnose only, each input model refitted on the log before it is diagnosed (a log
    whose robot-model terms were recomputed, ``diagnose --fix --calibrate``); ``warn(line)``:
    the warnings of reading; ``progress(data)`` (``progress(data, motor)`` for a coupled group's
    motor): a trainer progress callback with ``close()``; ``done(outcome)``: told of each unit
    as it ends.

    A unit's FricliError does not stop the others (``modelset.each_joint``: PartialFailure after
    the rest). LockedError when another job holds an output."""
    if refit and pipeline != "diagnose":
        raise ValueError("refit applies to diagnose")
    name = log_name(log)
    opts = runs.options(pipeline, opts)
    table, digest = read if read is not None else read_log(log, window, warn)
    runs.check_table(table, name, opts, pipeline)
    units, folder = _plan(pipeline, table, name, output, opts, _source(inputs))
    recorded = window.to_json() if window else None
    outcomes = []
    by_label = {u.label: u for u in units}

    def work(label):
        unit = by_label[label]
        if unit.group is not None:
            made = _run_group(pipeline, unit, table, digest, name, opts, if_changed, recorded, warn, progress)
        elif refit:
            made = _run_refit(unit, table, digest, name, opts, if_changed, recorded, warn)
        else:
            data = runs.read(table, digest, name, opts, joint=unit.joint, warn=warn, base=unit.base, pipeline=pipeline)
            on_eval = progress(data) if progress else None
            try:
                made = runs.run(pipeline, data, unit.output, opts, base=unit.base, if_changed=if_changed,
                                on_eval=on_eval, window=recorded)
            finally:
                if on_eval is not None:
                    on_eval.close()
        outcome = Outcome(unit.label, unit.output, digest, made, unit.group is not None, unit.base)
        outcomes.append(outcome)
        if done is not None:
            done(outcome)

    modelset.each_joint([u.label for u in units], work)
    return Run(outcomes, folder)


def _run_group(pipeline, unit, table, digest, name, opts, if_changed, window, warn, progress):
    from fricli.models import coupled

    reading = {"kt": opts["kt"], "cutoff_hz": opts["cutoff"], "drop_invalid": opts["drop_invalid"], "warn": warn,
               "zero": runs.zero(opts)}
    _, datas = coupled.group_rows(table, list(unit.group.joints), name, sha256=digest, **reading)
    return runs.run_group(datas, unit.group, unit.output, opts, if_changed=if_changed, window=window,
                          pipeline=pipeline, progress=(lambda i: progress(datas[0], i)) if progress else None)


def _run_refit(unit, table, digest, name, opts, if_changed, window, warn):
    """diagnose --fix on a recomputed log: the input model refitted on it (``fix.refit``), then
    diagnosed and fixed, under the output's lock and ``if_changed`` as ``runs.run`` writes."""
    from fricli import models
    from fricli.fitting.diagnosis.fix import refit

    data = runs.read(table, digest, name, opts, joint=unit.joint, warn=warn, base=unit.base, refitted=True)
    job = runs.record("diagnose", opts, data, unit.base, window)
    with jobs.output_lock(unit.output):
        if if_changed and jobs.up_to_date(unit.output, digest, job):
            return None
        base, meta = models.load(unit.base)
        return runs.fix_model(refit(base, data), data, unit.output, opts, job, unit.base, meta,
                              refitted_on_calibrated_log=True)


def up_to_date(pipeline: str, log: str, output: str, opts: dict, *, read: tuple, inputs=None,
               window: timewindow.Window | None = None) -> Run | None:
    """The outcomes of a run that would find every output up to date (nothing touched), or None
    when one needs work: for a run whose preparation is costly (``diagnose --fix --calibrate``
    calibrates the robot model first). Advisory: ``fit_log`` checks again under each lock."""
    name = log_name(log)
    opts = runs.options(pipeline, opts)
    table, digest = read
    units, folder = _plan(pipeline, table, name, output, opts, _source(inputs))
    recorded = window.to_json() if window else None
    outcomes = []
    for unit in units:
        if unit.group is not None:
            return None
        job = runs.record(pipeline, opts, _Joint(unit.joint), unit.base, recorded)
        if not jobs.up_to_date(unit.output, digest, job):
            return None
        outcomes.append(Outcome(unit.label, unit.output, digest, None, False, unit.base))
    return Run(outcomes, folder)


@dataclasses.dataclass
class _Joint:
    """What a job record needs of a log: its joint (``runs.record``)."""

    joint: object
