"""Model kinds, and saving/loading any of them through the model file.

Every kind subclasses ``FrictionModel``. A model made of other models (a base plus a
residual network, a model plus diagnosed effects) lists them in ``children()``; their arrays
are stored under ``<child>/`` in the file and their specs nested in ``meta["model"]``.
"""

from __future__ import annotations

import importlib

import numpy as np

from fricli.core import modelfile
from fricli.core.errors import ModelFileError
from fricli.models.base import FrictionModel

_KIND_MODULES = ("lugre", "linear", "gms", "neural", "dissipative", "residual", "augmented", "coupled")
KINDS: dict[str, type[FrictionModel]] = {}


def register(cls: type[FrictionModel]) -> type[FrictionModel]:
    KINDS[cls.kind] = cls
    return cls


def _load_kinds() -> None:
    for name in _KIND_MODULES:
        module = f"fricli.models.{name}"
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:
                raise


PRECISIONS = ("single", "double")


def set_precision(model: FrictionModel, precision: str) -> FrictionModel:
    """Evaluate every network in the model tree in ``precision``: "single" (float32, the
    default) or "double" (float64, the arithmetic of exported C code). Returns ``model``."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, not {precision!r}")
    if hasattr(model, "precision"):
        model.precision = precision
    for child in model.children().values():
        set_precision(child, precision)
    return model


def to_parts(model: FrictionModel, prefix: str = "") -> tuple[dict, dict[str, np.ndarray]]:
    """(spec, arrays) of a model tree; arrays keyed by ``prefix + name``."""
    spec = {"kind": model.kind, "params": model.get_params()}
    arrays = {prefix + k: np.asarray(v) for k, v in model.get_arrays().items()}
    children = model.children()
    if children:
        spec["children"] = {}
        for name, child in children.items():
            child_spec, child_arrays = to_parts(child, f"{prefix}{name}/")
            spec["children"][name] = child_spec
            arrays.update(child_arrays)
    return spec, arrays


def from_parts(spec: dict, arrays: dict[str, np.ndarray], prefix: str = "", name: str = "model") -> FrictionModel:
    _load_kinds()
    if not isinstance(spec, dict) or not isinstance(spec.get("children", {}), dict):
        raise ModelFileError(f"{name}: damaged model file (the model spec is not a JSON object)")
    try:
        cls = KINDS[spec["kind"]]
    except (KeyError, TypeError):
        raise ModelFileError(f"{name}: unknown model kind {spec.get('kind')!r}") from None
    own = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix) and "/" not in k[len(prefix):]}
    children = {child: from_parts(child_spec, arrays, f"{prefix}{child}/", name)
                for child, child_spec in spec.get("children", {}).items()}
    try:
        return cls.from_parts(spec.get("params", {}), own, children)
    except ModelFileError as exc:   # a readable file the current fricli refuses, with the fix
        raise ModelFileError(f"{name}: {exc}") from None
    except Exception as exc:  # the file is untrusted: whatever its parts break is a damaged file
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ModelFileError(f"{name}: damaged {spec['kind']} model ({first})") from None


def parts(model: FrictionModel, *, joint, axis: str, units: dict, provenance: dict, fit: dict | None = None,
          envelope: dict | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """(meta, arrays) of the model file of ``model`` (``save`` writes them)."""
    spec, arrays = to_parts(model)
    meta = modelfile.base_meta()
    meta.update(kind=model.kind, model=spec, joint=joint, axis=axis, units=units,
                inputs=sorted(model.required_inputs()), provenance=provenance, fit=fit or {})
    if envelope is not None:
        meta["envelope"] = envelope
    return meta, arrays


def save(path: str, model: FrictionModel, *, joint, axis: str, units: dict, provenance: dict,
         fit: dict | None = None, envelope: dict | None = None) -> dict:
    """Write ``model`` with its meta (``envelope``: the training envelope, ``Envelope.to_meta``);
    returns the meta."""
    meta, arrays = parts(model, joint=joint, axis=axis, units=units, provenance=provenance, fit=fit,
                         envelope=envelope)
    modelfile.write(path, meta, arrays)
    return meta


def load(path: str) -> tuple[FrictionModel, dict]:
    meta, arrays = modelfile.read(path)
    if "model" not in meta:
        raise ModelFileError(f"{path}: not a fricli model file (no model spec)")
    model = from_parts(meta["model"], arrays, name=path)
    if "kind" in meta and meta["kind"] != model.kind:
        raise ModelFileError(f"{path}: damaged model file (its kind {meta['kind']!r} disagrees with its model "
                             f"spec's {model.kind!r})")
    return model, meta


def reads_acceleration(model: FrictionModel) -> bool:
    """Whether ``model`` reads the acceleration qdd (a term of it: ``diagnose --fix``'s): a log
    without one is given a derived one only for such a model (``logs.from_table``'s ``qdd``)."""
    return "qdd" in model.required_inputs()


def check_log(meta: dict, log, model_name: str = "model") -> None:
    """Refuse a log whose axis kind (rotary/linear) differs from the model's."""
    if meta.get("axis") and meta["axis"] != log.axis:
        mu, lu = meta.get("units", {}), log.units
        raise ModelFileError(f"{model_name}: the model was fitted in {mu.get('q')}, {mu.get('tau')} "
                             f"but the log {log.name} is in {lu['q']}, {lu['tau']}")


def robot_model_note(meta: dict, log, model_name: str | None = None) -> str | None:
    """A warning when the model was fitted on a log whose tau_g and tau_dyn came from another robot
    model (URDF, gravity, rotor inertias, held joints) than ``log``'s: its friction target differs, so
    its friction does too. None when they agree or either is unrecorded. A payload is no part of the
    robot model: the load a joint carries changes from log to log, and a model's load terms are
    there to see it. Without ``model_name`` the line is the same for every joint's model of a folder
    (one line for all)."""
    from fricli.core import logs

    fitted, here = (meta.get("provenance") or {}).get("robot_model"), logs.robot_model(log.table.schema)
    if not fitted or not here:
        return None
    what = {"urdf_sha256": "URDF", "gravity": "gravity", "rotor_inertia": "rotor inertias", "held": "held joints"}
    differ = [name for key, name in what.items() if fitted.get(key) != here.get(key)]
    if not differ:
        return None
    who = f"{model_name}: fitted" if model_name else "the model was fitted"
    return (f"warning: {who} on tau_g and tau_dyn of another robot model than {log.name}'s (differing in "
            f"{', '.join(differ)}): the friction it learned holds what that model got wrong; import the log with the "
            "model's URDF and options, or refit")


def provenance(log, *, rows_used: int, seed: int | None = None, **extra) -> dict:
    """Where a model came from: enough to reproduce it (no wall-clock time). A command's options,
    the seed among them, are recorded once, in ``job`` (``extra``); ``seed`` is kept here only for
    a model written without one."""
    import os

    from fricli.core import logs

    out = {"log_sha256": log.sha256, "log_name": os.path.basename(log.name), "log_rows": len(log),
           "rows_used": int(rows_used), "derived": log.derived}
    robot = logs.robot_model(log.table.schema)
    if robot is not None:
        out["robot_model"] = robot
    if "job" not in extra:
        out["seed"] = seed
    out.update(extra)
    return out


def envelope(meta: dict, name: str = "model"):
    """The training envelope (``fricli.core.envelope.Envelope``) recorded in a model file's meta, or
    None for files without one."""
    from fricli.core.envelope import Envelope

    try:
        return Envelope.from_meta(meta.get("envelope"))
    except ValueError as exc:
        raise ModelFileError(f"{name}: {exc}") from None


def parts_for_log(model: FrictionModel, log, *, rows_used: int, seed: int | None = None, fit: dict | None = None,
                  envelope: dict | None = None, **extra) -> tuple[dict, dict[str, np.ndarray]]:
    """``parts`` with joint, units and provenance taken from the log the model was fitted on; the
    training envelope is the log's over the model's inputs unless ``envelope`` is given."""
    from fricli.core.envelope import Envelope

    if envelope is None:
        envelope = Envelope.fit(log.signals, model.required_inputs()).to_meta()
    return parts(model, joint=log.joint, axis=log.axis, units=log.units,
                 provenance=provenance(log, rows_used=rows_used, seed=seed, **extra), fit=fit, envelope=envelope)


def save_for_log(path: str, model: FrictionModel, log, *, rows_used: int, seed: int | None = None,
                 fit: dict | None = None, envelope: dict | None = None, **extra) -> dict:
    """``save`` with joint, units and provenance taken from the log the model was fitted on; the
    training envelope is the log's over the model's inputs unless ``envelope`` is given."""
    meta, arrays = parts_for_log(model, log, rows_used=rows_used, seed=seed, fit=fit, envelope=envelope, **extra)
    modelfile.write(path, meta, arrays)
    return meta
