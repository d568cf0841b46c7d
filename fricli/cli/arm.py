"""fricli fit-arm: a whole arm in one command (``fricli.arm.fit_arm``)."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import Cutoff, Folder, Number, common, emit_json, if_changed_option, json_flag, say, warn
from fricli.core import errors
from fricli.fitting.optionspec import OptionError


@cli.command("fit-arm")
@click.argument("recordings", nargs=-1, required=True)
@click.option("--mapping", "mapping", required=True, metavar="MAP.toml",
              help="Which column holds what (docs/robot-import.md), for every recording.")
@click.option("--urdf", required=True, metavar="ROBOT.urdf",
              help="The robot's URDF (CAD masses; calibrated on the recording). Needs pip install 'fricli[robot]'.")
@click.option("-o", "--output", required=True, type=Folder(), help="Folder for every step's output.")
@click.option("--validate", multiple=True, metavar="RECORDING",
              help="A held-out recording of the same robot (e.g. of another day) to score on. Repeatable.")
@click.option("--holdout", type=Number(min=0, max=1, min_open=True, max_open=True), default=None, metavar="SHARE",
              help="Without --validate: the share of the recording's time held out and scored on [default: 0.25].")
@click.option("--cutoff", type=Cutoff(), default=10.0, show_default=True,
              help="Low-pass cut-off [Hz] of the qd and qdd derived at import (or auto).")
@click.option("--prefix", default="friction", show_default=True, help="Prefix of the C names in friction.h.")
@if_changed_option
@json_flag
@common
def fit_arm_cmd(recordings, mapping, urdf, output, validate, holdout, cutoff, prefix, if_changed, as_json, quiet):
    """Fit a whole arm: import RECORDING (its files, for a recording in several files) with the
    mapping and the URDF, identify every joint, calibrate the robot model, refit and diagnose
    every joint's friction on the calibrated robot model (diagnose --fix --calibrate), score the
    models against the linear baseline on held-out data, and write a report and a C header.

    Each step's output is kept in -o DIR: fit-cad.parquet, lugre/, robot.urdf (and
    robot.calibration.json), fit.parquet, fixed/, validate/, friction.h, report.md, report.json,
    and fit-arm.json (what each step was made from). The score table goes to stdout (JSON with
    --json). With --if-changed a step whose inputs did not change is not redone; exit 9
    (UNCHANGED) when none was.

    \b
    Example:
      fricli fit-arm run.csv --mapping arm.toml --urdf arm.urdf -o arm/
      fricli fit-arm run.csv --mapping arm.toml --urdf arm.urdf --validate day2.csv --validate day3.csv -o arm/
    """
    from fricli import arm

    try:
        report = arm.fit_arm(list(recordings), mapping, urdf, output, validate=list(validate), holdout=holdout,
                             cutoff_hz=cutoff, prefix=prefix, if_changed=if_changed, say=lambda s: say(s, quiet))
    except OptionError as exc:
        raise click.UsageError("--holdout applies without --validate (the validation recordings are held out)"
                               if validate else f"--holdout: {exc}") from None
    for level, line in report.notices:
        if level == "warning":
            warn(line if line.startswith("warning") else f"warning: {line}")
        else:
            say(line, quiet)
    if if_changed and report.unchanged:
        say(f"{output} is up to date: every step was made from the same inputs; nothing to do", quiet)
        click.get_current_context().exit(errors.UNCHANGED)
    if as_json:
        emit_json(report.to_json())
    else:
        click.echo(arm.markdown(report, list(recordings), urdf), nl=False)
    say(f"wrote every step's output into {output}", quiet)
