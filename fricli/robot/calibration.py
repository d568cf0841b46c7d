"""Identify a robot's rigid-body model together with its joint friction from one whole-arm log.

The inverse dynamic model, linear in its parameters (IDIM):

    tau_m = Y(q, qd, qdd) pi + diag(qdd) a + sum_j [qd_j, sign(qd_j), 1] f_j

``Y``: Pinocchio's joint-torque regressor (``computeJointTorqueRegressor``, gravity included),
``pi``: the 10 standard inertial parameters of every moving body (Pinocchio's order
m, m c, inertia at the joint origin), ``a``: the reflected rotor inertia (armature) per joint,
``f_j = (Fv, Fc, offset)``: joint j's linear friction (optionally with the LuGre static curve's
Stribeck bump, linear for a given Stribeck velocity, which alternates with the fit).

With a transmission (``fricli.core.transmission``: motor velocities w = R qd, joint torques R^T
tau_motor) the rotors and the friction belong to the motors: row m of R is the motor of joint m,
``a`` becomes the motors' rotor inertias J_m (the torque R^T diag(J_m) R qdd, column of J_m:
R[m, :]^T (R[m, :] qdd), which holds the cross-term of coupled joints) and ``f_m`` motor m's
friction in w_m (columns R[m, :]^T [w_m, sign(w_m), 1]). One rotor per joint is R = identity:
the same columns, the armature.

The estimate is the least-squares fit of all parameters with a Gaussian prior centred on the URDF's
CAD values (maximum a posteriori, a ridge on the deviation from CAD): each parameter's prior
standard deviation is ``prior`` times its scale (mass: the CAD mass; first moment: mass x length;
inertia: mass x length^2, length = max(|CAD centre of mass|, 0.1 m); armature: the largest of its
prior value, the joint's CAD mass-matrix diagonal at q = 0 (over R_mj^2 for a motor) and the inertia
that would carry the motor's RMS torque at its RMS acceleration (a geared rotor reflects far more
inertia than a wrist's own link: no CAD value bounds it); friction: loose).
``prior`` "auto" chooses the strength, for all parameters and then per body and armature, by cross-validation
over blocks of time of the log (``choose_prior``).
Each joint's rows are those where it is in motion (``fricli.core.metrics.in_motion``; with a
transmission, every motor that drives it): at rest a joint holds whatever torque its last motion
left, which no friction law of the velocity gives.
Each joint's rows are weighted by 1 / its residual standard deviation, re-estimated until it settles
(iteratively reweighted; standard IDIM practice), so the prior matters only where the data say
little: directions the run does not excite stay at CAD, and the report names them.
"""

from __future__ import annotations

import dataclasses
import math
import os
import xml.etree.ElementTree as ET

import numpy as np

from fricli.core import logs, metrics, transmission
from fricli.core.errors import DataError, FitError, LogError, ModelFileError
from fricli.numerics.threads import pinned

PARAMS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")   # Pinocchio's dynamic parameters
FRICTION = ("Fv", "Fc", "offset")
#: the friction fitted with the robot model by diagnose --calibrate, which refits each joint's friction
#: model afterwards: the calibration's friction only has to keep friction out of the inertial
#: parameters, and a Stribeck bump left to the linear law is taken up by them (docs/diagnose.md)
LOOP_FRICTION = "stribeck"
DEFAULT_PRIOR = "auto"     # prior std of an inertial parameter relative to its scale, or chosen by held-out fit
PRIOR_GRID = (0.01, 0.03, 0.1, 0.2, 0.5, 1.0, 3.0, 10.0)   # the prior strengths "auto" chooses from
PRIOR_FOLDS = 10           # contiguous blocks of time of the cross-validation that chooses the prior (as diagnose)
PRIOR_START = 0.5          # the fixed strength whose fit gives the cross-validation's row weights
DEFAULT_EDGE_S = 0.5       # rows dropped at each end [s]: the zero-phase filter's and differences' transients
MIN_LENGTH = 0.1           # m: the length scale of a body whose CAD centre of mass is closer to its joint
SUSPICIOUS = 0.30          # a mass or armature this far from its prior value is flagged
POOR_EXCITATION = 1e3      # a scaled base regressor's condition number above this is flagged (varied runs: 10-300)
UNDETERMINED = 1.0         # a direction whose data information is below the prior's stays at CAD
NUMERIC_ZERO = 1e-10       # ... or below this share of the best-determined direction's
MAX_ITERATIONS = 30
MEMORY_COPIES = 6          # peak memory of a calibration / its regressor's size (5.4 measured on 4.5 M rows)
MIN_ROWS = 20              # a joint in motion in fewer rows is refused
STRIBECK_ALTERNATIONS = 4
STRIBECK_GRID = np.geomspace(0.005, 0.5, 25)   # Stribeck velocities searched, x the joint's top speed
TOLERANCE = 1e-9           # relative: a body on the boundary of consistency (a thin rod, a point) passes
OTHER_CAUSES = ("a drive gain off by a similar share on the joints that carry it", "a cable or hose pulling on the arm",
                "a counterbalance spring", "a tool or payload not in the URDF")


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
    per_joint = [logs.from_table(table, name=name, joint=j, cutoff_hz=cutoff_hz) for j in names]
    t = per_joint[0].signals["t"]
    for log in per_joint[1:]:
        if len(log) != len(t) or not np.array_equal(log.signals["t"], t):
            raise LogError(f"{name}: joints {names[0]} and {log.joint} are not sampled at the same times")
    if per_joint[0].axis != "rotary" and any(k == "rotary" for k in robot.kinds):
        raise LogError(f"{name}: the log's units are linear, the URDF's joints rotary")
    order = robot.match([urdf_names.get(str(j), str(j)) for j in names], match)
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


# --------------------------------------------------------------------------- the regressor


def bodies(robot) -> list[str]:
    """The URDF link moved by each joint (the body Pinocchio merges fixed children into)."""
    model = robot.pin_model
    out = []
    for i in range(1, model.njoints):
        joint_frame = model.getFrameId(model.names[i])
        link = next((f.name for f in model.frames if f.parentJoint == i and f.name != model.names[i]
                     and getattr(f, "parentFrame", None if hasattr(f, "parentFrame") else f.previousFrame) == joint_frame),
                    model.names[i])
        out.append(link)
    return out


def attached(robot) -> tuple[list[list[str]], np.ndarray]:
    """Per body, the URDF links with an inertia fixed to its moving link (a gripper's), and their CAD
    parameters summed in the joint frame (10 * joints,)."""
    pin = _pin()
    model = robot.pin_model
    names, total = [], np.zeros(10 * len(robot.joints))
    for i, link in enumerate(bodies(robot), start=1):
        names.append([])
        for f in model.frames:
            if (f.parentJoint == i and f.type == pin.FrameType.BODY and f.name != link
                    and robot.links.get(f.name, np.zeros(10)).any()):
                names[-1].append(f.name)
                total[10 * i - 10:10 * i] += moved(robot.links[f.name], f.placement.homogeneous)
    return names, total


