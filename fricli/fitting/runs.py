"""One job: a model of one joint of one log written to one file, the one way the commands
(identify, train-base, adapt, diagnose --fix) and the fleet make a model.

``run`` holds the lock on the output (``fricli.core.jobs.output_lock``), skips the work when the
output was made from the same log bytes by the same job (``if_changed``, ``jobs.up_to_date``),
fits, and saves the model with its job record (``jobs.job_record``) in the provenance. The
record holds every option that shapes the model (``fricli.fitting.optionspec``; diagnose: the options
the command gives) and the joint the model is of, so a command and a fleet job on the same log
with the same options write the same bytes.

Fitting and saving are two steps: ``fit`` returns a ``Fitted`` (the model, its fit figures and
what the file records), ``save`` writes it (``file_parts``: the file's meta and arrays). The
estimators of ``fricli.estimators`` fit with ``fit`` and save the same bytes.
"""

from __future__ import annotations

import dataclasses
import os
import time
from typing import Callable

import numpy as np

from fricli import models
from fricli.core import jobs, logs, metrics
from fricli.fitting import optionspec
from fricli.models.base import FrictionModel

PIPELINES = ("identify", "train-base", "adapt", "diagnose")
INPUT_NAME = {"adapt": "base", "diagnose": "model"}   # how a job records its input model


@dataclasses.dataclass
class Made:
    """What a job wrote: ``summary`` is the fit figures saved as the model's ``fit``;
    ``base``/``base_meta`` the input model of adapt and diagnose; ``diagnosis`` diagnose's
    ``fricli.fitting.diagnosis.driver.Diagnosis``; ``seconds`` the fit and save time [s]."""

    pipeline: str
    output: str
    data: logs.Log
    model: object
    summary: dict
    seconds: float = 0.0
    base: str | None = None
    base_meta: dict | None = None
    diagnosis: object = None


def options(pipeline: str, given: dict) -> dict:
    """Every option of ``pipeline`` (``given`` over the defaults, checked: ``optionspec.check``);
    diagnose's options are taken as given."""
    if pipeline == "diagnose":
        return dict(given)
    out = optionspec.check(pipeline, given)
    if pipeline == "train-base":
        check_train_base(out)
    return out


def check_train_base(opts: dict) -> None:
    """OptionError for train-base options that do not go together."""
    from fricli.fitting import learning

    try:  # e.g. selmic needs one layer of more than 10 units (its jump units)
        learning.ARCHS[opts["arch"]](hidden_sizes=tuple(opts["hidden"] or learning.DEFAULT_HIDDEN[opts["arch"]]))
    except ValueError as exc:
        raise optionspec.OptionError(f"train-base option hidden: {exc}", "hidden") from None
    if opts["arch"] == "dissipative" and opts["velocity_input"] != "asinh":
        raise optionspec.OptionError("train-base option velocity_input: the dissipative network always sees "
                                     "asinh(|qd| / v0); use --arch mlp", "velocity_input")
    if opts["coupling"] and opts["arch"] != "dissipative":
        raise optionspec.OptionError("train-base option coupling: the motors' friction is learned by dissipative "
                                     "networks (--arch dissipative)", "coupling")


def zero(opts: dict) -> tuple[str, ...]:
    """The robot-model columns the options declare zero (--no-gravity, --no-dynamics)."""
    return tuple(column for flag, column in optionspec.ZERO_FLAGS.items() if opts.get(flag))


# identify holds about this many bytes per row of the joint it fits (5 M rows took 3.1 GB, 10 M
# rows 6.0 GB), and fits at most IDENTIFY_MAX_ROWS rows of one joint: within IDENTIFY_MEMORY.
IDENTIFY_BYTES_PER_ROW = 600
IDENTIFY_MEMORY = 2 << 30
IDENTIFY_MAX_ROWS = IDENTIFY_MEMORY // IDENTIFY_BYTES_PER_ROW


def check_table(table, name: str, opts: dict, pipeline: str | None = None) -> None:
    """LogError when the log lacks tau_g or tau_dyn and the options do not declare it zero
    (checked once, before any joint); DataError before ``identify`` on a joint with more rows
    than it fits within its memory limit (``IDENTIFY_MAX_ROWS``)."""
    logs.require_robot_model(table.schema, name, zero(opts))
    if pipeline == "identify":
        check_rows(table, name, IDENTIFY_MAX_ROWS)


