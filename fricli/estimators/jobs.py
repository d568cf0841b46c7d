"""The estimators whose fit is one job of ``fricli.fitting.runs``: identify (``LuGre``, ``Linear``,
``GMS``), train-base (``Network``), adapt (``Residual``), diagnose --fix (``Diagnosis``)."""

from __future__ import annotations

import hashlib
import os

from fricli import models
from fricli.core import logs
from fricli.estimators.base import READING, Model, _Custom, _as_log, _Estimator, base_bytes, with_partners
from fricli.fitting import optionspec, runs
from fricli.fitting.optionspec import Option


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


class _OnModel(_Job):
    """A job on an input model (``_positional``): a path, a ``load_model`` result or a fitted estimator."""

    def _input(self):
        return getattr(self, self._positional)

    def _base(self, data: logs.Log):
        given = self._input()
        if isinstance(given, (str, os.PathLike)):
            path = os.fspath(given)
            model, meta, name = *models.load(path), os.path.basename(path)
        elif isinstance(given, Model):
            path = given.path if given.path and os.path.isfile(given.path) else None
            model, meta, name = given.model, given.meta, os.path.basename(path) if path else None
        elif isinstance(given, _Estimator):
            given._check_fitted()
            model, meta, name, path = given.model_, given.meta_, None, None
        else:
            raise TypeError(f"{type(self).__name__}: {self._positional} must be a model file's path, a "
                            f"fricli.load_model result or a fitted estimator, not {type(given).__name__}")
        source = path or getattr(given, "path", None) or self._positional
        models.check_log(meta, data, source)
        return runs.Base(with_partners(model, data), meta, name, source), path


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
    if isinstance(value, str):
        names = [v.strip() for v in value.split(",")]
    elif isinstance(value, (list, tuple)):
        names = list(value)
    else:
        raise ValueError(f"effects = {value!r}: expected effect names, a list or comma-separated")
    names = [n for n in names if n]
    bad = [n for n in names if not isinstance(n, str) or (n not in E.NAMES and n != "column"
                                                            and not n.startswith("column:"))]
    if bad:
        raise ValueError(f"effects = {bad[0]!r}: expected names of {', '.join(E.NAMES)}, column, column:NAME")
    return names or None


def diagnose_spec() -> dict:
    """diagnose's options (``optionspec.diagnose_options``), effects checked by name."""
    import dataclasses

    spec = {o.name: o for o in optionspec.diagnose_options()}
    given = {f.name: getattr(spec["effects"], f.name) for f in dataclasses.fields(spec["effects"])}
    spec["effects"] = _Custom(**given, validate=_effects)
    return spec


def diagnose_options(given: dict | None = None, reading: dict | None = None, **extra) -> dict:
    """The options the diagnose command records (``fricli.cli.options.command_options``), in its
    terms: ``given`` over the defaults (checked), the log's ``reading`` options (``read_log``),
    and ``extra`` (e.g. --calibrate's ``urdf_sha256``)."""
    spec = diagnose_spec()
    opts = {**optionspec.check_values({n: o.default for n, o in spec.items()} | (given or {}), spec, "Diagnosis"),
            "urdf": None, "calibrated": None, "calibrate_friction": None}
    opts["only"] = opts.pop("effects")
    read = {n: o.default for n, o in READING.items()} | optionspec.check_values(reading or {}, READING, "Diagnosis")
    opts.update({k: read[k] for k in ("joint", "kt", "cutoff", "drop_invalid")})
    opts.update({flag: True for flag in optionspec.ZERO_FLAGS if read[flag]})
    return {**opts, **extra}


class Diagnosis(_OnModel):
    """Which physical effects ``model`` misses on ``log``, and the model with them (``fricli diagnose
    --fix``): ``diagnosis_`` the ranked effects (``.to_json()``: what diagnose --json prints),
    ``added_`` the effects added, ``model_`` the fixed model (``save``: diagnose --fix's file)."""

    _pipeline = "diagnose"
    _positional = "model"
    _spec = diagnose_spec()

    def _job_options(self, data: logs.Log) -> dict:
        return diagnose_options({name: getattr(self, name) for name in self._spec}, data.reading)

    def _fitted(self, fitted) -> None:
        self.diagnosis_ = fitted.diagnosis
        self.added_ = list(fitted.diagnosis.added)