def moved(pi: np.ndarray, placement: np.ndarray) -> np.ndarray:
    """Inertial parameters (10,) of a link given in its own frame, expressed in the frame where that one
    sits at ``placement`` (4, 4): the pseudo-inertia's congruence T J T^T, linear (any 10-vector)."""
    return _from_pseudo(placement @ pseudo_inertia(pi) @ placement.T)


def parameter_names(robot, stribeck: bool = False, motors: list[int] | None = None) -> list[str]:
    """Every parameter's name: BODY.m ..., JOINT.armature, JOINT.Fv/Fc/offset (and JOINT.Fs-Fc); for
    the joints ``motors`` (URDF indices) whose motors a transmission gives, motor@JOINT.rotor_inertia,
    motor@JOINT.Fv ... instead."""
    own = [f"motor@{j}" if k in (motors or ()) else j for k, j in enumerate(robot.joints)]
    return ([f"{b}.{p}" for b in bodies(robot) for p in PARAMS]
            + [f"{j}.rotor_inertia" if j.startswith("motor@") else f"{j}.armature" for j in own]
            + [f"{j}.{f}" for j in own for f in FRICTION] + ([f"{j}.Fs-Fc" for j in own] if stribeck else []))


def regressor(robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, vs: np.ndarray | None = None,
              ratio: np.ndarray | None = None) -> np.ndarray:
    """The full observation matrix, shape (n * joints, 14 * joints): the rows of sample k are
    k * joints ... (k + 1) * joints - 1 (joint order of the URDF); columns as ``parameter_names``.
    With Stribeck velocities ``vs`` (joints,) one more column per joint, ``stribeck_columns``.
    ``ratio``: R (joints, joints) of ``motor_layout`` (default the identity: one rotor per joint)."""
    pin = _pin()
    model = robot.pin_model
    data = model.createData()
    config = robot.configuration(q)
    n, nj = q.shape
    ratio = np.eye(nj) if ratio is None else ratio
    out = np.zeros((n, nj, 14 * nj))
    for k in range(n):
        out[k, :, :10 * nj] = pin.computeJointTorqueRegressor(model, data, config[k], qd[k], qdd[k])
    w = qd @ ratio.T                                                  # motor velocities, (n, motors)
    out[:, :, 10 * nj:11 * nj] = ratio.T * (qdd @ ratio.T)[:, None, :]   # [k, j, m] = R[m, j] (R qdd_k)_m
    basis = np.stack([w, np.sign(w), np.ones_like(w)], axis=2)       # (n, motors, 3)
    out[:, :, 11 * nj:] = (ratio.T[None, :, :, None] * basis[:, None]).reshape(n, nj, 3 * nj)
    out = out.reshape(n * nj, 14 * nj)
    return out if vs is None else np.hstack([out, stribeck_columns(qd, vs, ratio)])


def stribeck_columns(qd: np.ndarray, vs: np.ndarray, ratio: np.ndarray | None = None) -> np.ndarray:
    """The Stribeck bump sign(w_m) exp(-(w_m / vs_m)^2) of each motor m (w = R qd; without ``ratio``
    each joint's own) in the rows of the joints it drives, times R[m, j]: (n * joints, motors)."""
    n, nj = qd.shape
    ratio = np.eye(nj) if ratio is None else ratio
    w = qd @ ratio.T
    return (ratio.T * (np.sign(w) * np.exp(-np.square(w / vs)))[:, None, :]).reshape(n * nj, nj)


def _pin():
    from fricli.robot.dynamics import pinocchio

    return pinocchio()


def cad_parameters(robot) -> np.ndarray:
    """The URDF's inertial parameters (10 per body), (10 * joints,)."""
    model = robot.pin_model
    return np.concatenate([model.inertias[i].toDynamicParameters() for i in range(1, model.njoints)])


def prior_scales(robot, pi_cad: np.ndarray, armature0: np.ndarray, qd_rms: np.ndarray, qdd_rms: np.ndarray,
                 tau_rms: np.ndarray, prior: float, ratio: np.ndarray | None = None) -> np.ndarray:
    """Prior standard deviation of every parameter, (14 * joints,) (see the module docstring);
    ``armature0``: each motor's prior rotor inertia, ``qd_rms``, ``qdd_rms`` and ``tau_rms``: each
    motor's RMS velocity, acceleration and torque, (joints,), for motors of ``ratio`` (default: one
    per joint)."""
    pin = _pin()
    nj = len(robot.joints)
    masses = pi_cad[0::10]
    m_floor = max(1e-3, 0.01 * float(masses.sum()))
    scale = []
    for b in range(nj):
        m = max(masses[b], m_floor)
        c = pi_cad[10 * b + 1:10 * b + 4] / masses[b] if masses[b] > 0 else np.zeros(3)
        length = max(float(np.linalg.norm(c)), MIN_LENGTH)
        scale += [m] + [m * length] * 3 + [m * length ** 2] * 6
    model = robot.pin_model
    diag = np.diag(pin.crba(model, model.createData(), pin.neutral(model)))
    diag = diag - np.asarray(model.armature)
    ratio = np.eye(nj) if ratio is None else ratio
    # each motor: the loosest of its joints' diagonals / R_mj^2 (over the joints it drives)
    per_joint = np.divide(diag, np.square(ratio), out=np.full(np.shape(ratio), -np.inf), where=ratio != 0)
    arm = np.maximum(armature0, per_joint.max(axis=1))
    arm = np.maximum(arm, tau_rms / np.maximum(qdd_rms, 1e-300))   # a rotor may carry its motor's whole torque
    fric = []
    for j in range(nj):
        loose = 10.0 * max(tau_rms[j], 1e-6)
        fric += [loose / max(qd_rms[j], 1e-6), loose, loose]
    return np.concatenate([prior * np.asarray(scale), prior * np.maximum(arm, 1e-9), fric])


# --------------------------------------------------------------------------- identification


@dataclasses.dataclass
class Calibration:
    """The identified parameters and the report (plain JSON types)."""

    x: np.ndarray              # every parameter, (14 or 15 * joints,): inertial, armature, friction (, Fs - Fc)
    x0: np.ndarray             # the prior's centre (CAD, prior armature, zero friction)
    names: list[str]
    bodies: list[str]
    joints: list[str]          # URDF joints
    report: dict
    ratio: np.ndarray | None = None   # R (joints, joints) of ``motor_layout``; None: one rotor per joint
    motors: list[int] | None = None   # URDF indices of the joints whose motors a transmission gives
    payload: np.ndarray | None = None   # (10 * joints,) a declared payload in each body: not the URDF's
    attached: list | None = None        # per body, the links with an inertia fixed to its moving link
    attached_cad: np.ndarray | None = None   # (10 * joints,) their CAD parameters, summed in the joint frame

    def links(self, x: np.ndarray | None = None) -> np.ndarray:
        """What the URDF's links of each body hold (10 * joints,): the body less a declared payload."""
        pi = (self.x if x is None else x)[:10 * len(self.joints)]
        return pi if self.payload is None else pi - self.payload

    def armature(self, x: np.ndarray | None = None) -> np.ndarray:
        """Each joint's reflected rotor inertia (joints,) [kg m^2]: the diagonal of R^T diag(J_m) R."""
        nj = len(self.joints)
        rotor = (self.x if x is None else x)[10 * nj:11 * nj]
        return rotor.copy() if self.ratio is None else np.diag(reflected(self.ratio, rotor)).copy()

    def motor_of(self, j: int) -> str:
        """How the report names the rotor of URDF joint index ``j``."""
        return f"motor of joint {self.joints[j]}" if j in (self.motors or ()) else f"joint {self.joints[j]}"


