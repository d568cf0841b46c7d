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

import numpy as np

from fricli.core import logs, metrics
from fricli.core.errors import DataError
from fricli.numerics.threads import pinned

# the parts (motion: the log and its motors; parameters: the regressor and the prior's scales; fit: the
# estimates; report: the checks and tables; urdf: the calibrated URDF), every name importable from here
from fricli.robot.calibration.motion import (Motion, edge_rows, _log_transmission, motion_check_ratio,  # noqa: F401
                                             motor_layout, motor_units, read_motion, recorded_motion,
                                             recorded_urdf, reflected)
from fricli.robot.calibration.parameters import (FRICTION, MIN_LENGTH, PARAMS, attached, base_parameters,  # noqa: F401
                                                 bodies, cad_parameters, _from_pseudo, moved,
                                                 parameter_names, _pin, prior_scales, pseudo_inertia,
                                                 _random_regressor, regressor, stribeck_columns)
from fricli.robot.calibration.fit import (MAX_ITERATIONS, NUMERIC_ZERO, PRIOR_FOLDS, PRIOR_GRID,  # noqa: F401
                                          PRIOR_START, STRIBECK_ALTERNATIONS, STRIBECK_GRID, UNDETERMINED,
                                          choose_prior, consistent_fit, _excitation, _map_fit, stribeck_velocity,
                                          _with_prior)
from fricli.robot.calibration.report import (OTHER_CAUSES, SUSPICIOUS, TOLERANCE, body_inertias,  # noqa: F401
                                             consistency, _friction_report, link_table, _motor_report,
                                             _physical, refuse_inconsistent, _scale, suspicious, warnings,
                                             whole_bodies)
from fricli.robot.calibration.result import Calibration  # noqa: F401
from fricli.robot.calibration.urdf import calibrated_urdf, report_path, write, _set_inertial  # noqa: F401

#: the friction fitted with the robot model by diagnose --calibrate, which refits each joint's friction
#: model afterwards: the calibration's friction only has to keep friction out of the inertial
#: parameters, and a Stribeck bump left to the linear law is taken up by them (docs/diagnose.md)
LOOP_FRICTION = "stribeck"
DEFAULT_PRIOR = "auto"     # prior std of an inertial parameter relative to its scale, or chosen by held-out fit
DEFAULT_EDGE_S = 0.5       # rows dropped at each end [s]: the zero-phase filter's and differences' transients
POOR_EXCITATION = 1e3      # a scaled base regressor's condition number above this is flagged (varied runs: 10-300)
MEMORY_COPIES = 6          # peak memory of a calibration / its regressor's size (5.4 measured on 4.5 M rows)
MIN_ROWS = 20              # a joint in motion in fewer rows is refused


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
        x0 = np.concatenate([x0, np.zeros(nj)])
        s = np.concatenate([s, 10.0 * np.maximum(motor_rms, 1e-6)])
        for _ in range(STRIBECK_ALTERNATIONS):
            Phi_s = np.hstack([Phi, stribeck_columns(qd, vs, norm) * mask[:, None]])
            x, sigma, resid, iteration = _map_fit(Phi_s, y, x0, s, sigma, rows_of, tau_rms, counts)
            own = (Phi_s[:, 11 * nj:] * x[11 * nj:]).reshape(n, nj, -1).sum(axis=2)  # friction part, (n, nj)
            target = to_motors(resid + own)
            for m in range(nj):
                on = sliding[:, m]
                vs[m] = stribeck_velocity(w[on, m], target[on, m], top[m])
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
        solved = {}
        x = consistent_fit(Phi / sigma[rows_of, None], y / sigma[rows_of], x, x0, s, nj, payload, solved)
        resid = (y - Phi @ x).reshape(n, nj)
        enforced = {"inconsistent_before": broken, "rms_linear": {str(motion.names[j]): float(sigma[j])
                                                                  for j in range(nj)},
                    "optimality_gap": solved["gap"], "newton_steps": solved["newton_steps"],
                    "converged": solved["converged"]}
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
