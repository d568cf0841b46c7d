"""``write_report`` and ``inspect_models``: ``fricli report`` and ``fricli inspect`` as one call each."""

from __future__ import annotations

from typing import Callable

from fricli.estimators.base import LOWPASS, path_arg, reading_of


def write_report(model: str, log: str, output: str, *, lowpass_hz: float | None = None, time_from=None,
                 time_until=None, warn: Callable[[str], None] | None = None, **reading) -> dict:
    """``fricli report MODEL LOG -o OUTPUT``: the figures of the model file or folder ``model`` on
    the log file ``log`` (- for stdin) and an index.html showing them, written into the folder
    ``output`` (a folder model: one report per joint in ``output/joint_<name>/``); ``lowpass_hz``
    [Hz] is --lowpass, ``time_from``/``time_until`` --from/--until, ``reading`` ``read_log``'s
    keywords (joint, kt, cutoff, drop_invalid, no_gravity, no_dynamics); ``warn(line)`` gets the
    notes the command prints. Returns {joint: summary}: the figure files, ``unit`` and the friction
    (and external-torque) errors [Nm] (``mae``, ``rmse``, ``max``). OptionError naming a wrong option."""
    from fricli import models
    from fricli.applying import report
    from fricli.core import logs, modelset
    from fricli.fitting import plan, runs
    from fricli.models import coupled

    r, extra, window = reading_of("report", reading, time_from, time_until, {"lowpass_hz": (LOWPASS, lowpass_hz)})
    kwargs = {"kt": r["kt"], "cutoff_hz": r["cutoff"], "drop_invalid": r["drop_invalid"], "warn": warn,
              "zero": runs.zero(r)}
    model, log, output = (path_arg(value, what, "write_report") for value, what in
                          ((model, "model"), (log, "log"), (output, "output")))
    source = modelset.source(model)
    table, digest = plan.read_log(log, window, warn)
    name = "stdin" if log == "-" else log
    pairs = []
    for j, path in modelset.paired(source, table, name, r["joint"]).items():
        data = logs.from_table(table, name=name, sha256=digest, joint=j, **kwargs)
        coupled.add_partners(coupled.view(models.load(path)[0], j), data, table, **kwargs)
        pairs.append((path, data))
    return report.write_reports(pairs, output, lowpass_hz=extra["lowpass_hz"])


def inspect_models(model: str) -> dict:
    """``fricli inspect MODEL``: what the command prints as JSON. A model file: its meta (kind,
    units, parameters, provenance; ``load_model(path).meta``); a model folder: {"joints": {joint:
    meta}} in the folder's order."""
    from fricli import models
    from fricli.core import modelset

    source = modelset.source(path_arg(model, "model", "inspect_models"))
    metas = {str(joint): models.load(path)[1] for joint, path in source.paths.items()}
    return {"joints": metas} if source.folder else next(iter(metas.values()))
