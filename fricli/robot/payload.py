"""The payload a whole-arm log's joints carry: a point mass at a frame, identified from the torques.

With the log's robot model (its URDF, gravity and armature, as ``fricli import`` recorded them,
without any payload it declared) and each joint's linear friction fitted alongside:

    tau_m - tau_rb(q, qd, qdd) = Y_b(q, qd, qdd) pi(m, c) + Fv qd + Fc sign(qd) + offset + e

(with ``friction="stribeck"`` also (Fs - Fc) sign(qd) exp(-(qd / vs)^2), the bump of the LuGre
static curve, vs per joint alternated with the fit by a search on a grid, as ``fricli calibrate
--friction stribeck`` does).

``Y_b`` (n, joints, 10): the columns of Pinocchio's joint-torque regressor for the body that holds
the frame; ``pi(m, c)``: the dynamic parameters of a point mass m [kg] at c [m] in the frame's
coordinates, placed by the frame's placement, which is how ``fricli import --payload-*`` adds a
payload (``fricli.robot.dynamics.RobotModel``). scipy's least squares over (m, c), the friction
by linear least squares at every step (variable projection), on the rows in motion
(``fricli.core.metrics.in_motion``) at least ``edge_s`` from either end of the log.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core import metrics
from fricli.core.errors import DataError, FitError, ModelFileError
from fricli.robot import calibration
from fricli.numerics.threads import pinned
from fricli.robot.dynamics import pinocchio

SIGNIFICANCE = 3.0   # a payload is reported as detected when its mass exceeds this many standard errors
# ... and as determined when its mass is known to within this share and its centre of mass to
# within this distance [m] (one standard error): else it is no constant load the log determines
DETERMINED_MASS, DETERMINED_COM = 0.1, 0.1


@dataclasses.dataclass
class IdentifiedPayload:
    """An identified point payload and what it explains."""

    frame: str
    mass: float                  # [kg]
    com: np.ndarray              # (3,) [m] in the frame's coordinates
    stderr: np.ndarray           # (4,) standard errors of mass, com (white residuals assumed)
    rows: int
    joints: list                 # the log's joint names, URDF order
    rms_without: np.ndarray      # (joints,) [Nm] RMS of the residual with the friction alone
    rms_with: np.ndarray         # (joints,) [Nm] with the payload too
    friction: np.ndarray         # (joints, 3) Fv, Fc, offset fitted with the payload; (joints, 4) with Fs - Fc
    vs: np.ndarray | None = None  # (joints,) [rad/s] the Stribeck velocities (friction "stribeck")
    held: list = dataclasses.field(default_factory=list)   # joints held still: not used (no figures)

    @property
    def detected(self) -> bool:
        """Whether the mass stands out of its noise: more than SIGNIFICANCE standard errors."""
        return bool(self.mass > SIGNIFICANCE * self.stderr[0])

    @property
    def verdict(self) -> str:
        """"payload" (detected and determined: declare it), "undetermined" (a mass beyond
        SIGNIFICANCE standard errors of zero, either sign, whose mass or centre of mass is not
        pinned down: the two trade against each other), "none" (within SIGNIFICANCE standard
        errors of zero) or "negative" (determined and below zero: no payload does that; the robot
        model is off)."""
        if abs(self.mass) <= SIGNIFICANCE * self.stderr[0]:
            return "none"
        if self.stderr[0] > DETERMINED_MASS * abs(self.mass) or (self.stderr[1:] > DETERMINED_COM).any():
            return "undetermined"
        return "negative" if self.mass < 0 else "payload"

    def report(self) -> dict:
        bump = (lambda j, f: {}) if self.vs is None else (lambda j, f: {"Fs-Fc": float(f[3]), "vs": float(self.vs[j])})
        return {"frame": self.frame, "detected": self.detected, "verdict": self.verdict, "mass": self.mass, "com": [float(v) for v in self.com],
                "stderr": {"mass": float(self.stderr[0]), "com": [float(v) for v in self.stderr[1:]]},
                "rows": self.rows, "held": [str(j) for j in self.held],
                "joints": {str(j): {"rms_without": float(a), "rms_with": float(b),
                                    "Fv": float(f[0]), "Fc": float(f[1]), "offset": float(f[2]), **bump(k, f)}
                           for k, (j, a, b, f) in enumerate(zip(self.joints, self.rms_without, self.rms_with,
                                                                self.friction))
                           if j not in self.held}}


def body_regressor(robot, frame: str, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> tuple[np.ndarray, object]:
    """Y_b (n, joints, 10) of the body holding ``frame``, and the frame's placement in that body."""
    pin = pinocchio()
    model = robot.pin_model
    if not model.existFrame(frame):
        frames = ", ".join(dict.fromkeys(f.name for f in model.frames if f.name != "universe"))
        raise ModelFileError(f"{robot.name}: no frame {frame!r} for the payload; the frames are: {frames}")
    f = model.frames[model.getFrameId(frame)]
    cols = slice(10 * (f.parentJoint - 1), 10 * f.parentJoint)
    data = model.createData()
    config = robot.configuration(q)
    y = np.empty((len(q), model.nv, 10))
    for k in range(len(q)):
        # (nv, 10 bodies), or a vector for a model of one joint
        y[k] = np.reshape(pin.computeJointTorqueRegressor(model, data, config[k], qd[k], qdd[k]), (model.nv, -1))[:, cols]
    return y, f.placement