def check_rows(table, name: str, limit: int) -> None:
    """DataError when one joint of ``table`` has more than ``limit`` rows (identify's memory
    grows with the rows of the joint it fits)."""
    from fricli.core.errors import DataError

    rows = table.num_rows
    if rows > limit and "joint" in table.column_names:
        import pyarrow.compute as pc

        counts = pc.value_counts(table.column("joint")).field("counts").to_numpy(zero_copy_only=False)
        rows = int(counts.max()) if counts.size else 0
    if rows > limit:
        raise DataError(f"{name}: {rows:,} rows of one joint; identify fits at most {limit:,} "
                        f"(about {limit * IDENTIFY_BYTES_PER_ROW / 2**30:.2g} GiB of memory at "
                        f"{IDENTIFY_BYTES_PER_ROW} bytes a row): identify on part of the log (--from, --until)")


def reads_acceleration(pipeline: str | None, base: FrictionModel | None = None) -> bool:
    """Whether the job ``pipeline`` (None: any reader) reads the log's acceleration: diagnose (its
    acceleration effect, the robot model's inertia), adapt over a ``base`` model that reads it;
    identify and train-base fit kinds that read none. A log without one is given none where it is
    not read: deriving it runs the zero-phase filter over the whole log (``logs.from_table``)."""
    if pipeline in ("identify", "train-base"):
        return False
    if pipeline == "adapt":
        return base is not None and models.reads_acceleration(base)
    return True


def read(table, digest: str, name: str, opts: dict, joint=None, warn=None, base: str | None = None,
         refitted: bool = False, pipeline: str | None = None) -> logs.Log:
    """The log of ``joint`` (default ``opts["joint"]``) read with the job's reading options, for
    the job ``pipeline`` (``reads_acceleration``; None: with everything a job may read); with
    ``base`` (the input model file of adapt and diagnose) also the other joints' velocities it
    reads (a coupled group's, ``coupled.add_partners``), and a warning when it was fitted on another
    robot model than the log's, unless the job refits it on this log (``refitted``)."""
    from fricli.models import coupled

    model, meta = models.load(base) if base is not None else (None, None)
    reading = dict(kt=opts.get("kt"), cutoff_hz=opts["cutoff"], drop_invalid=opts["drop_invalid"], zero=zero(opts))
    data = logs.from_table(table, name=name, sha256=digest, joint=opts.get("joint") if joint is None else joint,
                           warn=warn, qdd=reads_acceleration(pipeline, model), **reading)
    if base is not None:
        coupled.add_partners(coupled.view(model, data.joint), data, table, **reading)
        note = None if refitted else models.robot_model_note(meta, data, base)
        if note and warn:
            warn(note)
    return data


def record(pipeline: str, opts: dict, data: logs.Log, base: str | None = None, window: dict | None = None) -> dict:
    """The job record of a model of ``data``'s joint: the options with the joint fitted (as
    text; None for a log without a joint column), the time window (``Window.to_json``) when one
    is given, and the sha256 of the input model."""
    recorded = dict(opts, joint=None if data.joint is None else str(data.joint))
    if window:
        recorded["window"] = window
    inputs = {INPUT_NAME[pipeline]: base} if base else None
    return jobs.job_record(pipeline, recorded, inputs)


def run(pipeline: str, data: logs.Log, output: str, opts: dict, *, base: str | None = None,
        if_changed: bool = False, window: dict | None = None, on_eval: Callable | None = None) -> Made | None:
    """Fit ``pipeline`` on ``data`` and write the model to ``output`` ("-": stdout); None when
    ``if_changed`` and ``output`` is up to date (nothing touched). ``opts``: the pipeline's
    options (``options``); ``base``: the input model file of adapt and diagnose; ``on_eval``:
    the trainer's progress callback (train-base, adapt). LockedError when another job holds
    ``output``. The lock, ``fit`` and ``save``."""
    if pipeline not in PIPELINES:
        raise ValueError(f"unknown pipeline {pipeline!r}")
    opts = options(pipeline, opts)
    job = record(pipeline, opts, data, base, window)
    with jobs.output_lock(output):
        if if_changed and jobs.up_to_date(output, data.sha256, job):
            return None
        start = time.perf_counter()
        fitted = fit(pipeline, data, opts, base=load_base(base, data) if base is not None else None,
                     on_eval=on_eval)
        save(output, fitted, data, job)
        made = Made(pipeline, output, data, fitted.model, fitted.summary, base=base,
                    base_meta=fitted.base.meta if fitted.base else None, diagnosis=fitted.diagnosis)
        made.seconds = time.perf_counter() - start
    return made


