"""fricli identify: fit the extended LuGre model to a log."""

from __future__ import annotations

import os

import click

from fricli.core import errors
from fricli.cli import cli
from fricli.cli.options import (check_outputs, command_options, common, emit_results, fit_joints, if_changed_option,
                                json_flag, log_reading, output_option, read_log, say, spec_options, time_window,
                                up_to_date_line, warn, wrote)
from fricli.models.lugre import PARAM_INFO, unit_of


def _figures(errs: dict, unit: str) -> str:
    return f"MAE {errs['mae']:.4g} {unit}, RMSE {errs['rmse']:.4g} {unit}, max {errs['max']:.4g} {unit}"


@cli.command("identify")
@click.argument("log")
@output_option(help="Model file to write (.npz; - for stdout), or a folder for one model per joint (docs/joints.md).")
@log_reading
@spec_options("identify")
@if_changed_option
@json_flag
@common
def identify_cmd(log: str, output: str, kind: str, coupling: bool, motor_stribeck: bool, if_changed: bool,
                 as_json: bool, quiet: bool, **_options) -> None:
    """Fit the extended LuGre friction model to LOG (- for stdin) and write it to a model file.

    Static parameters (Fc, Fs, vs, delta, Fv and the load slopes kc, ks) are fitted on the
    steady-state samples, then the bristle parameters sigma0, sigma1 by simulating the whole
    log (see docs/lugre.md). With --kind linear, the model Fv*qd + Fc*sign(qd) + offset by least
    squares on the rows in motion instead. Parameters and fit errors go to stderr, or as JSON to stdout with
    --json. On failure the previous model file is left untouched.

    A log of several joints without --joint gives one model per joint in the folder -o DIR
    (DIR/joint_<name>.npz; docs/joints.md).

    \b
    Example:
      fricli identify sample_data/joint2_base.parquet -o lugre.npz
      fricli identify emps.parquet -o emps.npz --cutoff 100 --json
      fricli identify nightly.parquet -o lugre.npz --if-changed   # cron: exit 9 (UNCHANGED) when up to date
      fricli identify arm.parquet -o lugre-arm/                    # every joint of the arm
    """
    check_outputs(output, as_json)

    def report(made):
        data, model, fit, out = made.data, made.model, made.summary, made.output
        if kind != "lugre":
            return _report_linear(data, model, fit, out, quiet)
        _report(data, model, fit, out, quiet)
        params = model.parameters()
        return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis,
                "units": data.units, "parameters": params,
                "parameter_units": {k: unit_of(k, data.axis) for k in params}, "fit": fit}

    if motor_stribeck and not coupling:
        raise click.UsageError("--motor-stribeck applies to --coupling")

    def report_group(made, label):
        model, fit = made.model, made.summary
        if not quiet:
            unit = made.data.units["tau"]
            say(f"identified the coupled friction of joints {label} on {made.data.name} ({len(made.data):,} rows "
                "per joint), per motor:")
            say(model.describe().splitlines()[1:])
            for x, errs in fit["joints"].items():
                say(f"fit error, joint {x}: {_figures(errs, unit)}")
            say(wrote(made.output))
        return {"model": made.output, "log": made.data.name, "joints": list(model.joints), "kind": "coupled",
                "parameters": {k: getattr(model, k).tolist() for k in model.names()},
                "ratio": model.ratio.tolist(), "fit": fit}

    if coupling:
        results, folder_run = fit_coupled("identify", log, output, report, report_group, if_changed=if_changed,
                                          quiet=quiet)
    else:
        results, folder_run = fit_joints("identify", log, output, report, if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


def _report_linear(data, model, fit, out, quiet: bool) -> dict:
    from fricli.models import gms, linear

    if model.kind == "gms":
        linear = gms
        for note in fit.get("notes", []):
            say(f"note: {note}", quiet)

    unit, params = data.units["tau"], model.parameters()
    say([*model.describe().splitlines(), f"fit error, all rows: {_figures(fit, unit)}",
         f"fit error, {fit['moving_rows']:,} rows in motion: {_figures(fit['moving'], unit)}", wrote(out)], quiet)
    return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis, "units": data.units,
            "parameters": params, "parameter_units": {k: linear.unit_of(k, data.axis) for k in params}, "fit": fit}


