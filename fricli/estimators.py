"""fricli as a library: the commands that make a model as estimators in the scikit-learn shape.

An estimator takes its options as keyword arguments, stored as given (the names, defaults and
checks of the command's options, ``fricli.fitting.optionspec``); ``fit(log)`` fits it and returns
it; its fitted attributes end in ``_`` (``model_``, ``summary_``); ``predict(log)`` gives the
friction [Nm or N] (n,); ``save(path)`` writes the model file the command writes with the same
options on the same log (``fricli.fitting.runs``). ``log``: a ``read_log`` result or a log file's
path (read as the commands read it). See docs/python-api.md.
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import os

import numpy as np

from fricli import models
from fricli.core import logs, modelfile, timewindow
from fricli.core.errors import USAGE, DataError, FricliError
from fricli.fitting import optionspec, runs
from fricli.fitting.optionspec import Option, OptionError


class NotFittedError(FricliError):
    """An estimator used before ``fit``."""

    exit_code = USAGE


READING = {o.name: o for o in optionspec.READING}


@dataclasses.dataclass(frozen=True)
class _Custom(Option):
    """An option checked by ``validate(value)`` (the value as used; ValueError naming the option)."""

    validate: object = None

    def check(self, value):
        return self.validate(value)


def _checked(given: dict, spec: dict, who: str) -> dict:
    """``given`` checked against ``spec`` ({name: Option}); OptionError naming the option."""
    out = {}
    for name, value in given.items():
        if name not in spec:
            raise OptionError(f"{who}: unknown option {name!r} (known: {', '.join(sorted(spec))})", name)
        try:
            out[name] = spec[name].check(value)
        except ValueError as exc:
            raise OptionError(f"{who} option {exc}", name) from None
    return out


def read_log(path, *, joint=None, kt=None, cutoff=logs.DEFAULT_CUTOFF_HZ, drop_invalid=False, no_gravity=False,
             no_dynamics=False, time_from=None, time_until=None, warn=None) -> logs.Log:
    """One joint's log from the Parquet file ``path`` ("-": stdin), read as the commands read LOG
    with --joint, --kt [Nm/A], --cutoff [Hz], --drop-invalid, --no-gravity, --no-dynamics, --from
    and --until (``time_from``, ``time_until``: seconds of ``t``, or a share of its span: "60%").
    ``warn(line)`` gets the notes the commands print. ``Log.signals``: float64 arrays (n,)."""
    opts = _checked(dict(joint=joint, kt=kt, cutoff=cutoff, drop_invalid=drop_invalid, no_gravity=no_gravity,
                         no_dynamics=no_dynamics), READING, "read_log")
    bounds = []
    for option, bound in (("time_from", time_from), ("time_until", time_until)):
        try:
            bounds.append(None if bound is None else timewindow.Bound.parse(str(bound)))
        except ValueError as exc:
            raise OptionError(f"read_log option {option}: {exc}", option) from None
    window = timewindow.Window(*bounds)
    name = "stdin" if path == "-" else os.fspath(path)
    table, digest = logs.read_table(name)
    table = timewindow.slice_table(table, window, name, warn=warn)
    data = runs.read(table, digest, name, opts, warn=warn)
    data.window = window.to_json() if window else None
    return data


def _as_log(log, reading: dict | None = None) -> logs.Log:
    """``log`` itself, or the log at the path ``log`` read with ``reading`` (``read_log``'s options)."""
    if isinstance(log, logs.Log):
        return log
    if isinstance(log, (str, os.PathLike)):
        return read_log(log, **(reading or {}))
    raise TypeError(f"log: expected a fricli.read_log result or a path, not {type(log).__name__}")


def _friction(model, data: logs.Log) -> np.ndarray:
    return np.asarray(model.predict(data.signals)[0], dtype=np.float64)


class Model:
    """A model read from a model file (``load_model``): ``model`` the friction model
    (``fricli.models``), ``meta`` its file's meta, ``path`` the file."""

    def __init__(self, model, meta: dict, path: str | None = None):
        self.model, self.meta, self.path = model, meta, path

    @property
    def kind(self) -> str:
        return self.model.kind

    def predict(self, log) -> np.ndarray:
        """The friction [Nm or N] (n,) on ``log`` (a ``read_log`` result or a path)."""
        return _friction(self.model, _as_log(log))

    def save(self, path) -> None:
        """Write the model file again (the same bytes as the file it was read from)."""
        modelfile.write(os.fspath(path), self.meta, models.to_parts(self.model)[1])

    def __repr__(self) -> str:
        return f"Model({self.kind!r}, path={self.path!r})"


def load_model(path) -> Model:
    """The model in the model file ``path`` (.npz); ModelFileError when it is not one."""
    model, meta = models.load(os.fspath(path))
    return Model(model, meta, os.fspath(path))


def external_torque(model, log, lowpass_hz: float | None = None) -> np.ndarray:
    """tau_ext = tau_g + tau_dyn + friction - tau_m [Nm or N] (n,) on ``log`` as ``fricli predict
    --external`` gives it, with ``model`` a ``load_model`` result or a fitted estimator; optionally
    low-passed at ``lowpass_hz`` [Hz] (zero-phase, as --lowpass)."""
    from fricli.applying.predicting import external_estimate

    data = _as_log(log, getattr(model, "reading_", None))
    return external_estimate(data.signals, model.predict(data), lowpass_hz)


class _Params:
    """Parameters stored as given (``_spec``: {name: Option}, checked by the constructor),
    ``get_params``, ``set_params``."""

    _spec: dict = {}
    _positional: str | None = None   # the one parameter given by position (an input: a model, a URDF)

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        params = [inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD)]
        if cls._positional:
            params.append(inspect.Parameter(cls._positional, inspect.Parameter.POSITIONAL_OR_KEYWORD))
        params += [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=o.default)
                   for name, o in cls._spec.items()]

        def __init__(self, *args, **given):
            _Params._set(self, *args, **given)

        __init__.__signature__ = inspect.Signature(params)   # what help() and sklearn's clone() read
        __init__.__doc__ = f"{cls.__name__}'s parameters: " + (
            "; ".join(f"{n}: {o.help}" for n, o in cls._spec.items()) or "none")
        cls.__init__ = __init__

    def _set(self, *args, **params):
        who = type(self).__name__
        if self._positional:
            if len(args) > 1:
                raise TypeError(f"{who} takes one positional argument ({self._positional}), not {len(args)}")
            if args:
                if self._positional in params:
                    raise TypeError(f"{who}: {self._positional} given twice")
                params[self._positional] = args[0]
            if self._positional not in params:
                raise TypeError(f"{who} needs {self._positional}")
            setattr(self, self._positional, params.pop(self._positional))
        elif args:
            raise TypeError(f"{who} takes keyword arguments only")
        _checked(params, self._spec, who)
        self._options(params)   # options that do not go together
        for name, option in self._spec.items():
            setattr(self, name, params.get(name, option.default))

    def get_params(self, deep: bool = True) -> dict:
        """The parameters as given to the constructor."""
        names = ([self._positional] if self._positional else []) + list(self._spec)
        return {name: getattr(self, name) for name in names}

    def set_params(self, **params):
        """Set parameters (checked as the constructor checks them); returns self."""
        merged = {**self.get_params(), **params}
        checked = type(self)(**merged)
        for name, value in checked.get_params().items():
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        given = {k: v for k, v in self.get_params().items()
                 if k == self._positional or v != self._spec[k].default}
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in given.items())})"

    def _options(self, params: dict) -> dict:
        """The job's options from the parameters (and the log's reading options)."""
        return dict(params)



