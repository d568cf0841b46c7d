"""Exit codes and the exceptions that map onto them.

Library code raises a ``FricliError`` subclass; the CLI turns it into one line on
stderr and the exit code below. Click keeps exit code 2 for usage errors.
"""

OK = 0
FAILURE = 1          # unexpected internal error (a bug): reported with --debug
USAGE = 2            # click's own: bad options or arguments
INPUT = 3            # a log that cannot be read or breaks the log contract
MODEL = 4            # a model file that cannot be loaded or does not fit the log
FIT = 5              # a fit or training run that failed (non-finite loss, no convergence)
DATA = 6             # a valid log that holds too little to do the job (no motion, too short)
OUTPUT = 7           # an output that could not be written (disk full, permissions)
LOCKED = 8           # another job holds the lock on the output
UNCHANGED = 9        # --if-changed: the input is unchanged, nothing was done (not an error)
DEPENDENCY = 10      # an optional dependency (an extra such as fricli[robot]) is not installed
SOME_FAILED = 11     # fleet: some jobs failed, the others succeeded or were unchanged
NOTHING_RAN = 12     # fleet: no job could run (unusable manifest, no logs, cluster unreachable, all failed)
WEAR = 13            # trend: at least one joint is flagged for wear


def one_line(text: str) -> str:
    """``text`` as one printable line: line breaks and terminal escapes that a message quotes from
    a file (a joint name, a unit) are shown escaped."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class FricliError(Exception):
    """Base class: a clear, user-facing error with an exit code."""

    exit_code = FAILURE


class LogError(FricliError):
    exit_code = INPUT


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
