"""fricli identify: fit the extended LuGre model to a log."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import (check_outputs, common, emit_results, fit_joints, if_changed_option, json_flag,
                                log_reading, output_option, say, spec_options, wrote)
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
def identify_cmd(log: str, output: str, kind: str, if_changed: bool, as_json: bool, quiet: bool, **_options) -> None:
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

    results, folder_run = fit_joints("identify", log, output, report, if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


def _report_linear(data, model, fit, out, quiet: bool) -> dict:
    from fricli.models import linear

    unit, params = data.units["tau"], model.parameters()
    say(f"{model.describe()}\nfit error, all rows: {_figures(fit, unit)}\n"
        f"fit error, {fit['moving_rows']:,} rows in motion: {_figures(fit['moving'], unit)}\n{wrote(out)}", quiet)
    return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis, "units": data.units,
            "parameters": params, "parameter_units": {k: linear.unit_of(k, data.axis) for k in params}, "fit": fit}


def _report(data, model, fit, output, quiet) -> None:
    if quiet:
        return
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
    say(wrote(output))
