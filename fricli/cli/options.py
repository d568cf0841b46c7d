"""Options shared by several commands, as small decorator stacks."""

from __future__ import annotations

import json
import sys

import click

from fricli.logs import DEFAULT_CUTOFF_HZ


def _set_debug(ctx: click.Context, _param, value: bool) -> bool:
    if value:
        ctx.meta["fricli.debug"] = True
    return value


def common(f):
    """--quiet and --debug."""
    f = click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
                     help="Show the full traceback on errors.")(f)
    f = click.option("-q", "--quiet", is_flag=True, help="No progress bars or messages on stderr.")(f)
    return f


def log_reading(f):
    """--joint, --kt, --cutoff, --drop-invalid: how a log is read (see docs/log-format.md)."""
    f = click.option("--drop-invalid", is_flag=True,
                     help="Drop rows with NaN or infinite values (with a warning) instead of refusing the log.")(f)
    f = click.option("--cutoff", type=click.FloatRange(min=0, min_open=True), default=DEFAULT_CUTOFF_HZ,
                     show_default=True, help="Low-pass cut-off [Hz] used when qd/qdd are derived from q.")(f)
    f = click.option("--kt", type=float, default=None, help="Motor torque constant [Nm/A] when the log has i_m instead of tau_m.")(f)
    f = click.option("--joint", default=None, help="Joint to use when the log holds several.")(f)
    return f


def json_flag(f):
    return click.option("--json", "as_json", is_flag=True, help="Print the result as JSON on stdout.")(f)


def output_option(required: bool = True, help: str = "Output file (- for stdout)."):
    return click.option("-o", "--output", required=required, help=help)


def say(message: str, quiet: bool = False) -> None:
    """A message for people: stderr, unless --quiet."""
    if not quiet:
        click.echo(message, err=True)


def warn(message: str) -> None:
    """Warnings always reach stderr."""
    click.echo(message, err=True)


def emit_json(obj) -> None:
    sys.stdout.write(json.dumps(obj, indent=2, sort_keys=True, allow_nan=False) + "\n")


def progress_enabled(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def reading_kwargs(joint, kt, cutoff, drop_invalid) -> dict:
    return {"joint": joint, "kt": kt, "cutoff_hz": cutoff, "drop_invalid": drop_invalid, "warn": warn}
