"""One fleet job: a pipeline (identify, train-base, adapt) on one (robot, joint, log), made by
``fricli.fitting.plan`` like the command of the same name: a model written by the fleet is the
bytes ``fricli identify`` writes with the same options, and up to date for its ``--if-changed``,
and the other way round."""

from __future__ import annotations

import os
import time

from fricli.core import errors
from fricli.fitting import plan, runs
from fricli.fleet.manifest import Job


def options_of(job: Job) -> dict:
    """The job's options over the pipeline's defaults (``fricli.fitting.optionspec``), its joint included."""
    return runs.options(job.pipeline, dict(job.options, joint=job.joint or None))


def _diagnose(model, data) -> tuple[list, str]:
    from fricli.fitting.diagnosis import driver

    try:
        return list(driver.diagnose(model, data).added), ""
    except errors.FricliError as exc:
        return [], errors.one_line(f"diagnose: {exc}")


def run(job: Job, *, if_changed: bool = True) -> dict:
    """Run one job; never raises for a job's own failure.

    Returns {"status": ok | unchanged | failed, "reason": one line or "", "seconds",
    "kind", "parameters", "errors", "sha256", "effects", "warnings"}: "errors" are the MAE, RMSE
    and max over the log's rows in motion (``runs.moving_errors``); "warnings" the fit's
    plausibility warnings (those ``fricli identify`` prints). With ``job.diagnose`` the effects the
    new model misses are looked for (``fricli.fitting.diagnosis``); when that fails the job stays ok and
    the reason says why."""
    start = time.perf_counter()
    out = {"status": "failed", "reason": "", "kind": None, "parameters": {}, "errors": {}, "sha256": "",
           "effects": [], "warnings": []}
    try:
        if job.clash:
            raise errors.LogError(f"{job.log}: {job.clash} has the same file name, so both would write the model "
                                  f"{job.model}; rename one of them or match only one")
        opts = options_of(job)
        try:
            os.makedirs(os.path.dirname(job.model), exist_ok=True)
        except OSError as exc:
            raise errors.OutputError(f"cannot write {job.model}: {exc.strerror or exc}") from None
        read = plan.read_log(job.log)
        out["sha256"] = read[1]
        outcome, = plan.fit_log(job.pipeline, job.log, job.model, opts, inputs=job.base, read=read,
                                if_changed=if_changed).outcomes
        made = outcome.made
        if made is None:
            out["status"] = "unchanged"
            return out
        params = {}
        if made.pipeline == "identify":   # a gms model's in the LuGre model's terms (its sum of levels)
            params = getattr(made.model, "steady_parameters", made.model.parameters)()
        out.update(status="ok", kind=made.model.kind, parameters=params, errors=runs.moving_errors(made),
                   warnings=list(made.summary.get("warnings", [])))
        if job.diagnose:
            out["effects"], out["reason"] = _diagnose(made.model, made.data)
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
