"""Evaluate models on logs: friction error and, where a sensor column exists, external-torque error."""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli import models
from fricli.core import logs, metrics
from fricli.core.envelope import share_outside
from fricli.core.errors import DataError, one_line
from fricli.models import coupled
from fricli.applying.predicting import external_estimate


@dataclasses.dataclass
class Result:
    model: str
    log: str
    friction: dict                 # errors of tau_f_pred against the friction target [Nm], all rows
    external: dict | None          # errors of tau_ext_pred against tau_ext [Nm], if measured
    friction_moving: dict          # the same over the rows in motion (metrics.in_motion)
    external_moving: dict | None
    joint: object = None           # the log's joint the row is for (None: no joint column)
    extrapolation: dict | None = None   # rows outside the model's training envelope (None: no envelope)
    unit: str = "Nm"               # of the errors: Nm, or N on a linear axis
    robot_model: str | None = None  # a warning: the model was fitted on another robot model's torques


def evaluate_one(model, meta: dict, log: logs.Log, *, lowpass_hz: float | None = None,
                 model_name: str = "model", log_name: str = "log") -> Result:
    models.check_log(meta, log, model_name)
    sig = log.signals
    try:
        pred = model.predict(sig)[0]
    except DataError as exc:          # a column the model reads is missing: name the files
        raise DataError(f"{log.name}: {exc} ({model_name})") from None
    target = logs.friction_target(sig)
    moving = metrics.in_motion(sig["qd"])
    external = external_moving = None
    if "tau_ext" in sig:
        est = external_estimate(sig, pred, lowpass_hz)
        external = metrics.errors(sig["tau_ext"], est)
        external_moving = metrics.errors(sig["tau_ext"][moving], est[moving])
    return Result(model_name, log_name, metrics.errors(target, pred), external,
                  metrics.errors(target[moving], pred[moving]), external_moving,
                  extrapolation=share_outside(models.envelope(meta, model_name), sig), unit=log.units["tau"],
                  robot_model=models.robot_model_note(meta, log, model_name))


def evaluate(model_paths: dict[str, str], log_paths: dict[str, str], *, lowpass_hz: float | None = None,
             read_kwargs: dict | None = None, read=logs.read_table) -> list[Result]:
    """Every model on every log. A model is a file, a model set folder or a coupled group's file;
    which model applies to which joint of a log follows the joint rule (fricli.core.joints): a
    result per model, log and joint. A model that reads other joints' velocities (a coupled
    group's) gets them from the same log (``coupled.add_partners``).
    ``read``: path -> (table, sha256) of a log (e.g. with a time window)."""
    from fricli.core import joints, modelset

    sources = {name: modelset.source(path) for name, path in model_paths.items()}
    tables = {name: read(path) for name, path in log_paths.items()}
    read_kwargs = dict(read_kwargs or {})
    requested = read_kwargs.pop("joint", None)
    results = []
    cache: dict = {}
    for mname, source in sources.items():
        for lname, (table, digest) in tables.items():
            lpath = log_paths[lname]
            for joint, path in joints.pair(source, logs.joints_of(table, lpath), requested, lpath):
                if path not in cache:
                    cache[path] = models.load(path)
                model, meta = cache[path]
                model = coupled.view(model, joint)
                reads = models.reads_acceleration(model)
                key = (lname, str(joint), reads)
                if key not in cache:
                    cache[key] = logs.from_table(table, name=log_paths[lname], sha256=digest, joint=joint,
                                                 qdd=reads, **read_kwargs)
                log = dataclasses.replace(cache[key], signals=dict(cache[key].signals))
                coupled.add_partners(model, log, table, **read_kwargs)
                result = evaluate_one(model, meta, log, lowpass_hz=lowpass_hz, model_name=mname, log_name=lname)
                result.joint = joint
                results.append(result)
    return results


def to_json(results: list[Result], model_paths: dict, log_paths: dict, lowpass_hz) -> dict:
    return {"models": model_paths, "logs": log_paths, "lowpass_hz": lowpass_hz,
            "results": [dataclasses.asdict(r) for r in results]}


def markdown_table(results: list[Result], model_names: list[str], log_names: list[str]) -> str:
    """Rows: models (a row per joint when the results cover several joints); columns: logs; cells:
    friction MAE and RMS (and external-torque MAE and RMS) in the torque unit, all rows and, in
    brackets, rows in motion."""
    by = {(r.model, str(r.joint), r.log): r for r in results}
    rows = list(dict.fromkeys((r.model, r.joint) for r in results))
    labelled = len({str(r.joint) for r in results}) > 1
    has_ext = {ln: any(r.external for r in results if r.log == ln) for ln in log_names}
    figures = (("mae", "MAE"), ("rmse", "RMS"))
    unit = next((r.unit for r in results), "Nm")
    head = ["model"]
    for ln in log_names:
        name = one_line(str(ln))   # a name quoted from a file: one line, whatever it holds
        head += [f"{name} friction {label} [{unit}]" for _, label in figures]
        if has_ext[ln]:
            head += [f"{name} ext. torque {label} [{unit}]" for _, label in figures]
    motion = f"rows in motion, |qd| > {100 * metrics.REST_SHARE:g} % of the top speed"
    lines = [f"Error over all rows (in brackets: {motion}); RMS: root mean square", "",
             "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cell(value, moving) -> str:   # no row in motion: a dash in brackets, as the JSON's null
        return f"{value:.3f} ({'–' if moving is None or not np.isfinite(moving) else f'{moving:.3f}'})"

    for mn, joint in rows:
        label = (f"{mn} (joint {joint})" if joint is not None else f"{mn} (log without joints)") if labelled else mn
        row = [one_line(str(label))]
        for ln in log_names:
            r = by.get((mn, str(joint), ln))
            row += [cell(r.friction[k], r.friction_moving[k]) if r else "–" for k, _ in figures]
            if has_ext[ln]:
                row += [cell(r.external[k], r.external_moving[k]) if r and r.external else "–" for k, _ in figures]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines)


def static_friction(model, qd: np.ndarray, tau_g: np.ndarray, like: dict | None = None) -> np.ndarray:
    """Steady-state friction [Nm] at each (qd, tau_g) pair, shapes (n,).

    Points are spaced 1000 s apart with zero acceleration, so every history-dependent state
    (e.g. the LuGre bristles) settles between them. Other inputs the model reads are held at
    the median of ``like`` (a log's signals), or zero; a model that reads the motor torque (a
    payload term) gets the steady state's, tau_g plus the friction of a first pass.
    """
    qd = np.asarray(qd, dtype=np.float64).ravel()
    n = qd.size
    sig = {"t": np.arange(n) * 1000.0, "qd": qd, "tau_g": np.broadcast_to(tau_g, qd.shape).astype(np.float64).ravel(),
           "qdd": np.zeros(n), "tau_dyn": np.zeros(n), "tau_m": np.zeros(n)}
    for name in model.required_inputs():
        if name not in sig:
            value = float(np.median(like[name])) if like is not None and name in like else 0.0
            sig[name] = np.full(n, value)
    out = model.predict(sig)[0]
    if "tau_m" in model.required_inputs():
        sig["tau_m"] = sig["tau_g"] + out
        out = model.predict(sig)[0]
    return out
