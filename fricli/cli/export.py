"""fricli export."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.applying.observer import Adaptation
from fricli.cli.options import Number, common, output_option, say
from fricli.cli.replay import GAIN_HELP, TIME_CONSTANT_HELP


@cli.command("export")
@click.argument("model", type=click.Path(exists=False))
@output_option(help="Output C header (- for stdout).")
@click.option("--prefix", default="friction", show_default=True,
              help="Prefix of every C symbol (PREFIX_step, ...); a folder of models adds _JOINT per file.")
@click.option("--observer", is_flag=True,
              help="Also export the arm's momentum observer and contact detection around the joints' friction "
                   "(PREFIX_arm_*; MODEL a folder of per-joint models): what fricli replay runs "
                   "(docs/contact-detection.md).")
@click.option("--thresholds", "thresholds_path", type=click.Path(), default=None,
              help="With --observer: contact thresholds of fricli thresholds.")
@click.option("--adapt", is_flag=True, help="With --observer: the online friction-level adaptation (needs "
                                            "--thresholds), as fricli replay --adapt.")
@click.option("--adapt-offset", is_flag=True, help="With --adapt: adapt an offset too, as fricli replay --adapt-offset.")
@click.option("--time-constant", type=Number(min=0, min_open=True), default=None,
              help=f"With --adapt: {TIME_CONSTANT_HELP[0].lower()}{TIME_CONSTANT_HELP[1:]} Default: "
                   f"{Adaptation().time_constant:g}, as fricli replay's.")
@click.option("--gain", type=Number(min=0, min_open=True), default=None,
              help=f"With --observer: {GAIN_HELP[0].lower()}{GAIN_HELP[1:]}")
@common
def export_cmd(model, output, prefix, observer, thresholds_path, adapt, adapt_offset, time_constant, gain, quiet):
    """Export MODEL (a model file, or a folder with one .npz per joint) as dependency-free C99.

    Writes one header with the parameters baked in: PREFIX_state, PREFIX_init and
    PREFIX_step (one call per sample, returning the friction torque, as fricli predict)
    per model, and PREFIX_step_parts (friction alone, and the robot-model error correction
    of a diagnosed model apart); for a folder, a set per model file named PREFIX_<file name>_*. The header's comment lists the
    signals each step function takes (names, units, order) and the model's provenance.
    It needs only <math.h> and computes in double precision, like `fricli predict
    --precision double` (docs/deploy.md).

    \b
    Example:
      fricli export lugre.npz -o friction.h
      fricli export models/ --prefix arm -o arm_friction.h
    """
    from fricli.export.header import export_header

    export_header(model, output, prefix=prefix, observer=observer, thresholds=thresholds_path, adapt=adapt,
                    adapt_offset=adapt_offset, time_constant=time_constant, gain=gain)
    if output != "-":
        say(f"wrote {output}", quiet)

