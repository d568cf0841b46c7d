"""Options shared by several commands, as small decorator stacks."""

from __future__ import annotations

import functools
import math
import os
import sys

import click

from fricli.core import errors, jsontext, timewindow


class Number(click.FloatRange):
    """A finite float, optionally within bounds: nan and inf are refused as USAGE like any bad
    option value (click's float and FloatRange accept them)."""

    name = "float"

    def __init__(self, min=None, max=None, min_open=False, max_open=False):
        super().__init__(min=min, max=max, min_open=min_open, max_open=max_open)

    def _describe_range(self) -> str:
        return "" if self.min is None and self.max is None else super()._describe_range()

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


class Cutoff(Number):
    """A low-pass cut-off [Hz] above 0, or ``auto`` (``fricli.core.logs.AUTO_CUTOFF``)."""

    name = "cutoff"

    def __init__(self):
        super().__init__(min=0, min_open=True)

    def convert(self, value, param, ctx):
        from fricli.core.logs import AUTO_CUTOFF

        if isinstance(value, str) and value.strip().lower() == AUTO_CUTOFF:
            return AUTO_CUTOFF
        return super().convert(value, param, ctx)


class Folder(click.Path):
    """An output folder: "-" (stdout) is refused, not taken as a folder's name."""

    def __init__(self):
        super().__init__(file_okay=False)

    def convert(self, value, param, ctx):
        if value == "-":
            self.fail("this output is a folder: stdout (-) cannot take it; give a folder name", param, ctx)
        return super().convert(value, param, ctx)


def _set_debug(ctx: click.Context, _param, value: bool) -> bool:
    if value:
        ctx.meta["fricli.debug"] = True
    return value


OUTPUTS = {"output": "-o", "report_file": "--report"}   # the parameters that name a file a command writes


def _paths(value) -> list[str]:
    """The existing files and folders a parameter's value names (a path, a NAME=PATH, or several)."""
    if isinstance(value, (list, tuple)):
        return [p for v in value for p in _paths(v)]
    if not isinstance(value, str) or value == "-":
        return []
    return [p for p in dict.fromkeys((value, value.partition("=")[2])) if p and os.path.exists(p)]


def _stdin_uses(value) -> int:
    if isinstance(value, (list, tuple)):
        return sum(_stdin_uses(v) for v in value)
    return int(isinstance(value, str) and (value == "-" or value.endswith("=-")))


def check_paths(params: dict) -> None:
    """Refuse (USAGE) an output that names one of the command's input files, or another output
    (writing it would destroy what the command reads), and stdin (-) named as more than one input."""
    if sum(_stdin_uses(v) for n, v in params.items() if n not in OUTPUTS) > 1:
        raise click.UsageError("stdin (-) can be read only once: give at most one input as -")
    outputs = {name: params[name] for name in OUTPUTS if isinstance(params.get(name), str) and params[name] != "-"}
    if len({os.path.abspath(p) for p in outputs.values()}) < len(outputs):
        raise click.UsageError(f"{' and '.join(OUTPUTS[n] for n in outputs)} name the same file: choose two")
    for name, path in outputs.items():
        if not os.path.exists(path):
            continue
        others = [(n, v) for n, v in params.items() if n != name]
        for other, value in others:
            for found in _paths(value):
                if os.path.samefile(found, path):
                    what = OUTPUTS.get(other) or other.upper()
                    raise click.UsageError(f"{OUTPUTS[name]} {path} is also {what} {found}: it would be overwritten; "
                                           "choose another output")