def _report(data, model, fit, output, quiet) -> None:
    """Parameters, errors and notes (unless quiet), then the plausibility warnings (always)."""
    if not quiet:
        unit = data.units["tau"]
        where = f"joint {data.joint}, " if data.joint is not None else ""
        say(f"identified the extended LuGre model on {data.name} ({where}{len(data):,} rows, "
            f"{fit['steady_rows']:,} steady-state)")
        for name, value in model.parameters().items():
            say(f"  {name:<7} {value:>12.6g} {unit_of(name, data.axis):<9} {PARAM_INFO[name][2]}")
        say(f"fit error, all rows:          {_figures(fit, unit)}")
        say(f"fit error, steady-state rows: {_figures(fit['steady'], unit)}")
        for note in fit["notes"]:
            say(f"note: {note}")
    for warning in fit["warnings"]:
        warn(f"warning: {warning}")
    say(wrote(output), quiet)


def fit_coupled(pipeline: str, log: str, output: str, report, report_group, *, if_changed: bool, quiet: bool,
                progress=None) -> tuple[dict, bool]:
    """``fit_joints`` for ``pipeline`` (identify, train-base) with --coupling: a joint of a coupled
    group of the log's transmission brings its whole group into one model (DIR/joints_<a>_<b>.npz,
    ``fricli.fitting.runs.run_group``; ``report_group(made, label)`` prints it and returns its JSON
    result); the other joints get theirs (``report(made)``). ``progress(data)``: a trainer
    progress callback with ``close()``, for a joint's log; ``progress(data, motor)`` for a group's motor."""
    from fricli.core import joints, logs, modelset
    from fricli.fitting import runs
    from fricli.core.errors import LogError
    from fricli.models import coupled
    from fricli.core import transmission

    opts = command_options(pipeline)
    window = time_window()
    window = window.to_json() if window else None
    table, digest = read_log(log)
    name = "stdin" if log == "-" else log
    runs.check_table(table, name, opts, pipeline)
    try:
        tr = transmission.of_schema(table.schema.metadata)
    except ValueError as exc:
        raise LogError(f"{name}: {exc}") from None
    if tr is None:
        raise LogError(f"{name}: --coupling needs the log's transmission (written by fricli import from a mapping "
                       "with a transmission, docs/drives.md); the log records none")
    log_joints = logs.joints_of(table, name)
    covered = joints.select(log_joints, opts["joint"], name)
    groups = [tr.sub(g) for g in tr.coupled_groups()]
    units, seen = [], set()
    for j in covered:
        group = next((g for g in groups if any(joints.same(j, x) for x in g.joints)), None)
        key = tuple(map(str, group.joints)) if group else (str(j),)
        if key not in seen:
            seen.add(key)
            units.append((j, group))
    labels = {j: (", ".join(map(str, g.joints)) if g else j) for j, g in units}
    folder = modelset.output_folder(output, [j for j, _ in units], log_joints, name)   # a group alone: one file
    reading = {"kt": opts["kt"], "cutoff_hz": opts["cutoff"], "drop_invalid": opts["drop_invalid"], "warn": warn,
               "zero": runs.zero(opts)}
    results: dict = {}

    def work(label):
        j, group = next(u for u in units if labels[u[0]] == label)
        if group is None:
            data = runs.read(table, digest, name, opts, joint=j, warn=warn)
            out = modelset.path_for(folder, j) if folder else output
            on_eval = progress(data) if progress else None
            try:
                made = runs.run(pipeline, data, out, opts, if_changed=if_changed, window=window, on_eval=on_eval)
            finally:
                if on_eval is not None:
                    on_eval.close()
        else:
            missing = [x for x in group.joints if not any(joints.same(x, y) for y in log_joints)]
            if missing:
                raise LogError(f"{name}: joint {j} shares motors with joints {joints.listed(missing)}, which the log "
                               "does not hold: the coupled group needs every joint's rows")
            _, datas = coupled.group_rows(table, list(group.joints), name, sha256=digest, **reading)
            out = os.path.join(folder, modelset.group_file_name(group.joints)) if folder else output
            made = runs.run_group(datas, group, out, opts, if_changed=if_changed, window=window, pipeline=pipeline,
                                  progress=(lambda i: progress(datas[0], i)) if progress else None)
        if made is None:
            say(up_to_date_line(out, digest, False), quiet)
            if folder is None:
                click.get_current_context().exit(errors.UNCHANGED)
            return
        if group is None:
            results[j] = report(made)
            return
        results[labels[j]] = report_group(made, labels[j])

    modelset.each_joint([labels[j] for j, _ in units], work)
    if folder and not results:
        click.get_current_context().exit(errors.UNCHANGED)
    return results, folder is not None
