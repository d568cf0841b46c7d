"""One fleet job: a pipeline (identify, train-base, adapt) on one (robot, joint, log).

Each pipeline records the same job (command and options, see ``fricli.jobs.job_record``) as
the command of the same name, so a model written by the fleet is up to date for
``fricli identify ... --if-changed`` with the same options, and the other way round.
"""

from __future__ import annotations

import os
import time

from fricli import errors, jobs, learning, logs, models
from fricli.fleet.manifest import Job


def defaults(pipeline: str) -> dict:
    """Every option of the command of the same name that shapes the model, at its default (read
    from the command itself, so the job records cannot drift apart)."""
    from fricli.cli.options import shaping_defaults

    return shaping_defaults(pipeline)


def options_of(job: Job) -> dict:
    """The job's options over the command's defaults; FricliError for an unknown option."""
    out = defaults(job.pipeline)
    for name, value in job.options:
        if name not in out or name == "joint":
            known = ", ".join(sorted(set(out) - {"joint"}))
            raise errors.FricliError(f"unknown {job.pipeline} option {name!r} (known: {known})")
        if isinstance(out[name], float) and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)  # TOML's 50 is the command's 50.0: the same job record
        out[name] = value
    out["joint"] = job.joint or None
    return out


def _figures(fit: dict) -> dict:
    return {k: fit.get(k) for k in ("mae", "rmse", "max")}


def _identify(data, opts: dict, job: dict, output: str) -> dict:
    from fricli.identify import LuGreIdentifier

    idf = LuGreIdentifier(hold=opts["hold"], travel=opts["travel"], refine=opts["refine"], samples=opts["samples"],
                          settle=opts["settle"])
    idf.fit(data.signals, units=data.units, axis=data.axis)
    models.save_for_log(output, idf.model_, data, rows_used=len(data), fit=idf.fit_, job=job)
    return {"kind": idf.model_.kind, "parameters": idf.model_.parameters(), "errors": _figures(idf.fit_),
            "model": idf.model_}


def _train_base(data, opts: dict, job: dict, output: str) -> dict:
    arch = opts["arch"]
    hidden = tuple(opts["hidden"]) if opts["hidden"] else None
    model, summary = learning.train_base(
        data, arch=arch, hidden=hidden, steps=opts["steps"], schedule=opts["schedule"], patience=opts["patience"],
        lr=opts["lr"], batch_size=opts["batch_size"],
        seed=opts["seed"], val_fraction=opts["val_fraction"], balance=not opts["no_balance"],
        max_samples=opts["max_samples"], velocity_input=opts["velocity_input"],
        velocity_scale=opts["velocity_scale"])
    models.save_for_log(output, model, data, rows_used=summary["train_rows"] + summary["val_rows"],
                        seed=opts["seed"], fit=summary, job=job)
    return {"kind": arch, "parameters": {}, "errors": _figures(summary.get("log", {})), "model": model}


def _adapt(data, opts: dict, job: dict, output: str, base_model, base_meta: dict, base: str) -> dict:
    keys = ("hidden", "epochs", "batch_size", "lr", "val_fraction", "max_seconds", "min_speed")
    model, summary = learning.adapt(base_model, data, **{k: opts[k] for k in keys}, seed=opts["seed"])
    models.save_for_log(output, model, data, rows_used=summary["rows_used"], seed=opts["seed"], fit=summary, job=job,
                        base={"path": base, "kind": base_meta.get("kind"),
                              "provenance": base_meta.get("provenance", {})})
    return {"kind": "residual", "parameters": {}, "errors": _figures(summary.get("moving", {})), "model": model}


def _diagnose(model, data) -> tuple[list, str]:
    from fricli.diagnosis import driver

    try:
        return list(driver.diagnose(model, data).added), ""
    except errors.FricliError as exc:
        return [], errors.one_line(f"diagnose: {exc}")


def run(job: Job, *, if_changed: bool = True) -> dict:
    """Run one job; never raises for a job's own failure.

    Returns {"status": ok | unchanged | failed, "reason": one line or "", "seconds",
    "kind", "parameters", "errors", "sha256", "effects"}. With ``job.diagnose`` the effects the
    new model misses are looked for (``fricli.diagnosis``); when that fails the job stays ok and
    the reason says why."""
    start = time.perf_counter()
    out = {"status": "failed", "reason": "", "kind": None, "parameters": {}, "errors": {}, "sha256": "",
           "effects": []}
    try:
        opts = options_of(job)
        table, digest = logs.read_table(job.log)
        out["sha256"] = digest
        inputs = {"base": job.base} if job.pipeline == "adapt" else None
        os.makedirs(os.path.dirname(job.model), exist_ok=True)
        record = jobs.job_record(job.pipeline, opts, inputs)
        with jobs.output_lock(job.model):
            if if_changed and jobs.up_to_date(job.model, digest, record):
                out["status"] = "unchanged"
                return out
            data = logs.from_table(table, name=job.log, sha256=digest, cutoff_hz=opts["cutoff"],
                                   **{k: opts[k] for k in ("joint", "kt", "drop_invalid")})
            if job.pipeline == "identify":
                made = _identify(data, opts, record, job.model)
            elif job.pipeline == "train-base":
                made = _train_base(data, opts, record, job.model)
            else:
                base_model, base_meta = models.load(job.base)
                models.check_log(base_meta, data, job.base)
                made = _adapt(data, opts, record, job.model, base_model, base_meta, job.base)
        model = made.pop("model")
        out.update(made, status="ok")
        if job.diagnose:
            out["effects"], out["reason"] = _diagnose(model, data)
    except errors.FricliError as exc:
        out["reason"] = errors.one_line(str(exc))
    except MemoryError:
        out["reason"] = "out of memory"
    except Exception as exc:  # a bug or an unforeseen input: reported in one line, the other jobs go on
        first = str(exc).splitlines()[0] if str(exc) else ""
        out["reason"] = errors.one_line(f"internal error: {type(exc).__name__}: {first}")
    finally:
        out["seconds"] = time.perf_counter() - start
    return out
