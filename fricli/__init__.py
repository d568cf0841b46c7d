"""fricli: friction models for robot joints.

The library (docs/python-api.md): ``read_log`` reads a log as the commands do, the estimators
(``LuGre``, ``Linear``, ``GMS``, ``Network``, ``Residual``, ``Diagnosis``, ``Calibration``) fit
what the commands fit, ``load_model`` reads a model file, ``fit_arm`` runs ``fricli fit-arm``,
``diagnose_arm`` runs ``fricli diagnose`` on a log's models (``--fix``, ``--calibrate``),
``identify_payload`` runs ``fricli payload``, ``evaluate`` runs ``fricli evaluate``, ``import_log``
runs ``fricli import``, ``add_dynamics`` runs ``fricli dynamics``,
``calibrate_thresholds`` and ``replay_log`` run ``fricli thresholds`` and ``fricli replay``,
``export_header`` runs ``fricli export``, ``predict_file`` runs ``fricli predict`` and
``fricli estimate-ext`` from file to file, ``write_report`` runs ``fricli report``,
``inspect_models`` ``fricli inspect``, ``simulate_log`` ``fricli simulate``, ``run_fleet`` and
``fleet_trend`` run ``fricli fleet`` and ``fricli trend``, ``run_demo`` runs ``fricli demo``,
``fit_joints`` runs ``fricli identify``, ``train-base`` and ``adapt`` on every joint of a log.
The names are imported on first use, so ``import fricli`` stays cheap.
"""

__version__ = "0.2.0"

__all__ = ["read_log", "load_model", "external_torque", "LuGre", "Linear", "GMS", "Network", "Residual",
           "Diagnosis", "Calibration", "Model", "NotFittedError", "FricliError", "OptionError", "fit_arm",
           "diagnose_arm", "identify_payload", "evaluate", "Evaluation", "import_log", "add_dynamics",
           "calibrate_thresholds", "replay_log", "export_header", "predict_file",
           "write_report", "inspect_models", "simulate_log", "run_fleet", "fleet_trend", "run_demo",
           "fit_joints", "__version__"]

_FROM = {"FricliError": "fricli.core.errors", "OptionError": "fricli.fitting.optionspec", "fit_arm": "fricli.arm",
         "diagnose_arm": "fricli.arm_diagnosis", "import_log": "fricli.robot.importing",
         "add_dynamics": "fricli.robot.logterms", "calibrate_thresholds": "fricli.robot.replay",
         "replay_log": "fricli.robot.replay", "export_header": "fricli.export.header",
         "predict_file": "fricli.estimators.prediction", "write_report": "fricli.estimators.reporting",
         "inspect_models": "fricli.estimators.reporting", "simulate_log": "fricli.sim.writing",
         "run_fleet": "fricli.fleet.run", "fleet_trend": "fricli.fleet.trend", "run_demo": "fricli.demo",
         "fit_joints": "fricli.estimators.whole_log"}


def __getattr__(name: str):
    if name in __all__:
        import importlib

        value = getattr(importlib.import_module(_FROM.get(name, "fricli.estimators")), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'fricli' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
