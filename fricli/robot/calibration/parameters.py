"""The calibration's regressor: Pinocchio's joint-torque regressor with the armature and friction
columns, the parameters' names, the URDF's CAD values and the prior's scales, and the base
(identifiable) parameters."""

from __future__ import annotations

import numpy as np


PARAMS = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")   # Pinocchio's dynamic parameters
FRICTION = ("Fv", "Fc", "offset")
MIN_LENGTH = 0.1           # m: the length scale of a body whose CAD centre of mass is closer to its joint


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