def run_group(datas: list, transmission, output: str, opts: dict, *, if_changed: bool = False,
              window: dict | None = None, pipeline: str = "identify", progress: Callable | None = None) -> Made | None:
    """identify or train-base (``pipeline``) with --coupling for one coupled group: the joints of
    ``datas`` (their logs, rows at the same times, in the order of ``transmission``'s joints) into
    one model of kind coupled (``fricli.models.coupled``) at ``output``; None when up to date.
    identify fits the linear law per motor, train-base a network per motor
    (``fricli.fitting.learning.train_group``; ``progress(i)``: motor i's trainer progress callback).
    ``Made.data`` is the first joint's log, ``Made.summary`` the fit figures per joint."""
    from fricli.models import coupled

    if pipeline not in GROUP_FIT:
        raise ValueError(f"pipeline {pipeline!r} does not fit coupled groups")
    opts = options(pipeline, opts)
    recorded = dict(opts, joint=[str(j) for j in transmission.joints])
    if window:
        recorded["window"] = window
    job = jobs.job_record(pipeline, recorded)
    with jobs.output_lock(output):
        if if_changed and jobs.up_to_date(output, datas[0].sha256, job):
            return None
        start = time.perf_counter()
        model, fit = GROUP_FIT[pipeline](datas, transmission, opts, progress)
        coupled.save_group(output, model, datas[0], fit=fit, job=job)
    return Made(pipeline, output, datas[0], model, fit, seconds=time.perf_counter() - start)


def _identify_group(datas, transmission, opts, _progress):
    from fricli.models import coupled

    return coupled.fit_group(datas, transmission, stribeck=opts["motor_stribeck"])


def _train_base_group(datas, transmission, opts, progress):
    from fricli.fitting import learning

    return learning.train_group(datas, transmission, progress=progress, **_train_options(opts))


GROUP_FIT = {"identify": _identify_group, "train-base": _train_base_group}


def moving_errors(made: Made) -> dict:
    """MAE, RMSE, max [Nm or N] of the written model against the friction target over the rows
    in motion (``metrics.in_motion``): the one figure the fleet history keeps for every pipeline."""
    sig = made.data.signals
    moving = metrics.in_motion(sig["qd"])
    pred = made.model.predict(sig)[0]
    return metrics.errors(logs.friction_target(sig)[moving], np.asarray(pred)[moving])


@dataclasses.dataclass
class Base:
    """The input model of adapt and diagnose: ``model`` as it applies to the log's joint (a coupled
    group's member, ``coupled.view``), its file's ``meta`` and ``name`` (the file's base name, None
    for a model not read from a file); ``source`` names it in messages."""

    model: object
    meta: dict
    name: str | None
    source: str = "base"


@dataclasses.dataclass
class Fitted:
    """What one pipeline's fit made and what ``save`` needs: the model, its fit figures
    (``summary``, saved as the model's ``fit``), the rows it used, the seed, the training
    envelope (None: the log's over the model's inputs) and the base record of the provenance."""

    model: object
    summary: dict
    rows_used: int
    seed: int | None = None
    envelope: dict | None = None
    base_record: dict | None = None
    base: Base | None = None
    diagnosis: object = None


def load_base(path: str, data) -> Base:
    """The input model file ``path`` as it applies to ``data``'s joint, checked against the log."""
    from fricli.models import coupled

    model, meta = models.load(path)
    models.check_log(meta, data, path)
    return Base(coupled.view(model, data.joint), meta, os.path.basename(path), path)


def fit(pipeline: str, data: logs.Log, opts: dict, *, base: Base | None = None,
        on_eval: Callable | None = None) -> Fitted:
    """Fit ``pipeline`` on ``data`` with its options ``opts`` (``options``); ``base``: the
    input model of adapt and diagnose (``load_base``). Nothing is written (``save``)."""
    if pipeline not in PIPELINES:
        raise ValueError(f"unknown pipeline {pipeline!r}")
    if (base is None) != (pipeline not in INPUT_NAME):
        raise ValueError(f"{pipeline} {'needs' if base is None else 'takes no'} input model")
    return _FIT[pipeline](data, opts, base, on_eval)


def file_parts(fitted: Fitted, data: logs.Log, job: dict | None) -> tuple[dict, dict]:
    """(meta, arrays) of the model file of ``fitted`` (fitted on ``data``) with the job record ``job``."""
    extra = {"job": job} if job is not None else {}
    if fitted.base_record is not None:
        extra["base"] = fitted.base_record
    return models.parts_for_log(fitted.model, data, rows_used=fitted.rows_used, seed=fitted.seed,
                                fit=fitted.summary, envelope=fitted.envelope, **extra)


def save(output: str, fitted: Fitted, data: logs.Log, job: dict | None) -> dict:
    """Write the model file of ``fitted`` to ``output`` ("-": stdout); returns its meta."""
    from fricli.core import modelfile

    meta, arrays = file_parts(fitted, data, job)
    modelfile.write(output, meta, arrays)
    return meta


