"""``fricli replay`` and ``fricli thresholds``: a log run through what the controller runs, row by
row (``fricli.applying.observer``), and the contact thresholds calibrated from collision-free logs.

The friction model of each joint reads the log's columns as its exported step function reads
them from the controller (docs/deploy.md); its output is causal (each model is a recurrence over
the rows). The rigid-body terms of the observer come from a URDF through Pinocchio (``urdf``):
p = M(q) qd = RNEA(q, 0, qd) without gravity (with the armature: the URDF's rotor_params, else the
rotor inertias the log's import recorded, and the cross-inertia of a coupled group's rotors, the URDF's
or the import's), g(q) by RNEA,
C(q, qd) by ``computeCoriolisMatrix``; with the gravity, payload and held joints the log's
import recorded, and its joints matched to the URDF's by the names it recorded. Without a URDF the
observer takes the per-joint form on the log's tau_g and tau_dyn.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from fricli import models
from fricli.applying import observer
from fricli.core import joints as joint_rule
from fricli.core import lazy, logs, metrics, modelset
from fricli.core.atomic import atomic_open, atomic_write_bytes
from fricli.core.files import path_arg
from fricli.core.errors import DataError, InvalidRows, LogError, ModelFileError
from fricli.fitting import runs
from fricli.models import coupled
from fricli.models.base import predict_parts

pa = lazy.module("pyarrow")
pc = lazy.module("pyarrow.compute")
pq = lazy.module("pyarrow.parquet")


@dataclasses.dataclass
class Arm:
    """One log's rows as a controller sees them, per joint (n, J): time, the friction models'
    friction f0 (their robot-model error part apart: ``error``), tau_m, p, w (observer module), qd;
    the friction target for scoring; where each joint's rows sit in the log's table."""

    name: str
    joints: list
    t: np.ndarray
    f0: np.ndarray
    tau_m: np.ndarray
    p: np.ndarray
    w: np.ndarray
    qd: np.ndarray
    target: np.ndarray
    table: object
    rows: list                      # per joint: the row indices in ``table``
    form: str
    unit: str
    signals: list = dataclasses.field(default_factory=list)   # per joint: the signals its model read
    error: np.ndarray | None = None   # (n, J) the models' robot-model error part (diagnose --fix); f0 is friction


def read_arm(model_path: str, log_path: str, urdf: str | None = None, zero=()) -> Arm:
    """The log at ``log_path`` with each covered joint's model of ``model_path`` (a model file or
    a folder of them, the joint rule) and the rigid-body terms (``urdf``, or the per-joint form)."""
    table, _digest = logs.read_table(log_path)
    name = "stdin" if log_path == "-" else log_path
    found = logs.joints_of(table, name)
    pairs = joint_rule.pair(modelset.source(model_path), found, None, name, joint_option=False)
    jnames, f0, tau_m, qd, t, target, rows, tables, w, error = [], [], [], [], None, [], [], {}, [], []
    index = np.arange(table.num_rows)
    unit = "Nm"
    for j, path in pairs:
        model, meta = models.load(path)
        model = models.set_precision(coupled.view(model, j), "double")
        log, idx = _joint_rows(table, j, name, zero, models.reads_acceleration(model)), index
        if j is not None:
            jcol = table.column("joint")
            idx = index[pc.equal(jcol, pa.scalar(j, jcol.type)).to_numpy(zero_copy_only=False)]
        log.joint = j
        coupled.add_partners(model, log, table, zero=zero)
        models.check_log(meta, log, path)
        sig = log.signals
        if urdf is not None:
            from fricli.robot.dynamics import require_positions

            require_positions(sig, f"{name}: joint {j}")
        if t is None:
            t = sig["t"]
        elif len(sig["t"]) != len(t) or not np.array_equal(sig["t"], t):
            raise LogError(f"{name}: joint {j} has other time stamps than joint {pairs[0][0]}"
                           f"{_first_apart(sig['t'], t)}: the replay of an arm needs one sample of every joint per "
                           "time")
        try:
            tau, err, _ = predict_parts(model, sig, None)
        except DataError as exc:
            raise DataError(f"{name}: {exc} ({path})") from None
        jnames.append(j)
        f0.append(np.asarray(tau, dtype=np.float64))
        error.append(np.asarray(err, dtype=np.float64))
        tau_m.append(sig["tau_m"])
        qd.append(sig["qd"])
        target.append(logs.friction_target(sig))
        w.append(logs.column(sig, "tau_g") + logs.column(sig, "tau_dyn") if urdf is None else None)
        rows.append(idx)
        tables[j] = sig
        unit = log.units["tau"]
    stack = lambda xs: np.column_stack(xs)   # noqa: E731
    if urdf is None:
        p, wr, form = np.zeros((len(t), len(jnames))), stack(w), "per-joint"
    else:
        positions = {}              # every joint of the log, in its order: those without a model set the
        for j in found or jnames:   # arm's configuration too
            mine = [k for k in jnames if joint_rule.same(j, k)]
            if mine:
                positions[mine[0]] = tables[mine[0]]
                continue
            other = _joint_rows(table, j, name, zero, qdd=False).signals
            if len(other["t"]) != len(t) or not np.array_equal(other["t"], t):
                raise LogError(f"{name}: joint {j} has other time stamps than joint {jnames[0]}"
                               f"{_first_apart(other['t'], t)}: the robot model needs every joint's position at "
                               "each time")
            positions[j] = other
        p, wr = momentum_terms(urdf, table.schema, list(positions), positions, name, replayed=jnames)
        form = "urdf"
    return Arm(name, jnames, t, stack(f0), stack(tau_m), p, wr, stack(qd), stack(target), table, rows, form, unit,
               [tables[j] for j in jnames], stack(error))


def _first_apart(a: np.ndarray, b: np.ndarray) -> str:
    """Where two joints' time stamps (n,) [s] first differ, for a message."""
    n = min(len(a), len(b))
    apart = np.flatnonzero(a[:n] != b[:n])
    if len(apart):
        k = int(apart[0])
        return f" (sample {k + 1}: t = {a[k]:.15g} s against {b[k]:.15g} s)"
    return f" ({len(a)} samples against {len(b)}, alike up to t = {a[n - 1]:.15g} s)" if n else ""