@pinned
def calibrate(robot, motion: Motion, *, prior: float | str = DEFAULT_PRIOR, edge_s: float = DEFAULT_EDGE_S,
              enforce: bool = True, friction: str = "linear", seed: int = 0) -> Calibration:
    """Identify inertial parameters, armature and linear friction of ``robot`` from ``motion`` (per
    motor with a transmission, ``motor_layout``).
    ``enforce``: when the linear estimate is physically inconsistent, fit again over consistent
    parameters only (``consistent_fit``). ``seed`` fixes the random configurations of the
    structural (trajectory-independent) analysis. ``friction``: "linear" (Fv, Fc, offset per joint)
    or "stribeck" (and the bump (Fs - Fc) sign(qd) exp(-(qd / vs)^2) of the LuGre static curve, vs
    per joint alternated with the linear fit by a search on a grid). ``prior``: the prior strength
    (a float) or "auto" (``choose_prior``: the strength on ``PRIOR_GRID`` whose fits predict held-out
    blocks of time of the log best)."""
    if friction not in ("linear", "stribeck"):
        raise ValueError(f"unknown friction kind {friction!r}")
    nj = len(robot.joints)
    keep = edge_rows(motion.t, edge_s)
    if keep.sum() < MIN_ROWS:
        raise DataError(f"the log has {int(keep.sum())} rows more than {edge_s:g} s from its ends: too few to calibrate")
    still = [str(motion.names[j]) for j in np.flatnonzero(metrics.held_still(motion.q[keep]))]
    if still:
        raise DataError(f"joint{'s' if len(still) > 1 else ''} {', '.join(still)} "
                        f"{'are' if len(still) > 1 else 'is'} held still (position span under {metrics.HELD_SPAN:g} "
                        "rad): calibration needs every joint of the arm in motion, as in an excitation run")
    q, qd, qdd, tau = motion.q[keep], motion.qd[keep], motion.qdd[keep], motion.tau[keep]
    n = len(q)
    # fitted in each motor's units seen at its own joint (ratio / g; with one rotor per joint: the identity)
    ratio, gain, rotor0, motors = motor_layout(robot, motion)
    norm = np.where(ratio != 0, ratio / gain[:, None], 0.0)
    w = qd @ norm.T                                          # motor velocities / g (n, motors)
    sliding = np.column_stack([metrics.in_motion(w[:, m]) for m in range(nj)])
    use = np.column_stack([sliding[:, norm[:, j] != 0].all(axis=1) for j in range(nj)])   # (n, joints)
    counts = use.sum(axis=0)
    if counts.min() < MIN_ROWS:
        raise DataError(f"joint {motion.names[int(np.argmin(counts))]} is in motion in {int(counts.min())} rows: "
                        "too few to calibrate")
    check_memory(n, nj)
    mask = use.reshape(-1).astype(float)
    Phi = regressor(robot, q, qd, qdd, ratio=norm) * mask[:, None]
    y = tau.reshape(-1) * mask
    stribeck = friction == "stribeck"
    names = parameter_names(robot, stribeck, motors)
    pi_cad = cad_parameters(robot)
    fixed_links, fixed_cad = attached(robot)
    payload = robot.payload_parameters.reshape(-1)
    x0 = np.concatenate([pi_cad, rotor0, np.zeros(3 * nj)])
    tau_rms = np.sqrt(np.mean(tau ** 2, axis=0))

    def to_motors(joint_side):   # torques (n, joints) -> (n, motors), rows contiguous as the joints' were
        return np.ascontiguousarray(np.linalg.solve(norm.T, joint_side.T).T)

    motor_rms = np.sqrt(np.mean(to_motors(tau) ** 2, axis=0))
    s1 = prior_scales(robot, pi_cad, rotor0, np.sqrt(np.mean(w ** 2, axis=0)),
                      np.sqrt(np.mean(np.square(qdd @ norm.T), axis=0)), motor_rms, 1.0, norm)

    # before: the CAD model (with the prior armature) and each motor's friction fitted alone to its torque
    r0 = to_motors((y - Phi @ x0).reshape(n, nj))
    before = np.empty((n, nj))
    fric_before = {}
    for m in range(nj):
        cols = np.column_stack([w[:, m], np.sign(w[:, m]), np.ones(n)]) * sliding[:, m, None]
        coef = np.linalg.lstsq(cols, r0[:, m] * sliding[:, m], rcond=None)[0]
        before[:, m] = r0[:, m] - cols @ coef
        fric_before[m] = coef
    before = (before @ norm) * use                          # joint side: R^T (motor torques)
    sigma = np.maximum(np.sqrt(np.sum(before ** 2, axis=0) / counts), 1e-9 * tau_rms + 1e-300)

    rows_of = np.tile(np.arange(nj), n)
    prior_choice, strengths = None, float(prior) if prior != "auto" else None
    if prior == "auto":
        strengths, prior_choice = choose_prior(Phi, y, x0, s1, sigma, rows_of, tau_rms, counts)
        prior = prior_choice["chosen"]
        if "per_group" in prior_choice:
            groups = bodies(robot) + names[10 * nj:11 * nj]
            prior_choice["per_group"] = dict(zip(groups, prior_choice["per_group"]))
    s = _with_prior(s1, nj, strengths)
    vs = None
    if stribeck:
        top = np.abs(w).max(axis=0)
        vs = 0.1 * top
        grids = []      # a Stribeck velocity below the slowest row in motion has no rows to be fitted on
        for m in range(nj):
            grid = top[m] * STRIBECK_GRID
            slowest = np.abs(w[sliding[:, m], m]).min()
            grids.append(grid[grid >= slowest] if grid[-1] >= slowest else grid[-1:])
        x0 = np.concatenate([x0, np.zeros(nj)])
        s = np.concatenate([s, 10.0 * np.maximum(motor_rms, 1e-6)])
        for _ in range(STRIBECK_ALTERNATIONS):
            Phi_s = np.hstack([Phi, stribeck_columns(qd, vs, norm) * mask[:, None]])
            x, sigma, resid, iteration = _map_fit(Phi_s, y, x0, s, sigma, rows_of, tau_rms, counts)
            own = (Phi_s[:, 11 * nj:] * x[11 * nj:]).reshape(n, nj, -1).sum(axis=2)  # friction part, (n, nj)
            target = to_motors(resid + own)
            for m in range(nj):
                on = sliding[:, m]
                vs[m] = min(grids[m], key=lambda v: _stribeck_rss(w[on, m], target[on, m], v))
        Phi = np.hstack([Phi, stribeck_columns(qd, vs, norm) * mask[:, None]])
    x, sigma, resid, iteration = _map_fit(Phi, y, x0, s, sigma, rows_of, tau_rms, counts)

    A = (Phi / sigma[rows_of, None]) * s
    excitation = _excitation(robot, A, Phi, s, names, seed, vs, norm)
    unit = motor_units(gain, stribeck)      # x / unit: in motor units
    layout = {"x0": x0 / unit, "names": names, "bodies": bodies(robot), "joints": list(robot.joints),
              "ratio": None if motors is None else ratio, "motors": motors, "payload": payload,
              "attached": fixed_links, "attached_cad": fixed_cad}
    linear = Calibration(x=x / unit, report={}, **layout)
    broken = consistency(linear)["problems"]
    enforced = None
    if broken and enforce:
        x = consistent_fit(Phi / sigma[rows_of, None], y / sigma[rows_of], x, x0, s, nj, payload)
        resid = (y - Phi @ x).reshape(n, nj)
        enforced = {"inconsistent_before": broken, "rms_linear": {str(motion.names[j]): float(sigma[j])
                                                                  for j in range(nj)}}
    report = {
        "rows": int(n), "rows_dropped_at_ends": int((~keep).sum()), "edge_s": edge_s,
        "prior": float(prior), "prior_choice": prior_choice, "iterations": iteration,
        "excitation": excitation,
        "fit": {str(motion.names[j]): {"urdf_joint": robot.joints[j],
                                       "rms_before": float(np.sqrt(np.sum(before[:, j] ** 2) / counts[j])),
                                       "rms_after": float(np.sqrt(np.sum(resid[:, j] ** 2) / counts[j])),
                                       "noise_std": float(sigma[j]), "rows_in_motion": int(counts[j])}
                for j in range(nj)},
        "friction": _friction_report(robot, motion, x / unit, None if vs is None else vs * np.abs(gain), motors),
        "friction_with_cad": {str(motion.names[j]): {f: float(fric_before[j][k] / unit[11 * nj + 3 * j + k])
                                                     for k, f in enumerate(FRICTION)} for j in range(nj)},
        "consistency_enforced": enforced,
    }
    cal = Calibration(x=x / unit, report=report, **layout)
    report["armature"] = {robot.joints[j]: {"prior": float(a0), "identified": float(a)}
                          for j, (a0, a) in enumerate(zip(cal.armature(cal.x0), cal.armature()))}
    if motors is not None:
        report.update(_motor_report(cal, motion))
    report["links"] = link_table(cal)
    report["consistency"] = consistency(cal)
    report["suspicious"] = suspicious(cal, excitation["masses_not_determined_alone"])
    from fricli.robot import sanity

    report["mapping_check"] = sanity.check_motion(robot, motion, motion_check_ratio(robot, motion))
    for finding in reversed(report["mapping_check"]["findings"]):
        report["suspicious"].insert(0, f"the log's mapping disagrees with the URDF: {finding['message']}")
    if excitation["condition_number_scaled"] > POOR_EXCITATION:
        report["suspicious"].insert(0, (
            f"the run excites the arm's dynamics poorly: condition number {excitation['condition_number_scaled']:.3g} "
            f"of the scaled base regressor (above {POOR_EXCITATION:g}; a varied excitation run gives tens to a few "
            "hundred): parameters it barely sees are fitted to whatever else moves the torques (a push, a held "
            "load, noise); check the calibrated model on another run before using it"))
    return cal


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux: MemAvailable), None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_memory(n: int, nj: int) -> None:
    """DataError before a calibration of ``n`` samples of ``nj`` joints that would exhaust memory:
    the regressor holds n * nj rows of 15 * nj float64 columns, and the fit several of its copies."""
    need = MEMORY_COPIES * n * nj * 15 * nj * 8
    have = available_memory()
    if have is not None and need > have:
        raise DataError(f"calibrating {n:,} samples of {nj} joints needs about {need / 2**30:.2g} GiB of memory, "
                        f"{have / 2**30:.2g} GiB are available: calibrate on part of the log (--from, --until)")


