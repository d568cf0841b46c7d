"""fricli identify: fit the extended LuGre model to a log."""

from __future__ import annotations

import os

import click

from fricli import models
from fricli.cli import cli
from fricli.cli.options import (common, emit_results, fit_joints, if_changed_option, json_flag, log_reading,
                                output_option, reading_kwargs, say, warn)
from fricli.errors import OutputError
from fricli.identify import LuGreIdentifier
from fricli.models.lugre import PARAM_INFO, unit_of


def _figures(errs: dict, unit: str) -> str:
    return f"MAE {errs['mae']:.4g} {unit}, RMSE {errs['rmse']:.4g} {unit}, max {errs['max']:.4g} {unit}"


@cli.command("identify")
@click.argument("log")
@output_option(help="Model file to write (.npz), or a folder for one model per joint (docs/joints.md).")
@log_reading
@click.option("--hold", type=click.FloatRange(min=0, min_open=True), default=0.2, show_default=True,
              help="Steady state: the velocity must have been constant for at least this long [s].")
@click.option("--travel", type=click.FloatRange(min=0), default=0.002, show_default=True,
              help="Steady state: ... and over at least this distance [rad or m] (longer holds at slow speeds).")
@click.option("--samples", type=click.Choice(["auto", "steady", "settled"]), default="auto", show_default=True,
              help="Rows for the static curve: constant-velocity holds, every row --settle past a reversal "
                   "(continuous excitation), or settled when holds cover under half of the motion and the log has tau_dyn.")
@click.option("--settle", type=click.FloatRange(min=0), default=0.01, show_default=True,
              help="Settled rows: travel since the last velocity reversal [rad or m].")
@click.option("--refine", is_flag=True, help="Finally fit all parameters jointly on the whole log.")
@if_changed_option
@json_flag
@common
def identify_cmd(log: str, output: str, joint, kt, cutoff, drop_invalid, hold: float, travel: float,
                 samples: str, settle: float, refine: bool, if_changed: bool, as_json: bool, quiet: bool) -> None:
    """Fit the extended LuGre friction model to LOG (- for stdin) and write it to a model file.

    Static parameters (Fc, Fs, vs, delta, Fv and the load slopes kc, ks) are fitted on the
    steady-state samples, then the bristle parameters sigma0, sigma1 by simulating the whole
    log (see docs/lugre.md). Parameters and fit errors go to stderr, or as JSON to stdout with
    --json. On failure the previous model file is left untouched.

    A log of several joints without --joint gives one model per joint in the folder -o DIR
    (DIR/joint_<name>.npz; docs/joints.md).

    \b
    Example:
      fricli identify sample_data/joint2_base.parquet -o lugre.npz
      fricli identify emps.parquet -o emps.npz --cutoff 100 --json
      fricli identify nightly.parquet -o lugre.npz --if-changed   # cron: exit 9 when up to date
      fricli identify arm.parquet -o lugre-arm/                    # every joint of the arm
    """
    if output == "-":
        raise click.UsageError("identify writes a model file: give -o FILE.npz (or a folder), not -")
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {output}: folder {folder} does not exist")

    def fit_one(data, out, job, _model):
        idf = LuGreIdentifier(hold=hold, travel=travel, refine=refine, samples=samples,
                              settle=settle).fit(data.signals, units=data.units,
                                                                           axis=data.axis)
        model, fit = idf.model_, idf.fit_
        models.save_for_log(out, model, data, rows_used=len(data), fit=fit, job=job)
        _report(data, model, fit, out, quiet)
        params = model.parameters()
        return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis,
                "units": data.units, "parameters": params,
                "parameter_units": {k: unit_of(k, data.axis) for k in params}, "fit": fit}

    results, folder_run = fit_joints(log, output, joint, reading_kwargs(joint, kt, cutoff, drop_invalid), fit_one,
                                     if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


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
    say(f"wrote {output}", quiet)
