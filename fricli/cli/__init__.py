"""The ``fricli`` command line. Commands only parse options and format output; the work is
done in library modules. Library errors (``FricliError``) become one line on stderr and
the exit code documented in docs/exit-codes.md; click keeps exit code 2 for usage errors.
"""

from __future__ import annotations

import sys

import click

from fricli import __version__
from fricli import errors


class FricliGroup(click.Group):
    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except errors.FricliError as exc:
            if ctx.meta.get("fricli.debug"):
                raise
            click.echo(f"fricli: error: {errors.one_line(str(exc))}", err=True)
            ctx.exit(exc.exit_code)
        except KeyboardInterrupt:
            click.echo("fricli: interrupted", err=True)
            ctx.exit(130)
        except BrokenPipeError:
            sys.stderr.close()  # the reader went away: nothing more to say
            ctx.exit(errors.OUTPUT)
        except MemoryError:
            click.echo("fricli: error: out of memory", err=True)
            ctx.exit(errors.FAILURE)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except Exception as exc:
            if ctx.meta.get("fricli.debug"):
                raise
            first = errors.one_line(str(exc).splitlines()[0]) if str(exc) else ""
            click.echo(f"fricli: internal error: {type(exc).__name__}: {first} (run with --debug for details)", err=True)
            ctx.exit(errors.FAILURE)


@click.group(cls=FricliGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, "--version", prog_name="fricli")
def cli() -> None:
    """Friction models for robot joints: identify, train, adapt, predict, diagnose.

    \b
    Example:
      fricli demo -o demo-out
      fricli identify sample_data/joint2_base.parquet -o lugre.npz
      fricli predict lugre.npz sample_data/joint2_extended_asym.parquet -o pred.parquet

    Logs are Parquet files (docs/log-format.md); models are .npz files (docs/model-format.md).
    Use - for stdin/stdout to chain commands in a pipeline.
    """


# Each module adds its commands to ``cli``.
from fricli.cli import demo, evaluate, inspect_cmd  # noqa: E402,F401
from fricli.cli import neural  # noqa: E402,F401
from fricli.cli import simulate  # noqa: E402,F401
from fricli.cli import lugre, predict  # noqa: E402,F401
from fricli.cli import diagnose  # noqa: E402,F401
from fricli.cli import robot  # noqa: E402,F401
from fricli.cli import export  # noqa: E402,F401
from fricli.cli import fleet  # noqa: E402,F401


def main() -> None:
    cli(prog_name="fricli")
