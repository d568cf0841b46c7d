"""``fit_joints``: the fitting commands on a whole log, every joint (or coupled group) at once,
as they run with ``-o`` a folder."""

from __future__ import annotations

from typing import Callable

from fricli.estimators.base import window_of
from fricli.fitting import plan
from fricli.fitting.optionspec import OptionError

COMMANDS = ("identify", "train-base", "adapt")


def fit_joints(command: str, log: str, output: str, *, base=None, time_from=None, time_until=None,
               if_changed: bool = False, warn: Callable[[str], None] | None = None, progress: Callable | None = None,
               done: Callable | None = None, **options) -> plan.Run:
    """``fricli COMMAND LOG -o OUTPUT`` (``command``: identify, train-base or adapt; adapt takes its
    input models as ``base``, a model file or a folder with one per joint): one model file at
    ``output`` for a log of one joint (or with ``joint``), else one per joint, or per coupled group
    with ``coupling=True``, in the folder ``output``, the same files as the command writes.
    ``options``: the command's options as keywords (``--no-gravity`` is ``no_gravity=True``);
    ``time_from``, ``time_until``: ``--from``, ``--until``; ``if_changed``: ``--if-changed``;
    ``warn(line)`` receives what the command prints as notes and warnings; ``progress`` and ``done``
    as ``fricli.fitting.plan.fit_log`` takes them (a trainer's progress display, each joint's outcome
    as it ends).

    Returns the run (``plan.Run``): ``outcomes`` (per joint or group: ``label``, ``output``,
    ``made.summary`` the fit figures; ``made`` None for an output left untouched as up to date) and
    ``folder`` (None for one model file). OptionError naming a wrong option; a joint's
    ``FricliError`` does not stop the others (``PartialFailure`` after the rest)."""
    if command not in COMMANDS:
        raise OptionError(f"command: expected one of {', '.join(COMMANDS)} (diagnose: fricli.diagnose_arm), "
                          f"not {command!r}", "command")
    if (base is None) != (command != "adapt"):
        raise OptionError("base: adapt takes the input models as base, and only adapt" if base is not None
                          else "base: adapt needs the input models (a model file or folder)", "base")
    return plan.fit_log(command, log, output, options, inputs=base, window=window_of(command, time_from, time_until),
                        if_changed=if_changed, warn=warn, progress=progress, done=done)
