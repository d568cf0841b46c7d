"""Rigid-body terms from a URDF for a log that already exists (long format, one block of rows
per joint, all joints sampled at the same times)."""

from __future__ import annotations

import json

import numpy as np

from fricli.core import logs
from fricli.core.errors import LogError
from fricli.robot.importing import robot_terms
from fricli.robot.mapping import JointMap, Mapping

META_KEY = b"fricli.dynamics"


def add_terms(table, model, name: str, *, match: str | None, urdf_names: dict[str, str] | None = None,
              rotor_inertia: dict[str, float] | None = None, gravity=logs.DEFAULT_GRAVITY, payload=None,
              cutoff_hz: float | str | None = None):
    """``table`` with tau_g and tau_dyn set (replaced if present) for every row, qd/qdd added
    when derived (``cutoff_hz`` as ``robot_terms``), and the record under the schema metadata key
    ``fricli.dynamics``.
    ``urdf_names`` and ``rotor_inertia`` are keyed by the joint's name as text."""
    import pyarrow as pa
    import pyarrow.compute as pc

    urdf_names, rotor_inertia = urdf_names or {}, rotor_inertia or {}
    if table.num_rows == 0:
        raise LogError(f"{name}: the log is empty")
    names = logs.joints_of(table)
    if names == [None]:
        raise LogError(f"{name}: the log has no 'joint' column: a robot model needs every joint's position")
    unknown = sorted((set(urdf_names) | set(rotor_inertia)) - {str(j) for j in names})
    if unknown:
        raise LogError(f"{name}: no joint {unknown[0]} in the log (it holds {', '.join(str(j) for j in names)})")
    logs_per_joint = [logs.from_table(table, name=name, joint=j) for j in names]
    axes = {log.axis for log in logs_per_joint}
    if len(axes) > 1:
        raise LogError(f"{name}: mixes rotary and linear joints")
    t = logs_per_joint[0].signals["t"]
    for log in logs_per_joint[1:]:
        if len(log) != len(t) or not np.array_equal(log.signals["t"], t):
            raise LogError(f"{name}: joints {names[0]} and {log.joint} are not sampled at the same times")
    mapping = Mapping(time=None, joints=[JointMap(name=j, columns={}, rotor_inertia=rotor_inertia.get(str(j), 0.0),
                                                  urdf=urdf_names.get(str(j))) for j in names],
                      match=match, gravity=tuple(gravity), payload=payload)
    # what the log lacks is derived where the robot terms are (with --cutoff auto, at the cut-off chosen there)
    per_joint = [{c: v for c, v in log.signals.items() if c not in log.derived.get("columns", [])}
                 for log in logs_per_joint]
    record = robot_terms(model, mapping, t, per_joint, axes.pop(), cutoff_hz)
    derived = record["derived"].get("columns", {})
    joint_col = table.column("joint")
    units = logs.CANONICAL[logs_per_joint[0].axis]
    for column, unit in (("qd", units["qd"]), ("qdd", units["qdd"]), ("tau_g", units["tau"]), ("tau_dyn", units["tau"])):
        if column in ("qd", "qdd") and column not in derived:
            continue
        values = np.empty(table.num_rows)
        for j, sig in zip(names, per_joint):
            values[np.asarray(pc.equal(joint_col, pa.scalar(j)))] = sig[column]
        table = logs.with_column(table, column, values, unit)
    meta = {**(table.schema.metadata or {}), META_KEY: json.dumps(record).encode()}
    return table.replace_schema_metadata(meta), record


def add_dynamics(log: str, urdf: str, output: str | None = None, *, match: str | None = None,
                 urdf_joints: dict | None = None, rotor_inertia: dict | None = None, gravity=None,
                 payload_mass: float | None = None, payload_com=None, payload_frame: str | None = None, held=(),
                 cutoff_hz: float | str | None = None):
    """``fricli dynamics``: the long-format log file ``log`` (- for stdin) of every moving joint of
    ``urdf`` with tau_g and tau_dyn from it, written to ``output`` when given (- for stdout).
    ``match`` ("name" or "order") says how the log's joints match the URDF's; ``urdf_joints``
    {log joint: URDF joint}, ``rotor_inertia`` {log joint: kg m^2}, ``gravity`` (3,) [m/s^2] (default:
    what the log's import recorded), ``payload_mass`` [kg], ``payload_com`` (3,) [m],
    ``payload_frame``, ``held`` URDF joints, ``cutoff_hz`` as the command's options. Returns (the
    table, the record written under its ``fricli.dynamics`` metadata); options that do not go
    together raise ``OptionError`` naming the option."""
    from fricli.fitting.optionspec import OptionError
    from fricli.robot import mapping as mp
    from fricli.robot.dynamics import load_model

    if match not in ("name", "order"):
        raise OptionError("choose how the log's joints match the URDF's: --match name|order", "match")
    payload = mp.payload_option(None, payload_mass, payload_com, payload_frame)
    table, _ = logs.read_table(log)
    name = "stdin" if log == "-" else log
    robot = Mapping(time=None, joints=[], gravity=logs.gravity_of(table.schema, gravity), payload=payload,
                    held=tuple(held) or logs.held_of(table.schema))
    model = load_model(urdf, robot)
    table, record = add_terms(table, model, name, match=match, urdf_names={str(k): v for k, v in
                                                                           (urdf_joints or {}).items()},
                              rotor_inertia={str(k): v for k, v in (rotor_inertia or {}).items()},
                              gravity=robot.gravity, payload=payload, cutoff_hz=cutoff_hz)
    if output is not None:
        logs.write_table(table, output)
    return table, record