def _with_prior(s1: np.ndarray, nj: int, prior) -> np.ndarray:
    """Prior std (as ``prior_scales``) for strength ``prior`` (a float, or one per inertial parameter
    and armature, (11 * joints,)) from those for strength 1: friction's loose prior does not scale."""
    return np.concatenate([np.asarray(prior, dtype=float) * s1[:11 * nj], s1[11 * nj:]])


def choose_prior(Phi, y, x0, s1, sigma, rows_of, tau_rms, counts, *, per_group: bool = True, grid=PRIOR_GRID,
                 folds=PRIOR_FOLDS) -> tuple[np.ndarray, dict]:
    """The prior strengths on ``grid`` whose fits predict held-out data best (ridge selection by
    blocked cross-validation): the log cut into ``folds`` contiguous blocks of time, each predicted
    by the fit on the others; score: the held-out sum of squared residuals, each joint's rows weighted
    by 1 / its residual std in the fit at ``PRIOR_START``. First one strength for every parameter;
    then, with ``per_group``, each group's own in turn (each body's 10 inertial parameters, centred
    on CAD; each joint's armature, centred on the rotor inertia), until no group's change lowers the
    score. The weakest prior wins ties (noise-free data need none). ``Phi`` (n * joints, p),
    ``y`` (n * joints,), zero in the rows not used, ``counts`` (joints,) each joint's rows used,
    ``s1``: prior std at strength 1.
    Returns (strength of every inertial parameter and armature (11 * joints,), report)."""
    from scipy.linalg import solve_triangular

    from fricli.fitting.diagnosis.selection import fold_bounds

    nj = len(sigma)
    _, w, _, _ = _map_fit(Phi, y, x0, _with_prior(s1, nj, PRIOR_START), sigma, rows_of, tau_rms, counts)
    Wr = np.column_stack([Phi, y - Phi @ x0]) / w[rows_of, None]       # weighted regressor | residual at x0
    edges = fold_bounds(len(y) // nj, folds) * nj
    # each block as the R factor of its [W r]: |W_k d - r_k| = |R_k [d; -1]| without forming W^T W,
    # whose round-off swamps a held-out error far below the CAD model's (noise-free data)
    blocks = [np.linalg.qr(Wr[a:b], mode="r") for a, b in zip(edges[:-1], edges[1:])]
    others = [np.linalg.qr(np.vstack(blocks[:k] + blocks[k + 1:]), mode="r") for k in range(len(blocks))]
    p = Phi.shape[1]
    tie = 1e-9 * float(np.sum(np.square(Wr[:, -1])))     # round-off of the scores below

    def score(strengths):
        s = _with_prior(s1, nj, strengths)
        total = 0.0
        for Rk, Ro in zip(blocks, others):    # the fit without block k (ridge in z = d / s), scored on block k
            q, r = np.linalg.qr(np.vstack([Ro[:, :p] * s, np.eye(p)]))
            d = s * solve_triangular(r, q[:len(Ro)].T @ Ro[:, p])
            total += float(np.sum(np.square(Rk[:, :p] @ d - Rk[:, p])))
        return total

    held = lambda v: float(np.sqrt(max(v, 0.0) / counts.sum()))  # noqa: E731
    weak_first = sorted(grid, reverse=True)
    scores = {g: score(np.full(11 * nj, g)) for g in weak_first}
    chosen = max(g for g, v in scores.items() if v <= min(scores.values()) + tie)
    strengths, best = np.full(11 * nj, chosen), scores[chosen]
    per = np.full(2 * nj, chosen)      # each body's inertial parameters, then each joint's armature
    for _ in range(3 * per_group):
        changed = False
        for b in range(2 * nj):
            for g in weak_first:
                trial = per.copy()
                trial[b] = g
                cols = np.concatenate([np.repeat(trial[:nj], 10), trial[nj:]])
                v = score(cols)
                if v < best - tie:
                    per, strengths, best, changed = trial, cols, v, True
        if not changed:
            break
    report = {"grid": sorted(grid), "folds": folds, "chosen": chosen,
              "held_out_rms": {f"{g:g}": held(v) for g, v in sorted(scores.items())}}
    if per_group:
        report.update(per_group=[float(v) for v in per], held_out_rms_per_group=held(best))
    return strengths, report


def _map_fit(Phi, y, x0, s, sigma, rows_of, tau_rms, counts):
    """Maximum a posteriori estimate, rows weighted by each joint's residual std, re-estimated until
    the weights settle: (x, sigma (joints,), residuals (n, joints), iterations). Rows not used are
    zero in ``Phi`` and ``y``; ``counts`` (joints,): each joint's rows used."""
    nj = len(sigma)
    for iteration in range(1, MAX_ITERATIONS + 1):
        A = (Phi / sigma[rows_of, None]) * s
        z = np.linalg.lstsq(np.vstack([A, np.eye(len(s))]),
                            np.concatenate([(y - Phi @ x0) / sigma[rows_of], np.zeros(len(s))]), rcond=None)[0]
        x = x0 + s * z
        resid = (y - Phi @ x).reshape(-1, nj)
        new = np.maximum(np.sqrt(np.sum(resid ** 2, axis=0) / counts), 1e-9 * tau_rms + 1e-300)
        settled = np.max(np.abs(np.log(new / sigma))) < 0.01
        sigma = new
        if settled:
            break
    return x, sigma, resid, iteration


def _stribeck_rss(qd: np.ndarray, target: np.ndarray, vs: float) -> float:
    cols = np.column_stack([qd, np.sign(qd), np.sign(qd) * np.exp(-np.square(qd / vs)), np.ones_like(qd)])
    coef = np.linalg.lstsq(cols, target, rcond=None)[0]
    return float(np.sum(np.square(target - cols @ coef)))


def _motor_report(cal: Calibration, motion: Motion) -> dict:
    """Per motor of the transmission: its joint, row of R, prior and identified rotor inertia; and the
    reflected inertia R^T diag(J_m) R of those joints (its off-diagonal: the rotors' cross-term)."""
    nj, listed = len(cal.joints), cal.motors
    joints = [cal.joints[i] for i in listed]
    sub = lambda x: reflected(cal.ratio, x[10 * nj:11 * nj])[np.ix_(listed, listed)].tolist()  # noqa: E731
    return {
        "motors": {cal.joints[m]: {"log_joint": str(motion.names[m]),
                                   "ratio": {cal.joints[j]: float(cal.ratio[m, j]) for j in listed if cal.ratio[m, j]},
                                   "prior": float(cal.x0[10 * nj + m]), "identified": float(cal.x[10 * nj + m])}
                   for m in listed},
        "reflected_inertia": {"joints": joints, "prior": sub(cal.x0), "identified": sub(cal.x)},
    }


def _friction_report(robot, motion: Motion, x: np.ndarray, vs: np.ndarray | None, motors: list[int] | None) -> dict:
    """Friction per log joint, or per motor (named by its joint, ``"motor": true``, in its velocity w)."""
    nj = len(robot.joints)
    rotary = robot.kinds[0] == "rotary"
    units = {"Fv": "Nm s/rad", "Fc": "Nm", "offset": "Nm"} if rotary else {"Fv": "N s/m", "Fc": "N", "offset": "N"}
    joints = {}
    for j in range(nj):
        row = {"urdf_joint": robot.joints[j], **{f: float(x[11 * nj + 3 * j + k]) for k, f in enumerate(FRICTION)}}
        if j in (motors or ()):
            row["motor"] = True
        if vs is not None:
            row.update(Fs=row["Fc"] + float(x[14 * nj + j]), vs=float(vs[j]), delta=2.0)
        joints[str(motion.names[j])] = row
    side = {} if motors is None else {"motors": "a motor's friction f is in its velocity w = (R qd)_m, its "
                                                 "torque in motor units; the joints feel R^T f"}
    if vs is None:
        return {"kind": "linear", "model": "Fv*qd + Fc*sign(qd) + offset", "units": units, "joints": joints, **side}
    units.update(Fs=units["Fc"], vs="rad/s" if rotary else "m/s", delta="-")
    return {"kind": "stribeck", "model": "Fv*qd + (Fc + (Fs - Fc) exp(-|qd/vs|^delta)) sign(qd) + offset",
            "units": units, "joints": joints, **side}


def pseudo_inertia(pi: np.ndarray) -> np.ndarray:
    """The 4x4 pseudo-inertia [[Sigma, m c], [m c^T, m]] of 10 dynamic parameters, Sigma =
    tr(I_o)/2 - I_o: positive definite exactly for a physically consistent body (positive mass,
    positive-definite inertia, triangle inequality)."""
    m, h = pi[0], pi[1:4]
    i_o = np.array([[pi[4], pi[5], pi[7]], [pi[5], pi[6], pi[8]], [pi[7], pi[8], pi[9]]])
    out = np.empty((4, 4))
    out[:3, :3] = 0.5 * np.trace(i_o) * np.eye(3) - i_o
    out[:3, 3] = out[3, :3] = h
    out[3, 3] = m
    return out


def _from_pseudo(j: np.ndarray) -> np.ndarray:
    sigma = j[:3, :3]
    i_o = np.trace(sigma) * np.eye(3) - sigma
    return np.array([j[3, 3], *j[:3, 3], i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2], i_o[1, 2], i_o[2, 2]])


