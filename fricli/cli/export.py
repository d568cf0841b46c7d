"""fricli export."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import common, output_option, say


@cli.command("export")
@click.argument("model", type=click.Path(exists=False))
@output_option(help="Output C header (- for stdout).")
@click.option("--prefix", default="friction", show_default=True,
              help="Prefix of every C symbol (PREFIX_step, ...); a folder of models adds _JOINT per file.")
@common
def export_cmd(model, output, prefix, quiet):
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
    from fricli.core.atomic import atomic_write_bytes
    from fricli.export import c

    try:
        c.check_prefix(prefix)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--prefix") from None
    text = c.export(model, prefix)
    if output == "-":
        click.echo(text, nl=False)
    else:
        atomic_write_bytes(output, text.encode("ascii"))
        say(f"wrote {output}", quiet)
