"""fricli identify: fit the extended LuGre model to a log."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import (check_outputs, common, emit_results, fit_joints, if_changed_option, json_flag,
                                log_reading, output_option, say, spec_options, warn, wrote)
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
                 as_json: bool, quiet: bool, window, **_options) -> None:
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

    results, folder_run = fit_joints("identify", log, output, report, report_group=report_group, window=window,
                                     if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


def _report_linear(data, model, fit, out, quiet: bool) -> dict:
    from fricli.models import gms, linear as plain

    linear = gms if model.kind == "gms" else plain
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