_TRIL = np.tril_indices(4)


def consistent_fit(A: np.ndarray, b: np.ndarray, x_start: np.ndarray, x0: np.ndarray, s: np.ndarray,
                   nj: int, fixed: np.ndarray | None = None) -> np.ndarray:
    """The same weighted least squares with the same prior (``A`` (rows, 14 nj) and ``b`` weighted),
    over physically consistent parameters only: each body (less ``fixed`` (10 nj,), a declared
    payload) as a pseudo-inertia L L^T (L lower triangular), each armature as u^2. From ``x_start``
    with eigenvalues clipped and from ``x0``: the better; returns x."""
    from scipy import linalg, optimize

    fixed = np.zeros(10 * nj) if fixed is None else fixed
    q, r = linalg.qr(A, mode="economic")
    c = q.T @ b            # |A x - b|^2 = |r x - c|^2 + a constant
    def start(x):        # theta of x, each pseudo-inertia's eigenvalues clipped to be positive
        theta = []
        for k in range(nj):
            w, v = np.linalg.eigh(pseudo_inertia(x[10 * k:10 * k + 10] - fixed[10 * k:10 * k + 10]))
            w = np.maximum(w, 1e-6 * max(w.max(), 1e-12))
            theta.append(np.linalg.cholesky((v * w) @ v.T)[_TRIL])
        arm = x[10 * nj:11 * nj]
        return np.concatenate(theta + [np.sqrt(np.maximum(arm, 1e-6 * s[10 * nj:11 * nj])), x[11 * nj:]])

    def params(th):
        pis = []
        for k in range(nj):
            low = np.zeros((4, 4))
            low[_TRIL] = th[10 * k:10 * k + 10]
            pis.append(_from_pseudo(low @ low.T))
        return np.concatenate([np.concatenate(pis) + fixed, th[10 * nj:11 * nj] ** 2, th[11 * nj:]])

    def dparams(th):   # d x / d theta: block diagonal
        out = np.zeros((len(th), len(th)))
        for k in range(nj):
            low = np.zeros((4, 4))
            low[_TRIL] = th[10 * k:10 * k + 10]
            for e, (a, b) in enumerate(zip(*_TRIL)):
                d = np.zeros((4, 4))
                d[a] = low[:, b]          # E_ab L^T + L E_ba: row a and column a of L's column b
                d = d + d.T
                out[10 * k:10 * k + 10, 10 * k + e] = _from_pseudo(d)
        idx = np.arange(10 * nj, 11 * nj)
        out[idx, idx] = 2 * th[idx]
        idx = np.arange(11 * nj, len(th))
        out[idx, idx] = 1.0
        return out

    stacked = np.vstack([r, np.diag(1.0 / s)])
    # convex in x, not in the factors: from a clipped estimate a body can sit where L is nearly singular
    # and the steps vanish, so the fit also starts from the prior's centre (CAD), and the lower cost wins
    fits = [optimize.least_squares(lambda th: np.concatenate([r @ params(th) - c, (params(th) - x0) / s]), start(x),
                                   jac=lambda th: stacked @ dparams(th), x_scale="jac", method="lm",
                                   xtol=1e-8, ftol=1e-6, max_nfev=2000) for x in (x_start, x0)]
    fits = [f for f in fits if np.all(np.isfinite(f.x))]
    if not fits:
        raise FitError("the physically consistent fit did not converge")
    return params(min(fits, key=lambda f: f.cost).x)