class _Estimator(_Params):
    """A friction model estimator: ``predict`` and ``save`` once ``fit`` set ``model_``, ``meta_``
    (the model file's meta) and ``reading_`` (how the fitted log was read)."""

    def _check_fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet: call fit(log) first")

    def predict(self, log) -> np.ndarray:
        """The friction [Nm or N] (n,) on ``log``; a path is read as the fitted log was read."""
        self._check_fitted()
        return _friction(self.model_, _as_log(log, self.reading_))

    def save(self, path) -> None:
        """Write the model file (.npz) the command writes with the same options on the same log."""
        self._check_fitted()
        modelfile.write(os.fspath(path), self.meta_, models.to_parts(self.model_)[1])

    def _model_bytes(self) -> bytes:
        return modelfile.dumps(self.meta_, models.to_parts(self.model_)[1])


def _spec(pipeline: str, leave_out=()) -> dict:
    return {o.name: o for o in optionspec.PIPELINES[pipeline] if o.name not in (*leave_out, *optionspec.WHOLE_LOG)}


class _Job(_Estimator):
    """An estimator whose fit is one job of ``fricli.fitting.runs`` (identify, train-base, adapt,
    diagnose --fix) on one joint's log."""

    _pipeline = ""

    def _job_options(self, data: logs.Log) -> dict:
        """The job's options (``runs.options``), with the reading options ``data`` was read with."""
        params = {name: getattr(self, name) for name in self._spec}
        return runs.options(self._pipeline, {**self._options(params), **data.reading})

    def _base(self, data: logs.Log):
        return None, None

    def fit(self, log):
        """Fit on ``log`` (a ``read_log`` result or a path); returns self."""
        data = _as_log(log)
        opts = self._job_options(data)
        runs.check_table(data.table, data.name, opts, self._pipeline)
        base, base_path = self._base(data)
        job = runs.record(self._pipeline, opts, data, base_path, data.window)
        if base is not None and base_path is None:   # a model not read from a file: the sha256 of its bytes
            job["inputs"] = {runs.INPUT_NAME[self._pipeline]: hashlib.sha256(base_bytes(self._input())).hexdigest()}
        fitted = runs.fit(self._pipeline, data, opts, base=base)
        meta, _ = runs.file_parts(fitted, data, job)
        self.model_, self.summary_, self.meta_, self.reading_ = fitted.model, fitted.summary, meta, dict(data.reading)
        self._fitted(fitted)
        return self

    def _fitted(self, fitted) -> None:
        pass