def point_parameters(mass: float, com: np.ndarray, placement) -> np.ndarray:
    """pi (10,): a point mass [kg] at ``com`` [m] in a frame with ``placement`` in its body."""
    pin = pinocchio()
    return placement.act(pin.Inertia(float(mass), np.asarray(com, dtype=float), np.zeros((3, 3)))).toDynamicParameters()


@pinned
def identify(robot, motion, frame: str, *, edge_s: float = calibration.DEFAULT_EDGE_S,
             friction: str = "linear") -> IdentifiedPayload:
    """The point payload at ``frame`` of ``robot`` (a ``RobotModel`` without payload) that the
    torques of ``motion`` (``calibration.Motion``) carry, with each joint's ``friction``: "linear"
    or "stribeck" (see the module docstring)."""
    from scipy.optimize import least_squares

    if friction not in ("linear", "stribeck"):
        raise ValueError(f"unknown friction kind {friction!r}")

    rows = calibration.edge_rows(motion.t, edge_s)
    q, qd, qdd, tau = (a[rows] for a in (motion.q, motion.qd, motion.qdd, motion.tau))
    if len(q) < 20:
        raise DataError(f"{len(q)} rows after dropping {edge_s:g} s at each end: too few to identify a payload")
    tau_g, tau_dyn = robot.terms(q, qd, qdd, np.nan_to_num(motion.rotor_inertia))   # NaN: none recorded
    residual = tau - tau_g - tau_dyn
    y_b, placement = body_regressor(robot, frame, q, qd, qdd)
    # a joint held still holds any torque up to its breakaway: its rows say nothing of the payload
    held = metrics.held_still(q)
    if held.all():
        raise DataError(f"every joint is held still (position span under {metrics.HELD_SPAN:g} rad): no motion "
                        "to identify a payload from")
    moving = [metrics.in_motion(qd[:, j]) & ~held[j] for j in range(qd.shape[1])]
    speeds = [qd[m, j] for j, m in enumerate(moving)]

    def fitted(vs):
        """(fit, parts) with the friction columns of Stribeck velocities ``vs`` (None: linear)."""
        cols = [np.column_stack([w, np.sign(w), np.ones_like(w)]
                                + ([] if vs is None else [np.sign(w) * np.exp(-np.square(w / vs[j]))]))
                for j, w in enumerate(speeds)]
        proj = [np.linalg.pinv(a) for a in cols]

        def parts(theta):
            load = y_b @ point_parameters(theta[0], theta[1:], placement)
            out, coef = [], []
            for j, m in enumerate(moving):
                r = residual[m, j] - load[m, j]
                c = proj[j] @ r
                out.append(r - cols[j] @ c)
                coef.append(c)
            return out, coef

        # start: the linear estimate of (m, m c) from the first moments' columns, the inertia neglected
        first = np.concatenate([y_b[m, j, :4] for j, m in enumerate(moving)])
        target = np.concatenate(parts(np.zeros(4))[0])
        h = np.linalg.lstsq(first, target, rcond=None)[0]
        start = np.zeros(4)
        if np.isfinite(h).all() and h[0] > 0:
            start = np.concatenate([[h[0]], placement.actInv(pinocchio().SE3(np.eye(3), h[1:] / h[0])).translation])
        fit = least_squares(lambda theta: np.concatenate(parts(theta)[0]), start, x_scale="jac")
        if not fit.success:
            raise FitError(f"no payload fits the torques at {frame} (least squares: {fit.message})")
        return fit, parts

    fit, parts = fitted(None)
    vs = None
    if friction == "stribeck":   # a joint held still has no rows, and no Stribeck velocity (NaN)
        for _ in range(calibration.STRIBECK_ALTERNATIONS):
            load = y_b @ point_parameters(fit.x[0], fit.x[1:], placement)
            vs = np.array([calibration.stribeck_velocity(w, residual[m, j] - load[m, j], np.abs(w).max())
                           if w.size else np.nan for j, (w, m) in enumerate(zip(speeds, moving))])
            fit, parts = fitted(vs)
    none, _ = parts(np.zeros(4))
    out, coef = parts(fit.x)
    dof = max(len(fit.fun) - 4 - (3 if vs is None else 4) * int((~held).sum()), 1)
    try:
        cov = np.linalg.inv(fit.jac.T @ fit.jac) * float(fit.fun @ fit.fun) / dof
        stderr = np.sqrt(np.clip(np.diag(cov), 0, None))
    except np.linalg.LinAlgError:
        stderr = np.full(4, np.inf)
    rms = lambda parts_: np.array([np.sqrt(np.mean(r ** 2)) if r.size else np.nan for r in parts_])  # noqa: E731
    return IdentifiedPayload(frame=frame, mass=float(fit.x[0]), com=fit.x[1:].copy(), stderr=stderr, rows=int(len(q)),
                             joints=list(motion.names), rms_without=rms(none), rms_with=rms(out), friction=np.array(coef),
                             vs=vs, held=[motion.names[j] for j in np.flatnonzero(held)])


def identify_log(table, name: str, frame: str, *, urdf: str | None = None, cutoff_hz: float | None = None,
                 edge_s: float = calibration.DEFAULT_EDGE_S, friction: str = "linear") -> IdentifiedPayload:
    """``identify`` on a whole-arm log imported with a URDF: its robot model as recorded (or the
    URDF at ``urdf``), without the payload the import may have declared."""
    from fricli.core import logs

    _, robot, motion = calibration.recorded_motion(
        table, name, urdf, cutoff_hz=logs.DEFAULT_CUTOFF_HZ if cutoff_hz is None else cutoff_hz)
    return identify(robot, motion, frame, edge_s=edge_s, friction=friction)
