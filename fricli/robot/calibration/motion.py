"""The log's motion for a calibration: its joints matched to the URDF's, and the motors that drive
them (``motor_layout``); a log's recorded robot model (``recorded_motion``)."""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from fricli.core import logs, transmission
from fricli.core.errors import InvalidRows, LogError
from fricli.robot.dynamics import check_kind, require_positions
from fricli.numerics.threads import pinned


@dataclasses.dataclass
class Motion:
    """A whole-arm log in the URDF's joint order: arrays of shape (n, joints)."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    names: list            # the log's joint names, in URDF order
    rotor_inertia: np.ndarray  # (joints,) recorded by import/dynamics, NaN where unknown
    transmission: object = None  # the log's Transmission over URDF joint names, or None


@pinned
def read_motion(table, name: str, robot, *, match: str | None, urdf_names: dict[str, str] | None = None,
                cutoff_hz: float = logs.DEFAULT_CUTOFF_HZ) -> Motion:
    """The log's joints matched to ``robot`` (a ``RobotModel``): ``match`` "name"/"order", or None for
    the matching recorded by ``fricli import``/``fricli dynamics`` in the log's metadata."""
    names = logs.joints_of(table, name)
    if names is None or names == [None]:
        raise LogError(f"{name}: the log has no 'joint' column: calibration needs every joint of the arm")
    record = logs.robot_record(table.schema)
    urdf_names = dict(urdf_names or {})
    unknown = sorted(set(urdf_names) - {str(j) for j in names})
    if unknown:
        raise LogError(f"{name}: no joint {unknown[0]} in the log (it holds {', '.join(str(j) for j in names)})")
    if match is None:
        if not record.get("joints"):
            raise LogError(f"{name}: the log does not record how its joints match the URDF's: give --match name|order")
        match = "name"
        urdf_names = {**record["joints"], **urdf_names}
    try:
        per_joint = [logs.from_table(table, name=name, joint=j, cutoff_hz=cutoff_hz) for j in names]
    except InvalidRows as exc:   # no --drop-invalid here: a whole-arm fit takes every row of every joint
        raise LogError(f"{exc.what}; remove those rows from the log (fricli import drops malformed rows)") from None
    for j, log in zip(names, per_joint):
        require_positions(log.signals, f"{name}: joint {j}")
    t = per_joint[0].signals["t"]
    for log in per_joint[1:]:
        if len(log) != len(t) or not np.array_equal(log.signals["t"], t):
            raise LogError(f"{name}: joints {names[0]} and {log.joint} are not sampled at the same times")
    order = robot.match([urdf_names.get(str(j), str(j)) for j in names], match)
    for j, log, k in zip(names, per_joint, order):
        check_kind(robot, k, j, log.axis)
    by_urdf = [order.index(k) for k in range(len(order))]
    stack = lambda c: np.column_stack([per_joint[i].signals[c] for i in by_urdf])  # noqa: E731
    recorded = record.get("rotor_inertia") or {}
    rotor = np.array([recorded.get(str(names[i]), np.nan) for i in by_urdf], dtype=float)
    return Motion(t=t, q=stack("q"), qd=stack("qd"), qdd=stack("qdd"), tau=stack("tau_m"),
                  names=[names[i] for i in by_urdf], rotor_inertia=rotor,
                  transmission=_log_transmission(table, name, names, [robot.joints[k] for k in order]))


def _log_transmission(table, name: str, names: list, urdf_joints: list[str]):
    """The transmission the log records (``fricli.transmission``), its joints renamed to the URDF's
    (``urdf_joints[i]`` is log joint ``names[i]``'s); None when it records none."""
    try:
        tr = transmission.of_schema(table.schema.metadata)
    except ValueError as exc:
        raise LogError(f"{name}: {exc}") from None
    if tr is None:
        return None
    by_name = {str(j): u for j, u in zip(names, urdf_joints)}
    missing = [j for j in tr.joints if str(j) not in by_name]
    if missing:
        raise LogError(f"{name}: the log's transmission drives joint {missing[0]}, which the log does not hold")
    return transmission.Transmission([by_name[str(j)] for j in tr.joints], tr.ratio, tr.offset, tr.rotor_inertia)


def motion_check_ratio(robot, motion: Motion) -> np.ndarray | None:
    """The ratio matrix (URDF order) the mapping check of ``motion`` reads its motors through (None: a
    motor per joint)."""
    ratio, _, _, motors = motor_layout(robot, motion)
    return ratio if motors is not None else None