class LuGre(_Job):
    """The extended LuGre model (``fricli identify``)."""

    _pipeline = "identify"
    _spec = _spec("identify", leave_out=("kind",))

    def _options(self, params):
        return {**params, "kind": "lugre"}


class Linear(_Job):
    """Fv*qd + Fc*sign(qd) + offset by least squares on the rows in motion (``fricli identify --kind
    linear``); ``asymmetric``: Fv and Fc per direction (--kind linear-asymmetric)."""

    _pipeline = "identify"
    _spec = {"asymmetric": Option("asymmetric", "flag", False, "Fv and Fc per direction.")}

    def _options(self, params):
        return {"kind": "linear-asymmetric" if params.get("asymmetric") else "linear"}


class GMS(_Job):
    """The Generalized Maxwell-slip model (``fricli identify --kind gms``)."""

    _pipeline = "identify"
    _spec = {}

    def _options(self, params):
        return {"kind": "gms"}


class Network(_Job):
    """A neural friction model (``fricli train-base``); the same ``seed`` gives the same model."""

    _pipeline = "train-base"
    _spec = _spec("train-base")

    def _options(self, params):
        opts = dict(params)
        runs.check_train_base(optionspec.check("train-base", opts))
        return opts


def base_bytes(model) -> bytes:
    """The model-file bytes of a fitted estimator or a ``load_model`` result."""
    if isinstance(model, Model):
        return modelfile.dumps(model.meta, models.to_parts(model.model)[1])
    return model._model_bytes()