def common(f):
    """--quiet and --debug; the paths checked (``check_paths``); an ``OptionError`` of the Python
    call that names an option of the command is click's usage error on it (2 (USAGE))."""

    command = f

    @functools.wraps(command)
    def checked(**params):
        from fricli.fitting.optionspec import OptionError

        check_paths(params)
        try:
            return command(**params)
        except OptionError as exc:
            ctx = click.get_current_context()
            named = {p.name: p for p in ctx.command.params if isinstance(p, click.Option)}
            if exc.option not in named:
                raise
            raise click.BadParameter(str(exc), ctx=ctx, param=named[exc.option]) from None

    f = checked
    f = click.option("--debug", is_flag=True, expose_value=False, is_eager=True, callback=_set_debug,
                     help="Show the full traceback on errors.")(f)
    f = click.option("-q", "--quiet", is_flag=True, help="No progress bars or messages on stderr (warnings and errors still go there).")(f)
    return f


def _window_bound(ctx: click.Context, param, value: str | None):
    if value is None:
        return None
    try:
        return timewindow.Bound.parse(value)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def window_options(f):
    """--from, --until: the rows read, given to the command as ``window`` (a
    ``fricli.core.timewindow.Window``; open without them)."""
    command = f

    @functools.wraps(command)
    def windowed(*args, time_from=None, time_until=None, **params):
        return command(*args, window=timewindow.Window(time_from, time_until), **params)

    f = windowed
    for name in ("until", "from"):
        f = click.option(f"--{name}", f"time_{name}", metavar="SECONDS|PERCENT%", callback=_window_bound,
                         help=f"Use only the rows {'from' if name == 'from' else 'before'} this time: seconds of the "
                              "log's t (12.5) or a share of its time span (60%). --until 60% and --from 60% split a "
                              "log in two (docs/tutorial.md).")(f)
    return f


def log_reading(f):
    """--joint, --kt, --cutoff, --drop-invalid, --no-gravity, --no-dynamics: how a log is read (see
    docs/log-format.md); the robot-model columns declared zero are given to the command as
    ``zero`` (a tuple of column names); --from, --until as ``window`` (``window_options``)."""
    from fricli.fitting.optionspec import READING, ZERO_FLAGS

    f = robot_model_flags(f)
    for opt in reversed([opt for opt in READING if opt.name not in ZERO_FLAGS]):
        f = _click_option(opt)(f)
    return window_options(f)


def robot_model_flags(f):
    """--no-gravity, --no-dynamics alone (log_reading's flags): the robot-model columns declared
    zero, given to the command as ``zero`` (a tuple of column names)."""
    from fricli.fitting.optionspec import READING, ZERO_FLAGS

    command = f

    @functools.wraps(command)
    def declared(*args, **params):
        return command(*args, zero=tuple(column for flag, column in ZERO_FLAGS.items() if params.pop(flag, False)),
                       **params)

    f = declared
    for opt in reversed([opt for opt in READING if opt.name in ZERO_FLAGS]):
        f = click.option(opt.flag, is_flag=True, help=opt.help)(f)
    return f


def zero_keywords(zero: tuple) -> dict:
    """``robot_model_flags``' ``zero`` as the library's keywords: {"no_gravity": bool, "no_dynamics": bool}."""
    from fricli.fitting.optionspec import ZERO_FLAGS

    return {flag: column in zero for flag, column in ZERO_FLAGS.items()}


def json_flag(f):
    return click.option("--json", "as_json", is_flag=True, help="Print the result as JSON on stdout.")(f)


def output_option(required: bool = True, help: str = "Output file (- for stdout)."):
    return click.option("-o", "--output", required=required, help=help)


def check_outputs(output: str, as_json: bool) -> None:
    """-o - (the model on stdout) and --json cannot share stdout."""
    if output == "-" and as_json:
        raise click.UsageError("-o - and --json both write to stdout: choose one")


def wrote(output: str) -> str:
    return "wrote the model to stdout" if output == "-" else f"wrote {output}"


def say(message, quiet: bool = False) -> None:
    """A message for people: stderr, unless --quiet."""
    if not quiet:
        click.echo(_printable(message), err=True)