def _excitation(robot, A: np.ndarray, Phi: np.ndarray, s: np.ndarray, names: list[str], seed: int,
                vs: np.ndarray | None = None, ratio: np.ndarray | None = None) -> dict:
    """How well the run determines the parameters.

    Structural: the base parameters (QR with column pivoting of the unscaled regressor at random
    states, as ``base_parameters``: identical for every trajectory and prior). This run: the
    condition number of its base regressor, and the directions of the identifiable parameters whose
    data information (eigenvalue of the prior-whitened information matrix, 1 = as much as the
    prior's) is below ``UNDETERMINED``."""
    from scipy import linalg

    R0 = _random_regressor(robot, seed, vs, ratio)
    R_ = R0 * s
    _, r, piv = linalg.qr(R0, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    rank = int(np.sum(d > 1e-9 * d[0]))
    base = np.sort(piv[:rank])
    # the identifiable subspace (whitened coordinates): right singular vectors of the random regressor
    _, sv, vt = np.linalg.svd(R_, full_matrices=False)
    U = vt[:rank].T
    null = vt[rank:].T          # what no joint torque sees: a mass with a part here is not determined alone
    tied = {}
    for c in range(0, 10 * len(robot.joints), 10):
        v = null @ null[c]
        if abs(v[c]) > 1e-6:
            tied[names[c]] = [names[k] for k in np.argsort(-np.abs(v)) if k != c and abs(v[k]) > 1e-3 * abs(v[c])][:3]
    sv_run = np.linalg.svd(Phi[:, base], compute_uv=False)
    sv_scaled = np.linalg.svd(A[:, base] / np.linalg.norm(A[:, base], axis=0), compute_uv=False)
    g, V = np.linalg.eigh(U.T @ (A.T @ A) @ U)
    cut = max(UNDETERMINED, NUMERIC_ZERO * float(g.max()))
    undetermined = []
    for i in np.flatnonzero(g < cut):
        w = U @ V[:, i]
        w = w / np.abs(w).max()
        order = np.argsort(-np.abs(w))
        parts = [{"parameter": names[c], "weight": round(float(w[c]), 3)} for c in order[:4] if abs(w[c]) >= 0.2]
        undetermined.append({"information": float(max(g[i], 0.0)), "combination": parts})
    return {
        "parameters": len(s), "base_parameters": rank, "structurally_unidentifiable": len(s) - rank,
        "base": [names[c] for c in base],
        "condition_number": float(sv_run[0] / sv_run[-1]) if sv_run[-1] > 0 else math.inf,
        "condition_number_scaled": float(sv_scaled[0] / sv_scaled[-1]) if sv_scaled[-1] > 0 else math.inf,
        "undetermined": undetermined,
        "masses_not_determined_alone": tied,
    }


def _random_regressor(robot, seed: int, vs: np.ndarray | None = None, ratio: np.ndarray | None = None) -> np.ndarray:
    """The regressor at random states (positions uniform in [-pi, pi], standard normal velocities
    and accelerations): enough rows to show every structural dependency."""
    nj = len(robot.joints)
    rng = np.random.default_rng(seed)
    k = max(60, 30 * nj)
    qd = rng.normal(size=(k, nj))
    if vs is not None:     # motor velocities around each motor's Stribeck velocity
        qd = qd * 2 * vs if ratio is None else np.linalg.solve(ratio, (qd * 2 * vs).T).T
    return regressor(robot, rng.uniform(-np.pi, np.pi, (k, nj)), qd, rng.normal(size=(k, nj)), vs, ratio)


def base_parameters(robot, x: np.ndarray, seed: int = 0, ratio: np.ndarray | None = None,
                    motors: list[int] | None = None) -> tuple[np.ndarray, list[str]]:
    """The identifiable combinations of ``x`` (14 * joints,): base parameters ``x_B + beta x_D`` from
    QR with column pivoting of the unscaled regressor at random states; and their leading names.
    ``ratio`` and ``motors``: a calibration's (``Calibration.ratio``, ``Calibration.motors``)."""
    from scipy import linalg

    R_ = _random_regressor(robot, seed, ratio=ratio)
    _, r, piv = linalg.qr(R_, mode="economic", pivoting=True)
    d = np.abs(np.diag(r))
    rank = int(np.sum(d > 1e-9 * d[0]))
    beta = linalg.solve_triangular(r[:rank, :rank], r[:rank, rank:])
    names = parameter_names(robot, motors=motors)
    return x[piv[:rank]] + beta @ x[piv[rank:]], [names[c] for c in piv[:rank]]


# --------------------------------------------------------------------------- checks


def body_inertias(cal: Calibration, x: np.ndarray | None = None) -> list:
    """pin.Inertia of every body for parameters ``x`` (default the identified ones)."""
    pin = _pin()
    x = cal.x if x is None else x
    # a massless body (a URDF link with no <inertial>, or mass 0) has no centre of mass to divide by
    return [pin.Inertia.FromDynamicParameters(pi) if pi[0] != 0 else pin.Inertia.Zero()
            for pi in (np.asarray(x[10 * b:10 * b + 10], dtype=float) for b in range(len(cal.bodies)))]


def link_table(cal: Calibration) -> dict:
    """Mass [kg], centre of mass [m] and inertia at the centre of mass [kg m^2] of every body, CAD and identified."""
    out = {}
    for body, cad, new in zip(cal.bodies, body_inertias(cal, cal.x0), body_inertias(cal)):
        out[body] = {"mass_cad": float(cad.mass), "mass": float(new.mass),
                     "com_cad": cad.lever.tolist(), "com": new.lever.tolist(),
                     "inertia_cad": cad.inertia.tolist(), "inertia": new.inertia.tolist()}
    return out


def _physical(pi: np.ndarray, scale: float = 0.0) -> str | None:
    """Why the 10 parameters ``pi`` are no real body, or None: the mass positive, the inertia at the
    centre of mass positive definite, its principal moments satisfying the triangle inequality, each to
    ``TOLERANCE`` of the body's largest moment or of ``scale`` [kg m^2] (the arm's: a body the fit
    shrank to nothing must not fail on round-off)."""
    m = float(pi[0])
    if not m > 0:
        return f"mass {m:.4g} kg is not positive"
    inertia = _pin().Inertia.FromDynamicParameters(np.asarray(pi, dtype=float))
    moments = np.sort(np.linalg.eigvalsh(inertia.inertia))
    text = ", ".join(f"{v:.4g}" for v in moments)
    pseudo = np.linalg.eigvalsh(pseudo_inertia(pi))
    if moments[0] <= -TOLERANCE * max(abs(moments[-1]), scale):
        return f"inertia at the centre of mass is not positive definite (principal moments {text} kg m^2)"
    if pseudo[0] < -TOLERANCE * max(pseudo[-1], scale):   # with the above: the triangle inequality
        return f"principal moments {text} kg m^2 break the triangle inequality (no real body has them)"
    return None


def _scale(cal: Calibration) -> float:
    """The largest principal moment at the centre of mass of the CAD bodies [kg m^2]."""
    return max((float(np.abs(np.linalg.eigvalsh(b.inertia)).max()) for b in body_inertias(cal, cal.x0)), default=0.0)


def whole_bodies(cal: Calibration) -> list[bool]:
    """Per body, whether the calibrated URDF writes all of it into its moving link (and gives the links
    fixed to it no inertia): when with those links at CAD the moving link could be no real body."""
    links, scale = cal.links(), _scale(cal)
    return [bool(cal.attached and cal.attached[b]) and _physical(links[10 * b:10 * b + 10], scale) is None
            and _physical(links[10 * b:10 * b + 10] - cal.attached_cad[10 * b:10 * b + 10], scale) is not None
            for b in range(len(cal.bodies))]


def consistency(cal: Calibration) -> dict:
    """Physical consistency: ``problems`` (each body, less a declared payload, a real body (``_physical``);
    each armature (a motor's rotor inertia) not negative) and ``warnings`` (negative friction
    coefficients; a body whose fixed links' CAD its moving link cannot complete, ``whole_bodies``)."""
    problems, warnings = [], []
    nj = len(cal.joints)
    links, scale = cal.links(), _scale(cal)
    for b, body in enumerate(cal.bodies):
        why = _physical(links[10 * b:10 * b + 10], scale)
        if why:
            problems.append(f"link {body}: {why}")
    for b in np.flatnonzero(whole_bodies(cal)):
        names, body, fixed = ", ".join(cal.attached[b]), cal.bodies[b], cal.attached_cad[10 * b:10 * b + 10]
        own = links[10 * b:10 * b + 10] - fixed
        why = ("lighter than they are" if own[0] <= 0 else
               f"and {body} would be no real body with them at CAD ({_physical(own, scale)})")
        warnings.append(f"link {body}: with {names} fixed to it ({fixed[0]:.4g} kg at CAD), its body comes out at "
                        f"{links[10 * b]:.4g} kg, {why}: the calibrated URDF holds the whole body in {body} and no "
                        f"inertia in {names}. The joint torques see only the body they form; a large gap means they "
                        "are not mounted as the URDF says")
    for j in range(nj):
        who, a = cal.motor_of(j), float(cal.x[10 * nj + j])
        if a < 0:
            problems.append(f"{who}: {'rotor inertia' if j in (cal.motors or ()) else 'armature'} {a:.4g} kg m^2 "
                            "is negative")
        fv, fc = cal.x[11 * nj + 3 * j], cal.x[11 * nj + 3 * j + 1]
        if fv < 0 or fc < 0:
            warnings.append(f"{who}: friction Fv {fv:.4g}, Fc {fc:.4g}: a negative coefficient "
                            f"makes the {'motor' if j in (cal.motors or ()) else 'joint'} gain energy")
        if len(cal.x) == 15 * nj and fc + cal.x[14 * nj + j] < 0:
            warnings.append(f"{who}: friction Fs {fc + cal.x[14 * nj + j]:.4g} at zero speed is negative")
    return {"ok": not problems, "problems": problems, "warnings": warnings}


def suspicious(cal: Calibration, tied: dict | None = None) -> list[str]:
    """Parameters far (> SUSPICIOUS) from CAD or from the prior armature (a motor's rotor inertia), with
    the other causes that give the same torque shape. ``tied``: the masses no joint torque determines
    alone, with the parameters they trade with (the excitation report's ``masses_not_determined_alone``)."""
    out = []
    causes = "; ".join(OTHER_CAUSES)
    for body, cad, new in zip(cal.bodies, body_inertias(cal, cal.x0), body_inertias(cal)):
        if cad.mass > 0 and abs(new.mass / cad.mass - 1) > SUSPICIOUS:
            change = f"link {body}: mass {cad.mass:.4g} -> {new.mass:.4g} kg ({100 * (new.mass / cad.mass - 1):+.0f} %)"
            partners = (tied or {}).get(f"{body}.m")
            if partners:
                out.append(f"{change}; no joint torque determines this mass alone: it trades with "
                           f"{', '.join(partners)}, and the prior splits what the data determine between them")
            elif partners is not None:
                out.append(f"{change}; no joint torque sees this mass")
            else:
                out.append(f"{change}; also consistent with: {causes}")
    nj = len(cal.joints)
    for j in range(nj):
        a0, a = cal.x0[10 * nj + j], cal.x[10 * nj + j]
        if a0 > 0 and abs(a / a0 - 1) > SUSPICIOUS and j in (cal.motors or ()):
            out.append(f"{cal.motor_of(j)}: rotor inertia {a0:.4g} -> {a:.4g} kg m^2 ({100 * (a / a0 - 1):+.0f} %); "
                       "also consistent with: a drive gain off on the joints it drives; a gear ratio off; inertia "
                       "of those links' own axes that the data cannot tell from the rotor's")
        elif a0 > 0 and abs(a / a0 - 1) > SUSPICIOUS:
            out.append(f"joint {cal.joints[j]}: armature {a0:.4g} -> {a:.4g} kg m^2 ({100 * (a / a0 - 1):+.0f} %); "
                       "also consistent with: a drive gain off on that joint; inertia of the link's own axis "
                       "that the data cannot tell from the armature")
        fc, offset = cal.x[11 * nj + 3 * j + 1], cal.x[11 * nj + 3 * j + 2]
        if fc >= 0 and abs(offset) > fc:     # a negative Fc: the warning of ``consistency``
            out.append(f"{cal.motor_of(j)}: friction offset {offset:.4g} exceeds its Coulomb level {fc:.4g}: a "
                       "torque the rigid-body model does not explain is taken for friction; also consistent with: "
                       f"{causes}")
    return out


# --------------------------------------------------------------------------- the calibrated URDF


def calibrated_urdf(urdf_text: str, name: str, cal: Calibration) -> str:
    """``urdf_text`` with the identified inertial parameters of every moving link (its own inertia
    plus the identified change of its body: links fixed to it keep theirs, unless ``whole_bodies``
    says the moving link takes all of the body) and the armature as
    Pinocchio's ``<rotor_params>`` (gear_ratio 1, mass = armature); with a transmission also each
    motor's rotor inertia and row of R as ``<fricli_transmission>`` (``fricli.robot.dynamics``)."""
    from fricli.robot.dynamics import TRANSMISSION, link_inertials

    pin = _pin()
    own_links = link_inertials(urdf_text, name)
    root = ET.fromstring(urdf_text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    links = {link.get("name"): link for link in root.findall("link")}
    nj = len(cal.joints)
    for b, (body, whole) in enumerate(zip(cal.bodies, whole_bodies(cal))):
        link = links.get(body)
        if link is None:
            raise ModelFileError(f"{name}: no link {body!r} for joint {cal.joints[b]}")
        if whole:
            _set_inertial(link, pin.Inertia.FromDynamicParameters(cal.links()[10 * b:10 * b + 10]))
            for other in cal.attached[b]:
                for inertial in links[other].findall("inertial"):
                    links[other].remove(inertial)
        else:
            delta = cal.x[10 * b:10 * b + 10] - cal.x0[10 * b:10 * b + 10]
            _set_inertial(link, pin.Inertia.FromDynamicParameters(own_links[body] + delta))
    for old in root.findall("rotor_params") + root.findall(TRANSMISSION):
        root.remove(old)
    if len(root):
        root[-1].tail = "\n  "
    rotor = ET.SubElement(root, "rotor_params")
    rotor.text, rotor.tail = "\n    ", "\n"
    for j, (joint, a) in enumerate(zip(cal.joints, cal.armature())):
        element = ET.SubElement(rotor, "joint", {"name": joint, "mass": repr(float(a)), "gear_ratio": "1"})
        element.tail = "\n    " if j < nj - 1 else "\n  "
    if cal.motors is not None:
        rotor.tail = "\n  "
        listed = ET.SubElement(root, TRANSMISSION)
        listed.text, listed.tail = "\n    ", "\n"
        for k, m in enumerate(cal.motors):
            motor = ET.SubElement(listed, "motor", {"joint": cal.joints[m], "rotor_inertia": repr(float(cal.x[10 * nj + m]))})
            for j in cal.motors:
                if cal.ratio[m, j]:
                    ET.SubElement(motor, "ratio", {"joint": cal.joints[j], "value": repr(float(cal.ratio[m, j]))})
            motor.tail = "\n    " if k < len(cal.motors) - 1 else "\n  "
    return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _set_inertial(link, inertia) -> None:
    """Write ``inertia`` (a pin.Inertia in the link frame) as the link's <inertial>, rpy = 0."""
    inertial = link.find("inertial")
    if inertial is None:
        inertial = ET.SubElement(link, "inertial")
    for child in list(inertial):
        inertial.remove(child)
    c, tensor = inertia.lever, inertia.inertia
    w, v = np.linalg.eigh(tensor)
    if w.min() < 0:            # a body the fit shrank to a point: the round-off of its moments is no inertia
        tensor = (v * np.maximum(w, 0.0)) @ v.T
    inertial.text = "\n      "
    ET.SubElement(inertial, "mass", {"value": repr(float(inertia.mass))}).tail = "\n      "
    ET.SubElement(inertial, "origin", {"xyz": " ".join(repr(float(v)) for v in c), "rpy": "0 0 0"}).tail = "\n      "
    ET.SubElement(inertial, "inertia", {k: repr(float(tensor[a, b])) for k, (a, b) in (
        ("ixx", (0, 0)), ("ixy", (0, 1)), ("ixz", (0, 2)), ("iyy", (1, 1)), ("iyz", (1, 2)), ("izz", (2, 2)))}).tail = "\n    "


def warnings(report: dict) -> list[str]:
    """The lines a calibration's report warns of: consistency warnings, then suspicious parameters."""
    return report["consistency"]["warnings"] + report["suspicious"]


def refuse_inconsistent(cal: Calibration) -> None:
    """FitError (exit 5) when the identified model is physically impossible."""
    problems = cal.report["consistency"]["problems"]
    if problems:
        raise FitError(f"the identified model is physically inconsistent: {'; '.join(problems)}; excite the arm "
                       "more, tighten the prior (--prior) or enforce consistency (--consistency enforce)")


# --------------------------------------------------------------------------- a log's robot model, calibrated


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


def recalibrate(table, name: str, urdf: str, *, prior: float | str = DEFAULT_PRIOR, friction: str = "linear",
                cutoff_hz: float = logs.DEFAULT_CUTOFF_HZ):
    """Calibrate the robot model of a whole-arm log imported with a URDF (the matching and gravity it
    recorded) and recompute its tau_g and tau_dyn from the calibrated model.

    Returns (Calibration, the calibrated URDF's text, the table with the new tau_g and tau_dyn).
    A payload the import declared is fitted into the last body (and not added again)."""
    from fricli.robot.dynamics import RobotModel
    from fricli.robot.logterms import add_terms

    record, robot, motion = recorded_motion(table, name, urdf, cutoff_hz=cutoff_hz)
    gravity = logs.gravity_of(table.schema)
    cal = calibrate(robot, motion, prior=prior, friction=friction)
    refuse_inconsistent(cal)
    with open(urdf, encoding="utf-8") as fh:
        text = calibrated_urdf(fh.read(), urdf, cal)
    new, _ = add_terms(table, RobotModel(text, urdf, gravity=gravity, held=robot.held), name, match="name",
                       urdf_names={str(k): v for k, v in record["joints"].items()}, gravity=gravity,
                       cutoff_hz=cutoff_hz)
    return cal, text, new