class _OnModel(_Job):
    """A job on an input model (``_positional``): a path, a ``load_model`` result or a fitted estimator."""

    def _input(self):
        return getattr(self, self._positional)

    def _base(self, data: logs.Log):
        from fricli.models import coupled

        given = self._input()
        if isinstance(given, (str, os.PathLike)):
            base, path = runs.load_base(os.fspath(given), data), os.fspath(given)
        elif isinstance(given, Model):
            path = given.path if given.path and os.path.isfile(given.path) else None
            base = runs.Base(coupled.view(given.model, data.joint), given.meta,
                             os.path.basename(path) if path else None, given.path or "base")
        elif isinstance(given, _Estimator):
            given._check_fitted()
            base, path = runs.Base(coupled.view(given.model_, data.joint), given.meta_, None), None
        else:
            raise TypeError(f"{type(self).__name__}: {self._positional} must be a model file's path, a "
                            f"fricli.load_model result or a fitted estimator, not {type(given).__name__}")
        models.check_log(base.meta, data, base.source)
        missing = [p for p in coupled.partners_read(base.model) if coupled.partner_key(p) not in data.signals]
        if missing:
            raise DataError(f"{data.name}: the {self._positional} model is a coupled group's and reads the velocities "
                            f"of joints {', '.join(missing)}: use the command (fricli {self._pipeline}) on the whole log")
        return base, path


class Residual(_OnModel):
    """``base`` + NN_add, a residual network learned on ``log`` (``fricli adapt``); ``base``: a
    model file's path, a ``load_model`` result or a fitted estimator."""

    _pipeline = "adapt"
    _positional = "base"
    _spec = _spec("adapt")


def _effects(value):
    """--effects as a list of names (None: every effect); ValueError for an unknown one."""
    from fricli.fitting.diagnosis import effects as E

    if value is None:
        return None
    names = [v.strip() for v in value.split(",")] if isinstance(value, str) else list(value)
    names = [n for n in names if n]
    bad = [n for n in names if not isinstance(n, str) or (n not in E.NAMES and n != "column"
                                                            and not n.startswith("column:"))]
    if bad:
        raise ValueError(f"effects = {bad[0]!r}: expected names of {', '.join(E.NAMES)}, column, column:NAME")
    return names or None


def _diagnose_spec() -> dict:
    from fricli.fitting.diagnosis import driver

    return {o.name: o for o in (
        Option("folds", "int", driver.DEFAULT_FOLDS, "Contiguous folds over time for the held-out scores.",
               low=3, high=100),
        Option("min_gain", "float", driver.DEFAULT_MIN_GAIN, "Share of the remaining held-out squared residual "
                                                             "an effect must remove.", low=0, low_open=True, high=1),
        Option("alpha", "float", driver.DEFAULT_ALPHA, "Significance level of the held-out improvement.",
               low=0, low_open=True, high=0.5),
        _Custom("effects", "text", None, "Candidate effects to test, names or comma-separated (default: all).",
                validate=_effects),
        Option("max_effects", "int", None, "Add at most this many effects.", low=0),
        Option("no_carry", "flag", False, "Keep every effect as an added term even when a LuGre base could carry it."),
        Option("accept_implausible", "flag", False, "Add effects whose fitted parameters are out of plausible range."),
    )}


class Diagnosis(_OnModel):
    """Which physical effects ``model`` misses on ``log``, and the model with them (``fricli diagnose
    --fix``): ``diagnosis_`` the ranked effects (``.to_json()``: what diagnose --json prints),
    ``added_`` the effects added, ``model_`` the fixed model (``save``: diagnose --fix's file)."""

    _pipeline = "diagnose"
    _positional = "model"
    _spec = _diagnose_spec()

    def _job_options(self, data: logs.Log) -> dict:
        # the options the diagnose command records (fricli.cli.options.command_options), in its terms
        opts = {name: getattr(self, name) for name in self._spec}
        opts = {**_checked(opts, self._spec, "Diagnosis"), "urdf": None, "calibrated": None,
                "calibrate_friction": None}
        opts["only"] = opts.pop("effects")
        reading = _checked(data.reading, READING, "Diagnosis")
        opts.update({k: reading[k] for k in ("joint", "kt", "cutoff", "drop_invalid")})
        opts.update({flag: True for flag in optionspec.ZERO_FLAGS if reading[flag]})
        return opts

    def _fitted(self, fitted) -> None:
        self.diagnosis_ = fitted.diagnosis
        self.added_ = list(fitted.diagnosis.added)


def _prior(value):
    if value == "auto" or (isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
                           and value > 0):
        return value
    raise ValueError(f"prior = {value!r}: expected auto or a number > 0")


