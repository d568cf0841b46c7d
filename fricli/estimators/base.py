"""What the estimators share: reading a log as the commands do, a model read from a file,
parameters checked against the option spec and stored as given."""

from __future__ import annotations

import dataclasses
import inspect
import os

import numpy as np

from fricli import models
from fricli.core import logs, modelfile, timewindow
from fricli.core.files import path_arg
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




def read_log(path, *, joint=None, kt=None, cutoff=logs.DEFAULT_CUTOFF_HZ, drop_invalid=False, no_gravity=False,
             no_dynamics=False, time_from=None, time_until=None, warn=None) -> logs.Log:
    """One joint's log from the Parquet file ``path`` ("-": stdin), read as the commands read LOG
    with --joint, --kt [Nm/A], --cutoff [Hz], --drop-invalid, --no-gravity, --no-dynamics, --from
    and --until (``time_from``, ``time_until``: seconds of ``t``, or a share of its span: "60%").
    ``warn(line)`` gets the notes the commands print. ``Log.signals``: float64 arrays (n,)."""
    given = dict(joint=joint, kt=kt, cutoff=cutoff, drop_invalid=drop_invalid, no_gravity=no_gravity,
                 no_dynamics=no_dynamics)
    opts, _, window = reading_of("read_log", given, time_from, time_until)
    path = path_arg(path, "path", "read_log")
    name = "stdin" if path == "-" else path
    table, digest = logs.read_table(path)
    table = timewindow.slice_table(table, window, name, warn=warn)
    data = runs.read(table, digest, name, opts, warn=warn)
    data.window = window.to_json() if window else None
    if len(logs.joints_of(table, name) or ()) > 1:
        data.source = table   # the other joints' velocities a coupled group's model reads (``with_partners``)
    return data


def with_partners(model, data: logs.Log):
    """``model`` as it applies to ``data``'s joint (a coupled group's member, ``coupled.view``), with
    the velocities of the group's other joints it reads added to ``data.signals`` from the log it
    was read from, as the commands read them. DataError when ``data`` does not hold them."""
    from fricli.models import coupled

    model = coupled.view(model, data.joint)
    missing = [p for p in coupled.partners_read(model) if coupled.partner_key(p) not in data.signals]
    if missing and data.source is None:
        raise DataError(f"{data.name}: the model is a coupled group's and reads the velocities of joints "
                        f"{', '.join(missing)}: give the log as a path, or as read_log reads it")
    if missing:
        r = {**{name: o.default for name, o in READING.items()}, **data.reading}
        coupled.add_partners(model, data, data.source, kt=r["kt"], cutoff_hz=r["cutoff"],
                             drop_invalid=r["drop_invalid"], zero=runs.zero(r))
    return model


def reading_of(command: str, reading: dict, time_from=None, time_until=None, extra: dict | None = None):
    """The commands' reading options given as keywords (``read_log``'s, ``--from``/``--until`` as
    ``time_from``/``time_until``, and ``extra`` {name: (Option, value)}) checked: (the values of
    READING with their defaults, the extra values, the time window). OptionError naming a wrong one."""
    extra = extra or {}
    given = {**reading, **{name: value for name, (_, value) in extra.items()}}
    opts = optionspec.check_values(given, {**READING, **{name: o for name, (o, _) in extra.items()}}, command)
    values = {name: opts.pop(name) for name in extra}
    return ({**{name: option.default for name, option in READING.items()}, **opts}, values,
            window_of(command, time_from, time_until))


def window_of(command: str, time_from=None, time_until=None) -> timewindow.Window:
    """``--from``/``--until`` given as ``time_from``/``time_until`` (text such as "60%" or "12.5 s",
    a number of seconds, or a ``timewindow.Bound``); OptionError naming a wrong one."""
    bounds = []
    for option, bound in (("time_from", time_from), ("time_until", time_until)):
        try:
            bounds.append(bound if bound is None or isinstance(bound, timewindow.Bound)
                          else timewindow.Bound.parse(str(bound)))
        except ValueError as exc:
            raise OptionError(f"{command} option {option}: {exc}", option) from None
    return timewindow.Window(*bounds)


def _as_log(log, reading: dict | None = None) -> logs.Log:
    """``log`` itself, or the log at the path ``log`` read with ``reading`` (``read_log``'s options)."""
    if isinstance(log, logs.Log):
        return log
    if isinstance(log, (str, bytes, os.PathLike)):
        return read_log(log, **(reading or {}))
    raise OptionError(f"log: expected a fricli.read_log result or a path, not {type(log).__name__}", "log")


def _friction(model, data: logs.Log, meta: dict, name: str) -> np.ndarray:
    """``model``'s friction on ``data`` once the model file's ``meta`` is checked against it as the
    commands check it: the units' axis kind, and the joint (one of the joints the model covers)."""
    from fricli.core import joints

    models.check_log(meta, data, name)
    covered = joints.covers(meta)
    if data.joint is not None and None not in covered and not any(joints.same(j, data.joint) for j in covered):
        raise joints.mismatch(name, joints.listed(covered), data.name, data.joint)
    return np.asarray(with_partners(model, data).predict(data.signals)[0], dtype=np.float64)


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
        return _friction(self.model, _as_log(log), self.meta, self.path or "the model")

    def save(self, path) -> None:
        """Write the model file again (the same bytes as the file it was read from)."""
        modelfile.write(path_arg(path, "path", "Model.save"), self.meta, models.to_parts(self.model)[1])

    def __repr__(self) -> str:
        return f"Model({self.kind!r}, path={self.path!r})"


def load_model(path) -> Model:
    """The model in the model file ``path`` (.npz); ModelFileError when it is not one."""
    path = path_arg(path, "path", "load_model")
    model, meta = models.load(path)
    return Model(model, meta, path)


LOWPASS = Option("lowpass_hz", "float", None, "Zero-phase low-pass of the external-torque estimate [Hz].", unit="Hz",
                 low=0, low_open=True)


def external_torque(model, log, lowpass_hz: float | None = None) -> np.ndarray:
    """tau_ext = tau_g + tau_dyn + friction - tau_m [Nm or N] (n,) on ``log`` as ``fricli estimate-ext``
    gives it, with ``model`` a ``load_model`` result, a model file's path or a fitted estimator;
    optionally low-passed at ``lowpass_hz`` [Hz] (zero-phase, as --lowpass)."""
    from fricli.applying.predicting import external_estimate

    lowpass_hz = optionspec.check_values({"lowpass_hz": lowpass_hz}, {"lowpass_hz": LOWPASS},
                                         "external_torque")["lowpass_hz"]
    if not hasattr(model, "predict"):
        model = load_model(path_arg(model, "model", "external_torque"))
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
        optionspec.check_values(params, self._spec, who)
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
        """The pipeline's options from the parameters; OptionError for options that do not go together."""
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
        return _friction(self.model_, _as_log(log, self.reading_), self.meta_, f"this {type(self).__name__}")

    def save(self, path) -> None:
        """Write the model file (.npz) the command writes with the same options on the same log."""
        self._check_fitted()
        modelfile.write(path_arg(path, "path", f"{type(self).__name__}.save"), self.meta_,
                        models.to_parts(self.model_)[1])

    def _model_bytes(self) -> bytes:
        return modelfile.dumps(self.meta_, models.to_parts(self.model_)[1])


def base_bytes(model) -> bytes:
    """The model-file bytes of a fitted estimator or a ``load_model`` result."""
    if isinstance(model, Model):
        return modelfile.dumps(model.meta, models.to_parts(model.model)[1])
    return model._model_bytes()