def warn(message) -> None:
    """Warnings always reach stderr, each line once per command (a note about a file is not
    repeated for each joint read from it)."""
    line = _printable(message)
    ctx = click.get_current_context(silent=True)
    if ctx is not None:
        seen = ctx.find_root().meta.setdefault("fricli.warned", set())
        if line in seen:
            return
        seen.add(line)
    click.echo(line, err=True)


def _printable(message: str) -> str:
    """``message`` with what it quotes from a file (a joint name holding a line break, a terminal
    escape) escaped: each message is one line; a message of several lines is given as a list."""
    from fricli.core.errors import one_line

    if isinstance(message, (list, tuple)):
        return "\n".join(one_line(str(m)) for m in message)
    return one_line(str(message))


def extrapolation_line(extrapolation: dict | None, joint=None) -> str | None:
    """The stderr line for the rows outside a model's training envelope (None without one);
    ``joint``: the log's joint it is about (named when given)."""
    if extrapolation is None:
        return None
    rows = "rows" if joint is None else f"rows of joint {joint}"
    return (f"{100 * extrapolation['share']:.1f} % of the {rows} ({extrapolation['rows']:,} of "
            f"{extrapolation['of']:,}) lie outside the model's training envelope")


def emit_json(obj) -> None:
    sys.stdout.write(jsontext.dumps(obj))


def progress_enabled(quiet: bool) -> bool:
    return not quiet and sys.stderr.isatty()


LOWPASS_HELP = ("Zero-phase Butterworth low-pass (4th order) of the external-torque estimate tau_ext_pred at this "
                "cut-off [Hz], one period of it within the log at least; default: none (5 smooths it).")


def read_log(log: str, window: timewindow.Window | None = None):
    """(table, sha256) of LOG (- for stdin) with the rows of ``window`` (--from/--until); the
    sha256 is the whole file's (the window is recorded with the options)."""
    from fricli.fitting import plan

    return plan.read_log(log, window, warn)


def reading_kwargs(joint, kt, cutoff, drop_invalid, zero=()) -> dict:
    return {"joint": joint, "kt": kt, "cutoff_hz": cutoff, "drop_invalid": drop_invalid, "warn": warn,
            "zero": tuple(zero)}


# Options that do not change the model a command writes (arguments are files: the log is
# recorded by its sha256, input models by theirs, ``fricli.fitting.runs.record``).
# The window (--from/--until) is recorded apart, as ``window``.
_NOT_SHAPING = {"output", "quiet", "as_json", "if_changed", "fix", "time_from", "time_until"}


def _click_option(opt):
    """A click option from a ``fricli.fitting.optionspec.Option``."""
    from fricli.fitting import optionspec

    kwargs = {"help": opt.help, "metavar": opt.metavar}
    if opt.type == "flag":
        return click.option(opt.flag, is_flag=True, help=opt.help)
    if opt.type == "choice":
        kwargs["type"] = click.Choice(list(opt.choices))
    elif opt.type == "sizes":
        def sizes(_ctx, _param, value):
            parsed = None if value is None else optionspec.parse_sizes(value)
            if value is not None and parsed is None:
                raise click.BadParameter(f"expected {opt.expects()}, got {value!r}")
            return parsed

        kwargs["callback"] = sizes
        default = None if opt.default is None else ",".join(map(str, opt.default))
        return click.option(opt.flag, default=default, show_default=default is not None, **kwargs)
    elif opt.type in ("float", "int"):
        bounded = opt.low is not None or opt.high is not None
        if opt.type == "float":
            kwargs["type"] = (Number(min=opt.low, max=opt.high, min_open=opt.low_open) if bounded
                              else Number())
        else:
            kwargs["type"] = click.IntRange(min=opt.low, max=opt.high) if bounded else int
    return click.option(opt.flag, default=opt.default, show_default=opt.default is not None, **kwargs)


def spec_option(opt):
    """The click option of one ``fricli.fitting.optionspec.Option``."""
    return _click_option(opt)


