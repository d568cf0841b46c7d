"""``evaluate``: ``fricli evaluate`` as one call (every model on every log, friction and
external-torque errors)."""

from __future__ import annotations

import dataclasses

from fricli.estimators.base import LOWPASS, path_arg, reading_of
from fricli.fitting import optionspec, runs


@dataclasses.dataclass
class Evaluation:
    """What ``evaluate`` found: ``results`` (a ``fricli.applying.evaluation.Result`` per model, log
    and joint: ``friction``, ``external``, ``moving``, ``extrapolation``, ...), the ``models`` and
    ``logs`` evaluated ({name: path}) and ``lowpass_hz``."""

    results: list
    models: dict
    logs: dict
    lowpass_hz: float | None

    def to_json(self) -> dict:
        """What ``fricli evaluate --json`` prints."""
        from fricli.applying import evaluation

        return evaluation.to_json(self.results, self.models, self.logs, self.lowpass_hz)

    def markdown(self) -> str:
        """The table ``fricli evaluate`` prints."""
        from fricli.applying import evaluation

        return evaluation.markdown_table(self.results, list(self.models), list(self.logs))


def evaluate(models: dict, logs: dict, *, lowpass_hz: float | None = None, time_from=None, time_until=None, warn=None,
             **reading) -> Evaluation:
    """``fricli evaluate --model NAME=MODEL ... --log NAME=LOG ...``: ``models`` and ``logs`` are
    {name: path} (a model file or a model folder; a Parquet log), ``lowpass_hz`` [Hz] is --lowpass,
    ``time_from``/``time_until`` are --from/--until, ``reading`` are ``read_log``'s keywords (joint,
    kt, cutoff, drop_invalid, no_gravity, no_dynamics); ``warn(line)`` gets the notes the command
    prints. OptionError naming a wrong option; the command's errors for a log or model it cannot use."""
    from fricli.applying import evaluation
    from fricli.fitting import plan

    r, extra, window = reading_of("evaluate", reading, time_from, time_until, {"lowpass_hz": (LOWPASS, lowpass_hz)})
    lowpass_hz = extra["lowpass_hz"]
    read_kwargs = {"joint": r["joint"], "kt": r["kt"], "cutoff_hz": r["cutoff"], "drop_invalid": r["drop_invalid"],
                   "warn": warn, "zero": runs.zero(r)}
    for what, given in (("models", models), ("logs", logs)):
        if not isinstance(given, dict):
            raise optionspec.OptionError(f"evaluate: {what} must be a dict {{name: file path}}, not "
                                         f"{type(given).__name__}", what)
    model_paths = {str(k): path_arg(v, "models", "evaluate") for k, v in models.items()}
    log_paths = {str(k): path_arg(v, "logs", "evaluate") for k, v in logs.items()}
    results = evaluation.evaluate(model_paths, log_paths, lowpass_hz=lowpass_hz, read_kwargs=read_kwargs,
                                  read=lambda path: plan.read_log(path, window, warn))
    return Evaluation(results, model_paths, log_paths, lowpass_hz)
