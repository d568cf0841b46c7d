"""fricli evaluate, fricli report."""

from __future__ import annotations

import os

import click

from fricli.cli import cli
from fricli.cli.options import (LOWPASS_HELP, Folder, Number, common, emit_json, extrapolation_line, json_flag,
                                log_reading, say, warn, zero_keywords)


def _named(values: tuple[str, ...], what: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for value in values:
        name, sep, path = value.partition("=")
        if not sep:
            name, path = os.path.splitext(os.path.basename(value))[0], value
        if not name or not path:
            raise click.BadParameter(f"expected NAME=PATH or PATH, got {value!r}", param_hint=f"--{what}")
        if name in out:
            raise click.BadParameter(f"the name {name!r} is used twice", param_hint=f"--{what}")
        out[name] = path
    return out


@cli.command("evaluate")
@click.option("--model", "model_specs", multiple=True, required=True, metavar="[NAME=]MODEL",
              help="A model file, or a model folder with one model per joint, to evaluate (repeatable).")
@click.option("--log", "log_specs", multiple=True, required=True, metavar="[NAME=]LOG.parquet",
              help="A log to evaluate on (repeatable).")
@click.option("--lowpass", type=Number(min=0, min_open=True), default=None,
              help=LOWPASS_HELP)
@log_reading
@json_flag
@common
def evaluate_cmd(model_specs, log_specs, lowpass, joint, kt, cutoff, drop_invalid, zero, window, as_json, quiet):
    """Friction (and external-torque) MAE and RMS of every model on every log, as a table.

    The friction error is against the target tau_m + tau_ext - tau_g - tau_dyn; the
    external-torque error is against the log's sensor column tau_ext, when it has one.
    A model folder (one model per joint) is evaluated on every joint of a log, one row per
    joint, and so is a coupled group's model on each joint of its group, with the other joints'
    velocities from the same log (docs/drives.md); a model fitted on another joint than the
    log's is refused (docs/joints.md).
    The share of each log's rows outside each model's training envelope goes to stderr (and the JSON).
    The JSON gives each error's mae, rmse (the RMS) and max, in the log's torque unit ("unit").

    \b
    Example:
      fricli evaluate --model lugre=lugre.npz --model adapted=adapted.npz \\
          --log asym=sample_data/joint2_extended_asym.parquet --json
    """
    from fricli.estimators import evaluate

    run = evaluate(_named(model_specs, "model"), _named(log_specs, "log"), lowpass_hz=lowpass, joint=joint, kt=kt,
                   cutoff=cutoff, drop_invalid=drop_invalid, no_gravity="tau_g" in zero, no_dynamics="tau_dyn" in zero,
                   time_from=window.start, time_until=window.stop, warn=warn)
    results = run.results
    if as_json:
        emit_json(run.to_json())
    else:
        click.echo(run.markdown())
    several = len({str(r.joint) for r in results}) > 1
    checked = [r for r in results if r.extrapolation is not None]
    outside = [r for r in checked if r.extrapolation["rows"]]
    for r in outside:
        say(f"{r.model} on {r.log}: {extrapolation_line(r.extrapolation, r.joint if several else None)}", quiet)
    if len(outside) < len(checked):
        where = "" if len(checked) == 1 else (f" in {'the other ' if outside else ''}{len(checked) - len(outside)} "
                                              f"of the {len(checked)} evaluations")
        say(f"no row lies outside the model's training envelope{where}", quiet)
    for note in dict.fromkeys(r.robot_model for r in results if r.robot_model):
        warn(note)


@cli.command("report")
@click.argument("model", type=click.Path())
@click.argument("log")
@click.option("-o", "--output", required=True, type=Folder(), help="Folder for the figures and index.html.")
@click.option("--lowpass", type=Number(min=0, min_open=True), default=None,
              help=LOWPASS_HELP)
@log_reading
@common
def report_cmd(model, log, output, lowpass, joint, kt, cutoff, drop_invalid, zero, window, quiet):
    """PNG figures of MODEL on LOG and an index.html that shows them, each with a caption
    saying what it shows and how to read it, and the errors with their units (MAE, RMS, max).

    Figures: training/validation loss, friction against velocity, a heat map over velocity and
    gravity torque, friction over time, the four quadrants, and the external torque against the
    sensor when the log has one. MODEL may be a model folder (one model per joint): every joint
    of the log gets its report in DIR/joint_<name>/, and DIR/index.html links them (docs/joints.md);
    a coupled group's model the same for each joint of its group (docs/drives.md).

    \b
    Example:
      fricli report adapted.npz sample_data/joint2_extended_asym.parquet -o report/
    """
    from fricli.estimators.reporting import write_report  # matplotlib loads only for this command

    summaries = write_report(model, log, output, lowpass_hz=lowpass, time_from=window.start,
                             time_until=window.stop, warn=warn, joint=joint, kt=kt, cutoff=cutoff,
                             drop_invalid=drop_invalid, **zero_keywords(zero))
    if len(summaries) == 1:
        summary = next(iter(summaries.values()))
        say(f"wrote {len(summary['figures'])} figures and index.html to {output} "
            f"(friction MAE {summary['friction']['mae']:.3f} {summary['unit']})", quiet)
    else:
        maes = ", ".join(f"joint {j} {r['friction']['mae']:.3f} {r['unit']}" for j, r in summaries.items())
        say(f"wrote a report per joint and index.html to {output} (friction MAE: {maes})", quiet)
