"""Options shared by several commands, as small decorator stacks."""

from __future__ import annotations

import contextlib
import json
import math
import sys
from typing import Iterator

import click

from fricli import errors, jobs, timewindow
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


def _window_bound(ctx: click.Context, param, value: str | None) -> None:
    if value is not None:
        try:
            ctx.meta.setdefault("fricli.window", {})[param.name] = timewindow.Bound.parse(value)
        except ValueError as exc:
            raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _declare_zero(ctx: click.Context, param, value: bool) -> bool:
    if value:
        ctx.meta.setdefault("fricli.zero", []).append({"no_gravity": "tau_g", "no_dynamics": "tau_dyn"}[param.name])
    return value


def declared_zero() -> tuple[str, ...]:
    """Robot-model columns declared zero by --no-gravity/--no-dynamics (docs/log-format.md)."""
    ctx = click.get_current_context(silent=True)
    return tuple(ctx.meta.get("fricli.zero", ())) if ctx else ()


def log_reading(f):
    """--joint, --kt, --cutoff, --drop-invalid, --no-gravity, --no-dynamics: how a log is read (see
    docs/log-format.md); --from, --until: the rows read (``time_window``, ``read_log``;
    fricli.timewindow)."""
    for name in ("until", "from"):
        f = click.option(f"--{name}", f"time_{name}", metavar="SECONDS|PERCENT%", expose_value=False,
                         callback=_window_bound,
                         help=f"Use only the rows {'from' if name == 'from' else 'before'} this time: seconds of the "
                              "log's t (12.5) or a share of its time span (60%). --until 60% and --from 60% split a "
                              "log in two (docs/tutorial.md).")(f)
    for flag, what in (("--no-dynamics", "tau_dyn (inertia and Coriolis torque) as 0"),
                       ("--no-gravity", "tau_g as 0: the joint carries no gravity load")):
        f = click.option(flag, is_flag=True, expose_value=False, callback=_declare_zero,
                         help=f"When the log has no {what.split(' ')[0]} column, take {what}.")(f)
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


def extrapolation_line(extrapolation: dict | None, joint=None) -> str | None:
    """The stderr line for the rows outside a model's training envelope (None without one);
    ``joint``: the log's joint it is about (named when given)."""
    if extrapolation is None:
        return None
    rows = "rows" if joint is None else f"rows of joint {joint}"
    return (f"{100 * extrapolation['share']:.1f} % of the {rows} ({extrapolation['rows']:,} of "
            f"{extrapolation['of']:,}) lie outside the model's training envelope")


def _json_safe(obj):
    """``obj`` with NaN and infinite floats as None (JSON null): e.g. the MAE over no rows."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    return obj


def emit_json(obj) -> None:
    sys.stdout.write(json.dumps(_json_safe(obj), indent=2, sort_keys=True, allow_nan=False) + "\n")


def progress_enabled(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


def time_window() -> timewindow.Window:
    """The window --from/--until give (an open window without them)."""
    bounds = click.get_current_context().meta.get("fricli.window", {})
    return timewindow.Window(bounds.get("time_from"), bounds.get("time_until"))


def read_log(log: str):
    """(table, sha256) of LOG (- for stdin) with the rows of --from/--until; the sha256 is the
    whole file's (the window is recorded with the options, ``model_job``)."""
    from fricli import logs

    table, digest = logs.read_table(log)
    return timewindow.slice_table(table, time_window(), "stdin" if log == "-" else log), digest


def reading_kwargs(joint, kt, cutoff, drop_invalid) -> dict:
    return {"joint": joint, "kt": kt, "cutoff_hz": cutoff, "drop_invalid": drop_invalid, "warn": warn,
            "zero": declared_zero()}


# Options that do not change the model a command writes (arguments are files: the log is
# recorded by its sha256, input models through ``model_job(inputs=...)``).
_NOT_SHAPING = {"output", "quiet", "as_json", "if_changed", "fix"}


