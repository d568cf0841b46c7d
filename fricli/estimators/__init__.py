"""fricli as a library: the commands that make a model as estimators in the scikit-learn shape.

An estimator takes its options as keyword arguments, stored as given (the names, defaults and
checks of the command's options, ``fricli.fitting.optionspec``); ``fit(log)`` fits it and returns
it; its fitted attributes end in ``_`` (``model_``, ``summary_``); ``predict(log)`` gives the
friction [Nm or N] (n,); ``save(path)`` writes the model file the command writes with the same
options on the same log (``fricli.fitting.runs``). ``log``: a ``read_log`` result or a log file's
path (read as the commands read it). See docs/python-api.md.
"""

from fricli.estimators.base import Model, NotFittedError, external_torque, load_model, read_log
from fricli.estimators.calibration import Calibration, identify_payload
from fricli.estimators.evaluating import Evaluation, evaluate
from fricli.estimators.jobs import GMS, Diagnosis, Linear, LuGre, Network, Residual

__all__ = ["read_log", "load_model", "external_torque", "Model", "NotFittedError", "LuGre", "Linear", "GMS",
           "Network", "Residual", "Diagnosis", "Calibration", "identify_payload",
           "evaluate", "Evaluation"]