def spec_options(pipeline: str):
    """The click options of ``pipeline``'s model-shaping options (``fricli.fitting.optionspec.PIPELINES``)."""
    from fricli.fitting import optionspec

    def decorate(f):
        for opt in reversed(optionspec.PIPELINES[pipeline]):
            f = _click_option(opt)(f)
        return f

    return decorate


def if_changed_option(f):
    """--if-changed, for commands that write a model (see ``fit_joints``)."""
    return click.option("--if-changed", is_flag=True,
                        help=f"Do nothing and exit with code {errors.cite(errors.UNCHANGED)} when the output model was "
                             "made from the same log "
                             "bytes (sha256) with the same options and input models (for cron jobs).")(f)


def command_options(pipeline: str) -> dict:
    """The options of the running command that shape the model ``pipeline`` writes
    (``fricli.fitting.runs.options``; a wrong combination is a usage error on the option it names)."""
    from fricli.fitting import optionspec, runs

    ctx = click.get_current_context()
    arguments = {p.name for p in ctx.command.params if isinstance(p, click.Argument)}
    given = {k: v for k, v in ctx.params.items() if k not in _NOT_SHAPING | arguments
             and not (k in optionspec.ZERO_FLAGS and not v)}   # a column declared zero is recorded, others not
    try:
        return runs.options(pipeline, given)
    except optionspec.OptionError as exc:
        raise bad_parameter(exc, message=str(exc).split(": ", 1)[-1]) from None


def bad_parameter(exc, flags: dict | None = None, message: str | None = None) -> click.BadParameter:
    """A Python call's ``OptionError`` as click's error on the option it names: --name-with-dashes,
    or ``flags[name]`` where the command line spells it otherwise; ``message`` (default: the error's)."""
    flag = (flags or {}).get(exc.option, "--" + exc.option.replace("_", "-"))
    return click.BadParameter(str(exc) if message is None else message, param_hint=flag)


def up_to_date_line(out: str, digest: str, inputs: bool) -> str:
    same = "options and input models" if inputs else "options"
    return f"{out} is up to date: made from the same log ({digest[:12]}...) with the same {same}; nothing to do"


def fit_joints(pipeline: str, log: str, output: str, report, *, window: timewindow.Window, if_changed: bool,
               quiet: bool, source=None, progress=None, report_group=None) -> tuple[dict, bool]:
    """Make ``pipeline``'s models with the command's options (``fricli.estimators.whole_log.fit_joints``)
    and report each (``window``: --from/--until): ``report(made)`` prints a joint's model and returns its
    JSON result, ``report_group(made, label)`` a coupled group's (--coupling). ``source``: the input
    models of adapt; ``progress``: the trainers' progress display.

    Returns ({joint or group label: result} for the models written, whether OUTPUT is a
    folder). An up-to-date output (--if-changed) is said and left untouched; exits UNCHANGED
    (9) when every output is up to date. LOCKED (8) when another job holds an output."""
    from fricli.estimators import whole_log

    results: dict = {}

    def done(outcome) -> None:
        if outcome.unchanged:
            say(up_to_date_line(outcome.output, outcome.digest, outcome.base is not None), quiet)
        elif outcome.group:
            results[outcome.label] = report_group(outcome.made, outcome.label)
        else:
            results[outcome.label] = report(outcome.made)

    run = whole_log.fit_joints(pipeline, log, output, base=source, time_from=window.start, time_until=window.stop,
                               if_changed=if_changed, warn=warn, progress=progress, done=done,
                               **command_options(pipeline))
    if run.unchanged:
        click.get_current_context().exit(errors.UNCHANGED)
    return results, run.folder is not None


def emit_results(results: dict, folder_run: bool) -> None:
    """One JSON document: the one joint's result, or {"joints": {joint: result}}."""
    if folder_run:
        emit_json({"joints": {str(j): r for j, r in results.items()}})
    elif results:
        emit_json(next(iter(results.values())))
