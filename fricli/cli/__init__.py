"""The ``fricli`` command line. Commands only parse options and format output; the work is
done in library modules. Library errors (``FricliError``) become one line on stderr and
the exit code documented in docs/exit-codes.md; click keeps exit code 2 for usage errors.
"""

from __future__ import annotations

import errno
import importlib
import os
import signal
import sys

import click

from fricli import __version__
from fricli.core import errors


# Every command: name -> "module:function". A command's module is imported only when the
# command runs or its help is shown, so start-up stays fast; registering a command is one line.
COMMANDS = {
    "adapt": "fricli.cli.neural:adapt_cmd",
    "calibrate": "fricli.cli.calibrate:calibrate_cmd",
    "demo": "fricli.cli.demo:demo_cmd",
    "diagnose": "fricli.cli.diagnose:diagnose_cmd",
    "dynamics": "fricli.cli.robot:dynamics_cmd",
    "estimate-ext": "fricli.cli.predict:estimate_ext_cmd",
    "evaluate": "fricli.cli.evaluate:evaluate_cmd",
    "export": "fricli.cli.export:export_cmd",
    "fit-arm": "fricli.cli.arm:fit_arm_cmd",
    "fleet": "fricli.cli.fleet:fleet_cmd",
    "identify": "fricli.cli.lugre:identify_cmd",
    "import": "fricli.cli.robot:import_cmd",
    "inspect": "fricli.cli.inspect_cmd:inspect_model",
    "payload": "fricli.cli.payload:payload_cmd",
    "predict": "fricli.cli.predict:predict_cmd",
    "replay": "fricli.cli.replay:replay_cmd",
    "report": "fricli.cli.evaluate:report_cmd",
    "simulate": "fricli.cli.simulate:simulate_cmd",
    "thresholds": "fricli.cli.replay:thresholds_cmd",
    "train-base": "fricli.cli.neural:train_base",
    "trend": "fricli.cli.fleet:trend_cmd",
}


_OUTPUT_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EBADF)   # writing failed: exit OUTPUT


class FricliGroup(click.Group):
    """Loads each command from ``COMMANDS`` when it is first needed and turns library errors
    into one line on stderr with their exit code."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(COMMANDS) | set(self.commands))

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        if name not in self.commands and name in COMMANDS:
            module, _, attr = COMMANDS[name].partition(":")
            command = getattr(importlib.import_module(module), attr)
            self.commands[name] = command
        return self.commands.get(name)

    def invoke(self, ctx: click.Context):
        try:
            result = super().invoke(ctx)
            if sys.stdout is not None:
                sys.stdout.flush()    # a full disk shows here, not after the exit code is set
            return result
        except errors.FricliError as exc:
            if ctx.meta.get("fricli.debug"):
                raise
            click.echo(f"fricli: error: {errors.one_line(str(exc))}", err=True)
            ctx.exit(exc.exit_code)
        except errors.Terminated:
            click.echo("fricli: terminated", err=True)
            ctx.exit(errors.TERMINATED)
        except KeyboardInterrupt:
            click.echo("fricli: interrupted", err=True)
            ctx.exit(errors.INTERRUPTED)
        except BrokenPipeError:
            # the reader went away (| head): stdout goes to /dev/null, so that the interpreter's
            # last flush at exit raises nothing more
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            click.echo("fricli: error: cannot write to stdout: the command reading it has closed it", err=True)
            ctx.exit(errors.OUTPUT)
        except MemoryError:
            click.echo("fricli: error: out of memory", err=True)
            ctx.exit(errors.FAILURE)
        except (click.exceptions.Exit, click.ClickException, click.Abort):
            raise
        except Exception as exc:
            if ctx.meta.get("fricli.debug"):
                raise
            if isinstance(exc, OSError) and exc.errno in _OUTPUT_ERRNOS:
                click.echo(f"fricli: error: cannot write the output: {exc.strerror}", err=True)
                ctx.exit(errors.OUTPUT)
            first = errors.one_line(str(exc).splitlines()[0]) if str(exc) else ""
            click.echo(f"fricli: internal error: {type(exc).__name__}: {first} (run with --debug for details)", err=True)
            ctx.exit(errors.FAILURE)


@click.group(cls=FricliGroup, context_settings={"help_option_names": ["-h", "--help"]}, epilog=errors.help_table())
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



def _terminate(_signum, _frame):
    raise errors.Terminated()


class _ClosedStdout:
    """Stands in for a closed stdout (``>&-``): writing to it is an output error, not an internal one."""

    def write(self, _data):
        raise OSError(errno.EBADF, "stdout is closed")

    buffer = property(lambda self: self)
    closed = False
    flush = close = lambda self: None   # noqa: E731
    isatty = lambda self: False          # noqa: E731


def main() -> None:
    if sys.stdout is None:
        sys.stdout = _ClosedStdout()
    signal.signal(signal.SIGTERM, _terminate)
    cli(prog_name="fricli")