def shaping_defaults(command: str) -> dict:
    """The options of ``command`` that shape the model it writes, at their defaults: the
    ``options`` of the job record the command makes when none is given (see ``model_job``)."""
    from fricli.cli import cli

    ctx = click.Context(cli)
    cmd = cli.get_command(ctx, command)
    return {p.name: p.get_default(ctx) for p in cmd.params
            if isinstance(p, click.Option) and p.expose_value and p.name not in _NOT_SHAPING}


def if_changed_option(f):
    """--if-changed, for commands that write a model (see ``model_job``)."""
    return click.option("--if-changed", is_flag=True,
                        help=f"Do nothing and exit with code {errors.cite(errors.UNCHANGED)} when the output model was "
                             "made from the same log "
                             "bytes (sha256) with the same options and input models (for cron jobs).")(f)


@contextlib.contextmanager
def model_job(output: str, log, *, if_changed: bool, quiet: bool,
              inputs: dict[str, str] | None = None, exit_unchanged: bool = True) -> Iterator[dict | None]:
    """Hold the lock on OUTPUT for the block (LOCKED, exit 8, when another job holds it); with
    --if-changed exit UNCHANGED (9) and touch nothing when OUTPUT is up to date (or, with
    ``exit_unchanged=False``, yield None: one joint of a whole-arm run is skipped).

    Yields the job record (command, shaping options, input model hashes) to save in the
    model's provenance as ``job=``. ``inputs``: name -> path of input model files."""
    ctx = click.get_current_context()
    arguments = {p.name for p in ctx.command.params if isinstance(p, click.Argument)}
    options = {k: v for k, v in ctx.params.items() if k not in _NOT_SHAPING and k not in arguments}
    if time_window():
        options["window"] = time_window().to_json()
    job = jobs.job_record(ctx.command.name, options, inputs)
    with jobs.output_lock(output):
        if if_changed and jobs.up_to_date(output, log.sha256, job):
            same = "options and input models" if inputs else "options"
            say(f"{output} is up to date: made from the same log ({log.sha256[:12]}...) with the same {same}; "
                "nothing to do", quiet)
            if exit_unchanged:
                ctx.exit(errors.UNCHANGED)
            yield None
            return
        yield job


def fit_joints(log: str, output: str, joint, reading: dict, fit_one, *, if_changed: bool, quiet: bool,
               source=None, input_name: str = "model", read=None) -> tuple[dict, bool]:
    """Run ``fit_one(data, out_path, job, model_path)`` for every joint LOG's run covers (the
    joint rule, fricli.joints): one model file at OUTPUT, or one per joint in the folder OUTPUT.

    ``source``: the input models (``joints.Source``) of a command that starts from a model, each
    joint paired with its own; ``read``: (table, sha256) of LOG when already read. Returns
    ({joint: what fit_one returned} for the joints fitted, whether OUTPUT is a folder); exits
    UNCHANGED (9) when --if-changed finds every output up to date."""
    from fricli import logs, modelset

    table, digest = read or read_log(log)
    name = "stdin" if log == "-" else log
    logs.require_robot_model(table.schema, name, reading.get("zero", ()))
    pairs, folder = modelset.plan(logs.joints_of(table, name), joint, output, name, source)
    results: dict = {}
    reading = {k: v for k, v in reading.items() if k != "joint"}

    def work(j):
        data = logs.from_table(table, name=name, sha256=digest, joint=j, **reading)
        out = modelset.path_for(folder, data.joint) if folder else output
        model_path = pairs[j]
        inputs = {input_name: model_path} if model_path else None
        with model_job(out, data, if_changed=if_changed, quiet=quiet, inputs=inputs,
                       exit_unchanged=folder is None) as job:
            if job is not None:
                results[j] = fit_one(data, out, job, model_path)

    modelset.each_joint(list(pairs), work)
    if folder and not results:
        click.get_current_context().exit(errors.UNCHANGED)
    return results, folder is not None


def emit_results(results: dict, folder_run: bool) -> None:
    """One JSON document: the one joint's result, or {"joints": {joint: result}}."""
    if folder_run:
        emit_json({"joints": {str(j): r for j, r in results.items()}})
    elif results:
        emit_json(next(iter(results.values())))
