"""Exit codes and the exceptions that map onto them.

Library code raises a ``FricliError`` subclass; the CLI turns it into one line on
stderr and its exit code. ``TABLE`` is the one list of exit codes (code, name, meaning): the
``--help`` texts and docs/exit-codes.md (written by tools/docs/make_exit_codes.py) come from it, and
tests/test_exit_codes.py checks every code the docs and ``--help`` texts mention against it, and
each row against the constant of its name.
"""

from __future__ import annotations

import dataclasses
import re

# The codes; TABLE below says what each means.
OK = 0
FAILURE = 1
USAGE = 2
INPUT = 3
MODEL = 4
FIT = 5
DATA = 6
OUTPUT = 7
LOCKED = 8
UNCHANGED = 9
DEPENDENCY = 10
SOME_FAILED = 11
NOTHING_RAN = 12
WEAR = 13
INTERRUPTED = 130
TERMINATED = 143


@dataclasses.dataclass(frozen=True)
class ExitCode:
    """One exit code: ``summary`` is plain text for ``--help``, ``meaning`` Markdown for the docs."""

    code: int
    name: str
    summary: str
    meaning: str


TABLE: tuple[ExitCode, ...] = (
    ExitCode(OK, "OK", "success", "success"),
    ExitCode(FAILURE, "FAILURE", "internal error (a bug): rerun with --debug",
             "an unexpected internal error (please report it with the `--debug` output)"),
    ExitCode(USAGE, "USAGE", "bad options or arguments",
             "bad options or arguments (click's own code; used for nothing else)"),
    ExitCode(INPUT, "INPUT", "a log that cannot be read or breaks the log contract",
             "a log cannot be read or breaks the [log contract](log-format.md); `--joint` that the log "
             "does not hold, or on a log without a `joint` column; several joints where one is needed "
             "([joints](joints.md)); for `fricli import`: a recording with fewer than 3 usable rows or with time "
             "going back, or a [mapping](robot-import.md) file that is missing or wrong (no `--mapping` at all: 2 (USAGE)); "
             "a thresholds file (`--thresholds`) that is missing, not one of `fricli thresholds` or of another version, "
             "without a threshold for a joint of the log, or calibrated on the other observer form (`--urdf`); "
             "`fricli trend` on a folder that is not a fleet history"),
    ExitCode(MODEL, "MODEL", "a model file that cannot be loaded or does not fit the log",
             "a model file cannot be loaded (missing, truncated, not a fricli model, unknown version, "
             "pickled content) or does not fit the log: other units, or fitted on another joint than the "
             "rows it is applied to; a model folder without a model for a joint of the log "
             "([joints](joints.md)); a URDF that cannot be loaded or does not match the log's joints "
             "(`--urdf`)"),
    ExitCode(FIT, "FIT", "a fit or training run failed; the previous model is kept",
             "fitting or training failed (non-finite loss, optimiser failure); the previous model is "
             "left in place"),
    ExitCode(DATA, "DATA", "the log holds too little for the job (too short, no motion)",
             "a valid log holds too little for the job (too short, no motion, no samples in one "
             "direction) or lacks a robot-model column it needs (`tau_g`, `tau_dyn`: unknown, not zero; "
             "[log format](log-format.md#robot-model-columns)); for `fricli calibrate`, also a log longer than "
             "the memory available allows (calibrate on part of it with `--from`/`--until`); for `fricli identify`, a "
             "joint with more rows than it fits within its memory limit (identify on part of it with `--from`/`--until`)"),
    ExitCode(OUTPUT, "OUTPUT", "an output could not be written",
             "an output could not be written (missing folder, disk full, permissions, stdout closed by the command "
             "reading it)"),
    ExitCode(LOCKED, "LOCKED", "another job holds the lock on the output",
             "another job holds the lock on the same output; for `fleet`, another run of the same manifest"),
    ExitCode(UNCHANGED, "UNCHANGED", "--if-changed: the output is up to date, nothing was done",
             "`--if-changed`: the model was made from the same log bytes, the same options and the "
             "same input models; nothing was done"),
    ExitCode(DEPENDENCY, "DEPENDENCY", "an optional dependency is not installed",
             "an optional dependency is not installed (e.g. `--urdf` needs Pinocchio: "
             "`pip install 'fricli[robot]'`)"),
    ExitCode(SOME_FAILED, "SOME_FAILED", "fleet: some jobs failed, the others are ok or unchanged",
             "`fleet`: some jobs failed (each with its reason in the table); the others are ok or "
             "unchanged"),
    ExitCode(NOTHING_RAN, "NOTHING_RAN", "fleet: nothing could run",
             "`fleet`: nothing could run: the manifest is unusable or matches no log, Dask is not "
             "installed, the scheduler cannot be reached, or every job failed"),
    ExitCode(WEAR, "WEAR", "trend: at least one joint is flagged for wear",
             "`trend`: at least one joint is flagged for wear (see [fleet.md](fleet.md#wear-trends))"),
    ExitCode(INTERRUPTED, "INTERRUPTED", "interrupted (Ctrl-C)", "interrupted (Ctrl-C, SIGINT)"),
    ExitCode(TERMINATED, "TERMINATED", "terminated (SIGTERM)",
             "terminated by SIGTERM (`kill`, `timeout`, a service manager stopping the job); like 130, "
             "nothing half-written is left"),
)
BY_CODE = {row.code: row for row in TABLE}
BY_NAME = {row.name: row for row in TABLE}


