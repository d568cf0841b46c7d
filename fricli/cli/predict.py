"""fricli predict and fricli estimate-ext."""

from __future__ import annotations

import click

from fricli.applying import predicting
from fricli.cli import cli
from fricli.estimators.prediction import predict_file
from fricli.cli.options import (LOWPASS_HELP, Number, common, emit_json, extrapolation_line, json_flag, log_reading,
                                output_option, progress_enabled, say, warn, zero_keywords)


def _figures(errs: dict, unit: str) -> str:
    return f"MAE {errs['mae']:.4g} {unit}, RMSE {errs['rmse']:.4g} {unit}, max {errs['max']:.4g} {unit}"


def batch_option(f):
    return click.option("--batch-rows", type=click.IntRange(min=1), default=predicting.DEFAULT_BATCH_ROWS,
                        show_default=True, help="Rows per record batch (the model state is carried across).")(f)


def flag_option(f):
    return click.option("--flag-extrapolation", is_flag=True,
                        help="Add the boolean column 'extrapolating': the row lies outside the model's training "
                             "envelope (docs/neural-models.md).")(f)


def precision_option(f):
    return click.option("--precision", type=click.Choice(["single", "double"]), default="single", show_default=True,
                        help="Arithmetic of the networks: single (float32, fastest) or double (float64, "
                             "as the code of fricli export). A dissipative network on batches of 65,536 rows "
                             "or more runs through its polynomial pieces (double to 1e-12) either way.")(f)


def _run(model_path, log, output, joint, kt, cutoff, drop_invalid, as_json, batch_rows, quiet, *, zero, window,
         external: bool, lowpass=None, flag_extrapolation=False, precision="single"):
    if as_json and output == "-":
        raise click.UsageError("--json needs -o FILE: stdout carries the Parquet output")

    bar = None
    if progress_enabled(quiet):
        from tqdm import tqdm

        bar = tqdm(unit="rows", leave=False)

    def on_rows(rows: int, total: int) -> None:
        bar.total = total
        bar.update(rows)

    try:
        result = predict_file(model_path, log, output, external=external, lowpass_hz=lowpass,
                              flag_extrapolation=flag_extrapolation, precision=precision, batch_rows=batch_rows,
                              time_from=window.start, time_until=window.stop, warn=warn,
                              on_rows=on_rows if bar is not None else None, joint=joint, kt=kt, cutoff=cutoff,
                              drop_invalid=drop_invalid, **zero_keywords(zero))
    finally:
        if bar is not None:
            bar.close()
    if not quiet:
        where = f" of joint {result.joint}" if result.joint is not None else ""
        if result.per_joint:
            where = f" of joints {', '.join(result.per_joint)}"
        dest = "stdout" if output == "-" else output
        say(f"{result.rows:,} rows{where} -> {dest}" + (f" (read whole: {result.read_whole})" if result.read_whole else ""))
        say(f"friction error against the target: {_figures(result.friction, result.unit)}")
        if result.external is not None:
            say(f"external torque error against tau_ext: {_figures(result.external, result.unit)}")
        for j, figures in (result.per_joint or {}).items():
            outside = figures.get("outside")
            say(f"  joint {j} ({figures['rows']:,} rows, {figures['model']}): friction {_figures(figures['friction'], result.unit)}"
                + (f"; external {_figures(figures['external'], result.unit)}" if "external" in figures else "")
                + (f"; {outside:,} row{'s' if outside != 1 else ''} outside the training envelope" if outside else ""))
        if result.extrapolation is not None:
            say(extrapolation_line(result.extrapolation))
    if as_json:
        out = result.as_json()
        out.update(model=model_path, log=log, output=output)
        if lowpass:
            out["lowpass_hz"] = lowpass
        emit_json(out)


@cli.command("predict")
@click.argument("model", type=click.Path())
@click.argument("log")
@output_option(help="Output log (Parquet; - for stdout).")
@log_reading
@batch_option
@flag_option
@precision_option
@json_flag
@common
def predict_cmd(model, log, output, joint, kt, cutoff, drop_invalid, zero, window, batch_rows, flag_extrapolation,
                precision, as_json, quiet):
    """Predict friction with MODEL on LOG (- for stdin): writes the log with tau_f_pred added.

    Every column and its metadata is carried through. The friction error (MAE, RMSE, max)
    against the target tau_m + tau_ext - tau_g - tau_dyn goes to stderr (and to stdout as
    JSON with --json, when the output is a file). MODEL may be a model folder (one model per
    joint): every joint of the log is predicted with its own model into one long-format log.
    One model file on a log of several joints is used for its own joint (or --joint); a model
    fitted on another joint is refused (docs/joints.md). Large logs are processed in record batches with the model
    state carried across; a log without qd (or without qdd, for a model that reads it) is read
    whole (docs/lugre.md). The share of rows
    outside the model's training envelope (where it extrapolates) goes to stderr and the JSON.

    \b
    Example:
      fricli predict lugre.npz sample_data/joint2_extended_asym.parquet -o pred.parquet
      fricli simulate --scenario base --joint 2 --seed 2 -o - | fricli predict lugre.npz - -o - > pred.parquet
    """
    _run(model, log, output, joint, kt, cutoff, drop_invalid, as_json, batch_rows, quiet, zero=zero, window=window,
         external=False, flag_extrapolation=flag_extrapolation, precision=precision)


@cli.command("estimate-ext")
@click.argument("model", type=click.Path())
@click.argument("log")
@output_option(help="Output log (Parquet; - for stdout).")
@click.option("--lowpass", type=Number(min=0, min_open=True), default=None,
              help=LOWPASS_HELP + " Reads the log whole.")
@log_reading
@batch_option
@flag_option
@precision_option
@json_flag
@common
def estimate_ext_cmd(model, log, output, lowpass, joint, kt, cutoff, drop_invalid, zero, window, batch_rows,
                     flag_extrapolation, precision, as_json, quiet):
    """Estimate the external torque on LOG with MODEL's friction: adds tau_f_pred and
    tau_ext_pred = tau_g + tau_dyn + tau_f_pred - tau_m.

    When the log has the sensor column tau_ext, the error of tau_ext_pred against it (MAE,
    RMSE, max) goes to stderr (and to stdout as JSON with --json, when the output is a file).
    MODEL may be a model folder: every joint of the log with its own model (docs/joints.md).

    \b
    Example:
      fricli estimate-ext adapted.npz sample_data/joint2_extended_asym.parquet --lowpass 2 -o ext.parquet
    """
    _run(model, log, output, joint, kt, cutoff, drop_invalid, as_json, batch_rows, quiet, zero=zero, window=window,
         external=True,
         lowpass=lowpass, flag_extrapolation=flag_extrapolation, precision=precision)