def _gravity(value):
    try:
        if value is None:
            return None
        g = tuple(float(x) for x in value)
        if len(g) == 3 and np.all(np.isfinite(g)):
            return g
    except (TypeError, ValueError):
        pass
    raise ValueError(f"gravity = {value!r}: expected three numbers [m/s^2]")


def _urdf_joints(value):
    if value is None or (isinstance(value, dict) and all(isinstance(v, str) for v in value.values())):
        return value
    raise ValueError(f"urdf_joints = {value!r}: expected {{log joint: URDF joint name}}")


def _calibrate_spec() -> dict:
    return {o.name: o for o in (
        Option("friction", "choice", "linear", "Each joint's friction fitted with the robot model.",
               choices=("linear", "stribeck")),
        _Custom("prior", "text", "auto", "auto, or the prior's strength (a number > 0).", validate=_prior),
        Option("consistency", "choice", "enforce", "enforce: fit again over physically consistent parameters; "
                                                   "check: refuse an inconsistent estimate.",
               choices=("enforce", "check")),
        Option("edge", "float", 0.5, "Seconds left out at each end of every stretch of the log [s].", unit="s", low=0),
        Option("cutoff", "float", None, "Low-pass cut-off [Hz] when qd/qdd are derived from q.", unit="Hz",
               low=0, low_open=True),
        Option("match", "choice", None, "How the log's joints are matched to the URDF's: name or order.",
               choices=("name", "order")),
        _Custom("urdf_joints", "text", None, "{log joint: URDF joint name}.", validate=_urdf_joints),
        _Custom("gravity", "text", None, "Gravity (x, y, z) [m/s^2] in the URDF's base frame (default: the log's, "
                                         "else 0 0 -9.81).", validate=_gravity),
    )}


class Calibration(_Params):
    """The arm's inertial parameters, rotor inertias and each joint's friction from a whole-arm log
    and ``urdf`` (``fricli calibrate``; needs pinocchio): ``report_`` (the command's report),
    ``urdf_text_`` the calibrated URDF (``save``), ``friction_`` {joint: {Fv, Fc, offset, ...}}."""

    _positional = "urdf"
    _spec = _calibrate_spec()

    def _check_fitted(self) -> None:
        if not hasattr(self, "urdf_text_"):
            raise NotFittedError("this Calibration is not fitted yet: call fit(log) first")

    def fit(self, log):
        """Calibrate on the whole-arm log ``log`` (a path); returns self."""
        from fricli.robot import calibration as cb
        from fricli.robot.dynamics import load_model as load_robot
        from fricli.robot.mapping import Mapping

        urdf = os.fspath(self.urdf)
        name = os.fspath(log)
        table, _ = logs.read_table(name)
        gravity = _gravity(self.gravity)
        robot = load_robot(urdf, Mapping(time=None, joints=[], gravity=logs.gravity_of(table.schema, gravity),
                                         held=logs.held_of(table.schema)))
        names = {str(k): v for k, v in self.urdf_joints.items()} if self.urdf_joints else None
        motion = cb.read_motion(table, name, robot, match=self.match or ("name" if names else None), urdf_names=names,
                                cutoff_hz=logs.DEFAULT_CUTOFF_HZ if self.cutoff is None else float(self.cutoff))
        cal = cb.calibrate(robot, motion, prior=self.prior if self.prior == "auto" else float(self.prior),
                           edge_s=float(self.edge), enforce=self.consistency == "enforce", friction=self.friction)
        cb.refuse_inconsistent(cal)
        with open(urdf, encoding="utf-8") as fh:
            self.urdf_text_ = cb.calibrated_urdf(fh.read(), urdf, cal)
        self.calibration_, self.report_ = cal, cal.report
        self.friction_ = cal.report["friction"]["joints"]
        return self

    def save(self, path) -> None:
        """Write the calibrated URDF (the file ``fricli calibrate -o`` writes)."""
        from fricli.core.atomic import atomic_write_bytes

        self._check_fitted()
        atomic_write_bytes(os.fspath(path), self.urdf_text_.encode())