def motor_layout(robot, motion: Motion) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[int] | None]:
    """(R, g, a0, motors): the ratio matrix R (joints, joints) in URDF order (row m: the motor of URDF
    joint m); each motor's ratio to its own joint g (joints,) (R_mm, else the row's largest); each
    motor's prior rotor inertia seen at its own joint a0 = g^2 J0 (joints,) [kg m^2]; the URDF
    indices of the joints whose motors a transmission gives (None: none; every other joint has its
    own rotor, R = g = 1, a0 its armature prior: the URDF's ``rotor_params``, else the rotor inertia
    the log records, else 0).

    The transmission is the log's, else the URDF's (``fricli_transmission``). A motor's J0 is the
    URDF's per-motor value (same row of R), else for a motor alone on its joint that joint's
    armature prior / R_mm^2 (where the URDF gives the armature, or the transmission no rotor
    inertia), else the transmission's rotor inertia."""
    nj = len(robot.joints)
    armature0 = np.where(np.isnan(robot.armature), np.nan_to_num(motion.rotor_inertia), robot.armature)
    ratio, gain, rotor0 = np.eye(nj), np.ones(nj), armature0.copy()
    tr = motion.transmission if motion.transmission is not None else robot.transmission
    if tr is None:
        return ratio, gain, rotor0, None
    listed = [robot.joints.index(j) for j in tr.joints]
    ratio[np.ix_(listed, listed)] = tr.ratio
    gain = np.array([row[m] if row[m] else row[np.argmax(np.abs(row))] for m, row in enumerate(ratio)])
    own = {}
    if robot.transmission is not None:
        urdf = np.eye(nj)
        idx = [robot.joints.index(j) for j in robot.transmission.joints]
        urdf[np.ix_(idx, idx)] = robot.transmission.ratio
        own = {i: v for i, v in zip(idx, robot.transmission.rotor_inertia) if np.array_equal(urdf[i], ratio[i])}
    for m, i in enumerate(listed):
        alone = ratio[i, i] != 0 and np.count_nonzero(ratio[i]) == 1 and np.count_nonzero(ratio[:, i]) == 1
        if i in own:
            rotor0[i] = gain[i] ** 2 * own[i]
        elif not (alone and (not np.isnan(robot.armature[i]) or tr.rotor_inertia[m] == 0)):
            rotor0[i] = gain[i] ** 2 * tr.rotor_inertia[m]
    return ratio, gain, rotor0, sorted(listed)


def motor_units(gain: np.ndarray, stribeck: bool = False) -> np.ndarray:
    """Per parameter (14 or 15 * joints,), what a motor's parameter is multiplied by to be seen at its own
    joint (``motor_layout``'s g): 1 for inertial parameters, g^2 for J_m and Fv, |g| for Fc (and
    Fs - Fc), g for the offset."""
    fric = np.column_stack([gain ** 2, np.abs(gain), gain]).reshape(-1)
    return np.concatenate([np.ones(10 * len(gain)), gain ** 2, fric] + ([np.abs(gain)] if stribeck else []))


def reflected(ratio: np.ndarray, rotor: np.ndarray) -> np.ndarray:
    """R^T diag(J_m) R (joints, joints) [kg m^2]: rotor inertias ``rotor`` (joints,) seen at the joints."""
    return ratio.T @ (rotor[:, None] * ratio)


def edge_rows(t: np.ndarray, edge_s: float) -> np.ndarray:
    """Rows at least ``edge_s`` seconds from either end, (n,) bool."""
    return (t >= t[0] + edge_s) & (t <= t[-1] - edge_s)


def recorded_urdf(table) -> str | None:
    """The URDF the log's tau_g and tau_dyn came from, as ``import``/``dynamics`` recorded it: the
    path as given when it is a file from here, else its absolute path when that is (a log used from
    another folder), else the path as given (None: none recorded)."""
    record = logs.robot_record(table.schema)
    given = record.get("urdf") or None
    for path in (given, record.get("urdf_path")):
        if path and os.path.isfile(path):
            return path
    return given


@pinned
def recorded_motion(table, name: str, urdf: str | None = None, *, cutoff_hz: float = logs.DEFAULT_CUTOFF_HZ):
    """(record, robot, motion) of a whole-arm log imported with a URDF: what ``import``/``dynamics``
    recorded, the robot model of ``urdf`` (default: the recorded URDF) with the recorded gravity and
    no payload, the joints it held, and the log's motion matched to it as recorded."""
    from fricli.robot.dynamics import load_model
    from fricli.robot.mapping import Mapping

    record = logs.robot_record(table.schema)
    if not record.get("joints"):
        raise LogError(f"{name}: the log records no robot model (import it with --urdf)")
    gravity = logs.gravity_of(table.schema)
    robot = load_model(urdf or recorded_urdf(table), Mapping(time=None, joints=[], gravity=gravity,
                                                           held=logs.held_of(table.schema)))
    return record, robot, read_motion(table, name, robot, match=None, cutoff_hz=cutoff_hz)