def _joint_rows(table, joint, name: str, zero, qdd: bool) -> logs.Log:
    """Joint ``joint``'s rows of the log's ``table`` (every row for None), rows named by their row in
    the file; a missing acceleration derived only when ``qdd`` (the joint's model reads it: the
    observer reads none)."""
    rows = None
    if joint is not None:
        jcol = table.column("joint")
        mask = pc.equal(jcol, pa.scalar(joint, jcol.type)).to_numpy(zero_copy_only=False)
        table, rows = table.filter(pa.array(mask)), np.flatnonzero(mask)
    try:
        return logs.from_table(table, name=name, zero=zero, rows=rows, qdd=qdd)
    except InvalidRows as exc:
        raise LogError(f"{exc.what}: a replay runs every row as the controller would and drops none") from None


def momentum_terms(urdf: str, schema, jnames: list, sig: dict, name: str,
                   replayed: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(p, w) per row and joint of ``replayed`` (default: every joint of ``jnames``): p = M(q) qd,
    w = g(q) - C(q, qd)^T qd, with Pinocchio, in the configuration of the log joints ``jnames``
    (signals ``sig``)."""
    from fricli.robot import dynamics
    from fricli.robot.mapping import Payload

    pin = dynamics.pinocchio()
    record = logs.robot_record(schema)
    named = record.get("joints") or {}
    payload = record.get("payload")
    robot = dynamics.RobotModel(dynamics._urdf_text(urdf), urdf, gravity=logs.gravity_of(schema),
                                payload=Payload(**payload) if isinstance(payload, dict) else None,
                                held=tuple(record.get("held") or ()))
    if named:
        replayed = jnames if replayed is None else replayed
        jnames = [j for j in jnames if str(j) in named or j in replayed]   # a joint the URDF does not model
        missing = [j for j in jnames if str(j) not in named]
        if missing:
            raise DataError(f"{name}: the log records no URDF joint for joint {missing[0]}")
        idx = robot.match([named[str(j)] for j in jnames], "name")
    else:
        idx = robot.match([None] * len(jnames), "order")
    axis = logs.axis_of(schema, name)
    for k, j in zip(idx, jnames):
        dynamics.check_kind(robot, k, j, axis)
    nv = len(robot.joints)
    n = len(next(iter(sig.values()))["t"])
    q, qd = np.zeros((n, nv)), np.zeros((n, nv))
    for k, j in zip(idx, jnames):
        q[:, k], qd[:, k] = sig[j]["q"], sig[j]["qd"]
    rotor = np.zeros(nv)
    given = record.get("rotor_inertia") or {}
    for k, j in zip(idx, jnames):
        if np.isnan(robot.armature[k]):
            rotor[k] = float(given.get(str(j), 0.0) or 0.0)
    config = robot.configuration(q)
    zeros = np.zeros_like(q)
    p = dynamics._rnea(robot._no_g, config, zeros, qd) + qd * rotor + qd @ robot.cross_inertia.T
    cross = _recorded_cross_inertia(record, named, robot)
    if cross is not None:
        p += qd @ cross.T
    g = dynamics._rnea(robot._with_g, config, zeros, zeros)
    model = robot.pin_model
    data = model.createData()
    ctq = np.empty_like(q)
    for i in range(n):
        c = pin.computeCoriolisMatrix(model, data, config[i], qd[i])
        ctq[i] = c.T @ qd[i]
    w = g - ctq
    keep = [idx[jnames.index(j)] for j in (jnames if replayed is None else replayed)]
    return np.ascontiguousarray(p[:, keep]), np.ascontiguousarray(w[:, keep])


def _recorded_cross_inertia(record: dict, named: dict, robot) -> np.ndarray | None:
    """The rotors' cross-inertia (nv, nv) [kg m^2] in the URDF's joint order that the import added to
    tau_dyn (a coupled group's motors: ``cross_inertia`` over the import's joints, in the order of
    its joint names), or None."""
    cross = record.get("cross_inertia")
    if cross is None or not named:
        return None
    try:
        cross = np.asarray(cross, dtype=np.float64)
    except (TypeError, ValueError):
        cross = None
    if cross is None or cross.shape != (len(named), len(named)) or not np.all(np.isfinite(cross)):
        raise DataError("the log's import record holds a cross_inertia that is not one number per pair of its "
                        f"{len(named)} joints")
    pos = [robot.joints.index(u) if u in robot.joints else -1 for u in named.values()]
    keep = [k for k, i in enumerate(pos) if i >= 0]
    out = np.zeros((len(robot.joints), len(robot.joints)))
    out[np.ix_([pos[k] for k in keep], [pos[k] for k in keep])] = cross[np.ix_(keep, keep)]
    return out


def run(arm: Arm, gain: float, thresholds: observer.Thresholds | None,
        adaptation: observer.Adaptation | None) -> observer.Replayed:
    if thresholds is not None:
        if thresholds.form != arm.form:
            raise LogError(f"the thresholds were calibrated on the {thresholds.form} observer, this replay runs the "
                            f"{arm.form} one ({'give --urdf' if thresholds.form == 'urdf' else 'leave out --urdf'})")
        thresholds = thresholds.for_joints(arm.joints, arm.name)
    return _replay(arm, gain, thresholds, adaptation)


def _replay(arm: Arm, gain: float, thresholds: observer.Thresholds | None,
            adaptation: observer.Adaptation | None = None) -> observer.Replayed:
    """``observer.replay`` of ``arm``: the adapted level scales the friction alone; the models'
    robot-model error part is the robot model's (with w, as the arm header takes it), added to
    tau_f_pred unscaled."""
    error = arm.error if arm.error is not None else np.zeros_like(arm.f0)
    out = observer.replay(arm.t, arm.f0, arm.tau_m, arm.p, arm.w + error, arm.qd, gain, thresholds, adaptation)
    out.tau_f = out.tau_f + error
    return out


def write(arm: Arm, out: observer.Replayed, path: str) -> None:
    """The log's rows of the covered joints with tau_f_pred, tau_ext_pred [unit] and contact (0/1)
    added, in the log's order, written atomically."""
    order = np.concatenate(arm.rows)
    table = arm.table.take(pa.array(np.sort(order)))
    pos = np.empty(arm.table.num_rows, dtype=np.int64)
    pos[np.sort(order)] = np.arange(len(order))
    cols = {k: np.empty(len(order)) for k in ("tau_f_pred", "tau_ext_pred")}
    contact = np.zeros(len(order), dtype=np.int8)
    for j, idx in enumerate(arm.rows):
        cols["tau_f_pred"][pos[idx]] = out.tau_f[:, j]
        cols["tau_ext_pred"][pos[idx]] = out.tau_ext[:, j]
        contact[pos[idx]] = out.contact[:, j]
    for key in ("tau_f_pred", "tau_ext_pred", "contact"):
        if key in table.column_names:
            table = table.drop_columns([key])
    for key, values in cols.items():
        table = logs.with_column(table, key, values, arm.unit)
    table = table.append_column(pa.field("contact", pa.int8()), pa.array(contact))
    with atomic_open(path, binary=True) as fh:
        pq.write_table(table, fh, **logs.parquet_options(table.schema))


def moving(arm: Arm) -> np.ndarray:
    """(n, J): the rows in motion per joint, as ``fricli evaluate`` counts them."""
    return np.column_stack([metrics.in_motion(arm.qd[:, j]) for j in range(len(arm.joints))])


def calibrate(model_path: str, log_paths: list[str], urdf: str | None = None, gain: float | None = None,
              quantile: float = observer.DEFAULT_QUANTILE, margin: float = observer.DEFAULT_MARGIN,
              release: float = observer.DEFAULT_RELEASE, moving_speed: float = observer.DEFAULT_MOVING_SPEED,
              zero=(), persistence: int = observer.DEFAULT_PERSISTENCE, level: bool = True) -> observer.Thresholds:
    """Thresholds from the static observer on collision-free logs (``observer.calibrate``); with
    ``level``, each joint's share of the friction from the online adaptation replayed on the same
    logs with those thresholds (``observer.level_share``). ``gain`` None: ``observer.default_gain``
    of the logs' sample interval (the longest of their median intervals)."""
    arms = [read_arm(model_path, path, urdf, zero) for path in log_paths]
    names = [str(j) for j in arms[0].joints]
    for k, arm in enumerate(arms[1:], 1):
        if sorted(str(j) for j in arm.joints) != sorted(names):
            raise DataError(f"{arm.name}: joints {', '.join(map(str, arm.joints))}, but {arms[0].name} has "
                            f"{', '.join(names)}: calibrate on logs of the same joints")
        arms[k] = _in_order(arm, names)
    if gain is None:
        gain = observer.default_gain(max(float(np.median(np.diff(a.t))) if len(a.t) > 1 else np.inf for a in arms))
    joints = list(arms[0].joints)
    band = observer.static_band([a.f0 for a in arms], [a.qd for a in arms], moving_speed, joints)
    free = observer.Thresholds(joints, np.full(len(joints), np.inf), band, np.ones(len(joints)), gain=gain,
                               moving_speed=moving_speed, form=arms[0].form)
    res = [_replay(a, gain, free) for a in arms]
    thr = observer.calibrate([r.tau_ext for r in res], [a.f0 for a in arms], [a.qd for a in arms], joints, gain,
                             arms[0].form, band, quantile, margin, release, moving_speed,
                             logs=[os.path.basename(p) for p in log_paths])
    thr = dataclasses.replace(thr, persistence=int(persistence), share=np.zeros(len(joints)))
    if not level:
        return thr
    adapted = [_replay(a, gain, thr, observer.Adaptation()) for a in arms]
    return observer.level_share([r.scale for r in adapted], [a.qd for a in arms], thr)


def _in_order(arm: Arm, names: list[str]) -> Arm:
    """``arm`` with its joints in the order of ``names`` (the joints as text): a log may list them in
    another order than the first calibration log."""
    idx = [[str(j) for j in arm.joints].index(n) for n in names]
    if idx == list(range(len(idx))):
        return arm
    return dataclasses.replace(arm, joints=[arm.joints[i] for i in idx], f0=arm.f0[:, idx], tau_m=arm.tau_m[:, idx],
                               p=arm.p[:, idx], w=arm.w[:, idx], qd=arm.qd[:, idx], target=arm.target[:, idx],
                               rows=[arm.rows[i] for i in idx], signals=[arm.signals[i] for i in idx],
                               error=None if arm.error is None else arm.error[:, idx])


def write_thresholds(thresholds: observer.Thresholds, path: str) -> None:
    import json

    data = thresholds.as_json()
    atomic_write_bytes(path, (json.dumps(data, indent=1) + "\n").encode("utf-8"))


def summary(arm: Arm, out: observer.Replayed) -> dict:
    """Figures of a replay: per joint the RMS of the friction error in motion and over every row, the
    rows flagged, the final adapted level; and the contact events."""
    mv = moving(arm)
    per = {}
    for j, name in enumerate(arm.joints):
        e = arm.target[:, j] - out.tau_f[:, j]
        per[str(name)] = {"friction_rms_moving": float(np.sqrt(np.mean(e[mv[:, j]] ** 2))) if mv[:, j].any() else None,
                          "friction_rms": float(np.sqrt(np.mean(e ** 2))),
                          "contact_rows": int(out.contact[:, j].sum()),
                          "scale": float(out.scale[-1, j]), "offset": float(out.offset[-1, j])}
    evs = observer.events(arm.t, out.contact, out.tau_ext, arm.joints)
    return {"rows": len(arm.t), "form": arm.form, "joints": per,
            "events": [dataclasses.asdict(e) | {"joint": str(e.joint)} for e in evs]}


def check_model_path(path: str) -> None:
    if not os.path.exists(path):
        raise ModelFileError(f"{path}: no such model file or folder")


def checked(who: str, **given) -> dict:
    """The options of replay, thresholds and export --observer ``given`` as Python keywords,
    checked as the command line checks them (``OptionError`` naming the option)."""
    from fricli.fitting.optionspec import Option, check_values

    positive = {name: Option(name, "float", low=0, low_open=True) for name in ("gain", "time_constant", "margin",
                                                                               "moving_speed")}
    spec = {**positive, "quantile": Option("quantile", "float", low=0, low_open=True, high=1),
            "release": Option("release", "float", low=0, low_open=True, high=1, high_open=True),
            "persistence": Option("persistence", "int", low=1, high=observer.MAX_PERSISTENCE),
            **{name: Option(name, "flag") for name in ("adapt", "adapt_offset", "level_share", "no_gravity",
                                                       "no_dynamics", "observer")}}
    return check_values(given, spec, who)


def settings(thresholds: str | None, adapt: bool = False, adapt_offset: bool = False,
             time_constant: float | None = None, gain: float | None = None):
    """(gain, thresholds or None, adaptation or None) of replay's and export --observer's options:
    the gain given, else the thresholds file's, else ``observer.DEFAULT_GAIN``. Options of the
    wrong value, or that do not go together, raise ``OptionError``."""
    from fricli.fitting.optionspec import OptionError

    checked("replay", adapt=adapt, adapt_offset=adapt_offset, time_constant=time_constant, gain=gain)
    if adapt and thresholds is None:
        raise OptionError("--adapt needs --thresholds: the adaptation stops while a contact is suspected", "thresholds")
    if adapt_offset and not adapt:
        raise OptionError("--adapt-offset goes with --adapt", "adapt_offset")
    thr = observer.Thresholds.read(thresholds) if thresholds else None
    if thr is not None and gain is not None and gain != thr.gain:
        raise OptionError(f"--gain {gain:g}: the thresholds were calibrated with gain {thr.gain:g}", "gain")
    k = gain if gain is not None else (thr.gain if thr is not None else observer.DEFAULT_GAIN)
    extra = {"time_constant": time_constant} if time_constant is not None else {}
    return k, thr, (observer.Adaptation(offset=adapt_offset, **extra) if adapt else None)


@dataclasses.dataclass
class Replay:
    """A replay's result: ``arm`` (its joints, form, unit, rows), ``replayed`` (per row and joint:
    tau_f, tau_ext, contact, the adapted scale and offset), ``gain`` [1/s] and ``figures`` (what
    ``fricli replay --json`` prints of it: per joint the friction error, contact rows and level; events)."""

    arm: Arm
    replayed: observer.Replayed
    gain: float
    figures: dict


def replay_log(model: str, log: str, output: str | None = None, *, urdf: str | None = None,
               thresholds: str | None = None, adapt: bool = False, adapt_offset: bool = False,
               time_constant: float | None = None, gain: float | None = None, no_gravity: bool = False,
               no_dynamics: bool = False) -> Replay:
    """``fricli replay``: the log file ``log`` run row by row through what the controller runs with
    the model file or folder ``model`` (``thresholds``: a thresholds file's path; ``adapt``,
    ``adapt_offset``, ``time_constant`` [s], ``gain`` [1/s], ``no_gravity``, ``no_dynamics`` as the
    command's options), written to ``output`` when given (the log with tau_f_pred, tau_ext_pred
    and contact added)."""
    checked("replay", no_gravity=no_gravity, no_dynamics=no_dynamics)
    model, log = path_arg(model, "model", "replay_log"), path_arg(log, "log", "replay_log")
    output = None if output is None else path_arg(output, "output", "replay_log")
    k, thr, adaptation = settings(thresholds, adapt, adapt_offset, time_constant, gain)
    arm = read_arm(model, log, urdf, runs.zero({"no_gravity": no_gravity, "no_dynamics": no_dynamics}))
    out = run(arm, k, thr, adaptation)
    if output is not None:
        write(arm, out, output)
    return Replay(arm, out, k, summary(arm, out))


def calibrate_thresholds(model: str, log_files: str | list[str], output: str | None = None, *, urdf: str | None = None,
                         gain: float | None = None, quantile: float = observer.DEFAULT_QUANTILE,
                         margin: float = observer.DEFAULT_MARGIN, release: float = observer.DEFAULT_RELEASE,
                         moving_speed: float = observer.DEFAULT_MOVING_SPEED,
                         persistence: int = observer.DEFAULT_PERSISTENCE, level_share: bool = True,
                         no_gravity: bool = False, no_dynamics: bool = False) -> observer.Thresholds:
    """``fricli thresholds``: contact thresholds calibrated from the collision-free log files
    ``log_files`` replayed with ``model`` (``calibrate``), written to ``output`` when given (JSON);
    the keywords are the command's options (``level_share`` False: ``--no-level-share``; ``gain``
    None: ``observer.default_gain`` of the logs' sample interval)."""
    from fricli.fitting.optionspec import OptionError

    checked("thresholds", gain=gain, quantile=quantile, margin=margin, release=release, moving_speed=moving_speed,
            persistence=persistence, level_share=level_share, no_gravity=no_gravity, no_dynamics=no_dynamics)
    model = path_arg(model, "model", "calibrate_thresholds")
    listed = [log_files] if isinstance(log_files, (str, bytes, os.PathLike)) or log_files is None else log_files
    paths = [path_arg(p, "log_files", "calibrate_thresholds") for p in listed]
    if not paths:
        raise OptionError("no collision-free log given to calibrate on", "log_files")
    zero = runs.zero({"no_gravity": no_gravity, "no_dynamics": no_dynamics})
    thr = calibrate(model, paths, urdf, gain, quantile, margin, release, moving_speed, zero=zero,
                    persistence=persistence, level=level_share)
    if output is not None:
        write_thresholds(thr, output)
    return thr