def _identify(data, opts, _base, _on_eval) -> Fitted:
    if opts["kind"] == "gms":
        from fricli.fitting import hysteresis

        model, fit_ = hysteresis.fit(data.signals, axis=data.axis)
        return Fitted(model, fit_, rows_used=len(data))
    if opts["kind"] != "lugre":
        from fricli.models import linear

        model, fit_ = linear.fit(data.signals, asymmetric=opts["kind"] == "linear-asymmetric", axis=data.axis)
        return Fitted(model, fit_, rows_used=fit_["moving"]["n"])
    from fricli.fitting.identify import LuGreIdentifier

    idf = LuGreIdentifier(hold=opts["hold"], travel=opts["travel"], refine=opts["refine"], samples=opts["samples"],
                          settle=opts["settle"]).fit(data.signals, units=data.units, axis=data.axis)
    return Fitted(idf.model_, idf.fit_, rows_used=len(data))


def _train_base(data, opts, _base, on_eval) -> Fitted:
    from fricli.fitting import learning

    model, summary = learning.train_base(data, on_eval=on_eval, memory=opts["memory"], **_train_options(opts))
    return Fitted(model, summary, rows_used=summary["train_rows"] + summary["val_rows"], seed=opts["seed"])


def _train_options(opts: dict) -> dict:
    """train-base's options as the keyword arguments of ``learning.train_base`` and ``train_group``."""
    return dict(arch=opts["arch"], hidden=opts["hidden"], steps=opts["steps"], schedule=opts["schedule"],
                patience=opts["patience"], lr=opts["lr"], batch_size=opts["batch_size"], seed=opts["seed"],
                val_fraction=opts["val_fraction"], ensemble=opts["ensemble"], balance=not opts["no_balance"],
                max_samples=opts["max_samples"], velocity_input=opts["velocity_input"],
                velocity_scale=opts["velocity_scale"], bristles=opts["bristles"],
                prior=not opts["no_prior"])


def _adapt(data, opts, base: Base, on_eval) -> Fitted:
    from fricli.fitting import learning

    model, summary = learning.adapt(
        base.model, data, hidden=opts["hidden"], epochs=opts["epochs"], batch_size=opts["batch_size"],
        lr=opts["lr"], seed=opts["seed"], val_fraction=opts["val_fraction"], max_seconds=opts["max_seconds"],
        min_speed=opts["min_speed"], on_eval=on_eval, base_envelope=models.envelope(base.meta, base.source))
    return Fitted(model, summary, rows_used=summary["rows_used"], seed=opts["seed"],
                  envelope=base.meta.get("envelope"),
                  base_record={"name": base.name, "kind": base.meta.get("kind"),
                               "provenance": base.meta.get("provenance", {})}, base=base)


def _diagnose(data, opts, base: Base, _on_eval) -> Fitted:
    """diagnose --fix: the base model augmented with the effects it misses on ``data``."""
    return fit_fix(base, data, opts)


def fit_fix(base: Base, data, opts: dict, **base_record) -> Fitted:
    """``base.model`` augmented with the effects it misses on ``data`` (diagnose --fix);
    ``base_record``: more about the base for the model's provenance."""
    from fricli.fitting.diagnosis import driver
    from fricli.fitting.diagnosis.fix import augment

    base_model, base_meta = base.model, base.meta
    result = driver.diagnose(base_model, data, folds=opts["folds"], min_gain=opts["min_gain"], alpha=opts["alpha"],
                             only=opts["only"], max_effects=opts["max_effects"],
                             accept_implausible=opts["accept_implausible"])
    fixed = augment(base_model, result, data, carry=not opts["no_carry"])
    summary = metrics.errors(logs.friction_target(data.signals), fixed.predict(data.signals)[0])
    summary.update(heldout_mae_before=result.mae_before, heldout_mae_after=result.mae_after, added=result.added,
                   carried=fixed.carried, refitted=fixed.refitted)
    # nothing added or refitted: the model is the base, known where the base was fitted (not a base
    # refitted here on a recomputed log: that log is where it is known)
    same = (not (result.added or fixed.carried or fixed.refitted) and not base_record.get("refitted_on_calibrated_log")
            and base_meta.get("envelope") is not None)
    return Fitted(fixed, summary, rows_used=len(data), envelope=base_meta["envelope"] if same else None,
                  base_record={"name": base.name, "kind": base_model.kind, **base_record}, base=base,
                  diagnosis=result)


def fix_model(base_model, data, output: str, opts: dict, job: dict, base: str, base_meta: dict,
              **base_record) -> Made:
    """``base_model`` augmented with the effects it misses on ``data``, saved to ``output`` with
    ``job``; ``base_record``: more about the base for the model's provenance."""
    fitted = fit_fix(Base(base_model, base_meta, os.path.basename(base), base), data, opts, **base_record)
    save(output, fitted, data, job)
    return Made("diagnose", output, data, fitted.model, fitted.summary, base=base, base_meta=base_meta,
                diagnosis=fitted.diagnosis)


_FIT = {"identify": _identify, "train-base": _train_base, "adapt": _adapt, "diagnose": _diagnose}
