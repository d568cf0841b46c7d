"""``predict_file``: ``fricli predict`` and ``fricli estimate-ext`` from file to file as one call."""

from __future__ import annotations

from typing import Callable

from fricli.estimators.base import LOWPASS, path_arg, reading_of
from fricli.fitting import optionspec, runs

BATCH_ROWS = optionspec.Option("batch_rows", "int", None, "Rows per record batch.", low=1)
PRECISION = optionspec.Option("precision", "choice", "single", "Arithmetic of the networks.",
                              choices=("single", "double"))


def predict_file(model: str, log: str, output: str, *, external: bool = False, lowpass_hz: float | None = None,
                 flag_extrapolation: bool = False, precision: str = "single", batch_rows: int | None = None,
                 time_from=None, time_until=None, warn: Callable[[str], None] | None = None,
                 on_rows: Callable[[int, int], None] | None = None, **reading):
    """``fricli predict MODEL LOG -o OUTPUT`` (with ``external``: ``fricli estimate-ext``): the log
    file ``log`` (- for stdin) with tau_f_pred (and tau_ext_pred, low-passed at ``lowpass_hz`` [Hz])
    added, written to ``output`` (- for stdout) in record batches of ``batch_rows`` rows with the
    model state carried across. ``model`` is a model file or folder; ``precision`` "single" or
    "double" (the networks' arithmetic); ``time_from``/``time_until`` are --from/--until and
    ``reading`` ``read_log``'s keywords (joint, kt, cutoff, drop_invalid, no_gravity, no_dynamics);
    ``warn(line)`` gets the notes the command prints, ``on_rows(rows, total)`` the progress. Returns
    the run's ``fricli.applying.predicting.Result`` (rows, the friction and external-torque errors
    [Nm], per joint; ``as_json()`` what ``--json`` prints). OptionError naming a wrong option."""
    from fricli import models
    from fricli.applying import predicting
    from fricli.core import modelset

    r, extra, window = reading_of("predict", reading, time_from, time_until,
                                  {"lowpass_hz": (LOWPASS, lowpass_hz), "precision": (PRECISION, precision),
                                   "batch_rows": (BATCH_ROWS, batch_rows)})
    if extra["lowpass_hz"] is not None and not external:
        raise optionspec.OptionError("lowpass_hz applies to the external torque (external=True)", "lowpass_hz")

    def load(path):
        loaded, meta = models.load(path)
        return models.set_precision(loaded, extra["precision"]), meta

    read = predicting.Reading(joint=r["joint"], kt=r["kt"], cutoff_hz=r["cutoff"], drop_invalid=r["drop_invalid"],
                              window=window, batch_rows=extra["batch_rows"] or predicting.DEFAULT_BATCH_ROWS,
                              zero=runs.zero(r))
    outputs = predicting.Outputs(external=external, lowpass_hz=extra["lowpass_hz"],
                                 flag_extrapolation=flag_extrapolation)
    model, log, output = (path_arg(value, what, "predict_file") for value, what in
                          ((model, "model"), (log, "log"), (output, "output")))
    return predicting.run_models(modelset.source(model), log, output, reading=read, outputs=outputs, warn=warn,
                                 on_rows=on_rows, load=load)