def cite(code: int) -> str:
    """``code`` as the docs and ``--help`` texts write it: ``"11 (SOME_FAILED)"``."""
    return f"{code} ({BY_CODE[code].name})"


def cite_codes(f):
    """Decorator: ``{NAME}`` in ``f``'s docstring (its ``--help``) becomes ``cite(NAME)``."""
    f.__doc__ = re.sub(r"\{([A-Z_]+)\}", lambda m: cite(BY_NAME[m[1]].code), f.__doc__)
    return f


def help_table() -> str:
    """Every exit code, one per line, for a ``--help`` epilog (click keeps the lines: ``\\b``)."""
    width = max(len(row.name) for row in TABLE)
    lines = [f"  {row.code:>3} {row.name:<{width}}  {row.summary}" for row in TABLE]
    return "\b\nExit codes (docs/exit-codes.md):\n" + "\n".join(lines)


def one_line(text: str) -> str:
    """``text`` as one printable line: line breaks and terminal escapes that a message quotes from
    a file (a joint name, a unit) are shown escaped."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every clean-up that runs for an interruption runs."""


class FricliError(Exception):
    """Base class: a clear, user-facing error with an exit code."""

    exit_code = FAILURE


class LogError(FricliError):
    exit_code = INPUT


class InvalidRows(LogError):
    """Rows with missing, NaN, infinite or absurd values, refused; ``what`` says so without the
    advice of --drop-invalid (for a command that does not drop rows)."""

    def __init__(self, what: str, advice: str):
        super().__init__(f"{what}; {advice}")
        self.what = what


class NoValidRows(LogError):
    """--drop-invalid left no row of a table (a batch of a log read in batches may be all invalid)."""


class ModelFileError(FricliError):
    exit_code = MODEL


class FitError(FricliError):
    exit_code = FIT


class DataError(FricliError):
    exit_code = DATA


class OutputError(FricliError):
    exit_code = OUTPUT


class LockedError(FricliError):
    exit_code = LOCKED


class MissingDependencyError(FricliError):
    exit_code = DEPENDENCY


class OptionError(FricliError):
    """An option value of the wrong type or out of range, an unknown option, or options that do
    not go together; ``option`` names the option."""

    exit_code = USAGE

    def __init__(self, message: str, option: str = ""):
        super().__init__(message)
        self.option = option
