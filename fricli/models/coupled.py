"""Friction where it lives: one model for a group of joints that share motors (kind ``coupled``).

For the k joints of a coupled group with transmission R (k, k) (``fricli.core.transmission``):

    theta_d = R q_d                                        motor velocities [rad/s], (k,) per sample
    f_i     = Fv_i theta_d_i + Fc_i sign(theta_d_i) + o_i  motor i's friction [Nm] (motor side)
              [+ (Fs_i - Fc_i) sign(theta_d_i) exp(-(theta_d_i / vs_i)^2)]   with the Stribeck curve
    tau_f   = R^T f                                        each joint's friction [Nm]

A per-joint model of (q_d_j, tau_g_j) cannot represent this: motor 6 of a coupled wrist turns
at r65 q_d5 + r66 q_d6, and its friction reaches joints 5 and 6. The parameters are linear, so
the fit is one linear least squares in motor coordinates: the joints' friction targets mapped to
the motors, R^-T tau_f (n, k), regressed on every motor's features [theta_d, sign(theta_d), 1]
(which is the joint-side system tau_f = R^T Phi p whitened for equal noise on every motor).
With the Stribeck curve (the static curve of the LuGre model with delta = 2), each motor's vs is
chosen on a grid and the rest is linear for a given vs.

Instead of the linear law, each motor's friction can be a model of its own (``motors``: one
``FrictionModel`` per motor, trained by ``fricli train-base --coupling``, ``fricli.fitting.learning.train_group``),
which reads the motor's signals: ``qd`` its velocity theta_d_i [rad/s] and ``tau_g`` zero (the
motor's law depends on its velocity alone). A dissipative network per motor has f_i theta_d_i >= 0,
so tau_f . q_d = f . theta_d >= 0: the group is dissipative too. Its file holds the networks as
children ``motor_1`` ... ``motor_k`` (and the ratio); a file of the linear law is unchanged.

The model predicts the friction of every joint of the group from the group's rows at the same
times (``predict_group``). A command applying it to one joint's rows uses ``member(joint)``, a
view whose inputs are the joint's own ``qd`` and its partners' velocities as ``qd@<joint>``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fricli.core import logs, metrics
from fricli.core.errors import DataError, FitError, LogError, ModelFileError
from fricli.models import register
from fricli.models.base import FrictionModel
from fricli.core.transmission import Transmission

FEATURES = ("fv", "fc", "offset")
STRIBECK = ("fs", "vs")
VS_GRID = 24            # Stribeck velocities tried per motor, between the 2nd and 60th percentile of |theta_d|
MOTOR_INPUTS = ("qd", "tau_g")   # what a motor model may read (``motor_signals``)
PARAM_INFO = {"fv": ("Nm s/rad", "viscous friction (motor side)"), "fc": ("Nm", "Coulomb friction (motor side)"),
              "offset": ("Nm", "constant torque (motor side)"), "fs": ("Nm", "static friction (motor side)"),
              "vs": ("rad/s", "Stribeck velocity (motor side)")}


def partner_key(joint) -> str:
    """The signal name of another joint's velocity in a member's inputs."""
    return f"qd@{joint}"


@register
class CoupledModel(FrictionModel):
    """Motor-side friction of a coupled group; ``joints`` (k,), ``ratio`` R (k, k), and either
    per-motor ``fv`` [Nm s/rad], ``fc`` [Nm], ``offset`` [Nm], each (k,), optionally with the
    Stribeck curve's ``fs`` [Nm] and ``vs`` [rad/s], each (k,); or ``motors``, one stateless
    model per motor of its velocity ``qd`` [rad/s] (e.g. a dissipative network)."""

    kind = "coupled"

    def __init__(self, joints, ratio, fv=None, fc=None, offset=None, fs=None, vs=None, *, motors=None):
        self.transmission = Transmission(joints, ratio)
        k = len(self.joints)
        self.motors = None if motors is None else list(motors)
        if self.motors is not None:
            if len(self.motors) != k or any(v is not None for v in (fv, fc, offset, fs, vs)):
                raise ValueError(f"a coupled model has {k} motor models or the linear law's parameters, not both")
            if any(not m.required_inputs() <= set(MOTOR_INPUTS) for m in self.motors):
                raise ValueError("a motor model reads its velocity alone (qd, and tau_g as 0)")
            self.fv = self.fc = self.offset = self.fs = self.vs = None
            return
        if fv is None or fc is None or offset is None:
            raise ValueError("the linear law needs fv, fc and offset")
        self.fv, self.fc, self.offset = (np.array(v, dtype=np.float64).reshape(-1) for v in (fv, fc, offset))
        if (fs is None) != (vs is None):
            raise ValueError("the Stribeck curve needs both fs and vs")
        self.fs, self.vs = (None if v is None else np.array(v, dtype=np.float64).reshape(-1) for v in (fs, vs))
        if self.stribeck and not np.all(self.vs > 0):
            raise ValueError("vs must be positive")
        for name in self.names():
            v = getattr(self, name)
            if v.shape != (k,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{name} needs {k} finite numbers")

    @property
    def stribeck(self) -> bool:
        return self.fs is not None

    def names(self) -> tuple[str, ...]:
        """The per-motor parameters of the linear law (none with motor models)."""
        if self.motors is not None:
            return ()
        return FEATURES + (STRIBECK if self.stribeck else ())

    @property
    def joints(self) -> tuple:
        return self.transmission.joints

    @property
    def ratio(self) -> np.ndarray:
        return self.transmission.ratio

    def index(self, joint) -> int | None:
        return next((i for i, j in enumerate(self.joints) if str(j) == str(joint)), None)

    # ---------------------------------------------------------------- equations

    def motor_friction(self, theta_d: np.ndarray) -> np.ndarray:
        """f (n, k) [Nm] per motor at motor velocities theta_d (n, k) [rad/s]."""
        if self.motors is not None:
            return np.column_stack([motor.predict(motor_signals(theta_d[:, i]))[0]
                                    for i, motor in enumerate(self.motors)])
        f = self.fv * theta_d + self.fc * np.sign(theta_d) + self.offset
        if self.stribeck:
            f += (self.fs - self.fc) * np.sign(theta_d) * np.exp(-np.square(theta_d / self.vs))
        return f

    def predict_group(self, qd: np.ndarray) -> np.ndarray:
        """tau_f (n, k) [Nm] of the group's joints at joint velocities qd (n, k) [rad/s]."""
        tr = self.transmission
        return tr.joint_torques(self.motor_friction(tr.motor_velocities(qd)))

    @classmethod
    def fit(cls, joints, ratio, qd: np.ndarray, tau_f: np.ndarray, *,
            stribeck: bool = False) -> tuple["CoupledModel", dict]:
        """Least squares on joint velocities qd (n, k) [rad/s] and friction targets tau_f (n, k) [Nm]
        (with ``stribeck``, the Stribeck curve per motor too); returns the model and its fit
        figures per joint (MAE, RMSE, max [Nm])."""
        tr = Transmission(joints, ratio)
        k = len(tr.joints)
        w = tr.motor_velocities(qd)
        y = tr.motor_torques(tau_f)
        params = np.zeros((5 if stribeck else 3, k))
        for i in range(k):
            s = np.sign(w[:, i])
            a = np.column_stack([w[:, i], s, np.ones(len(w))])
            if np.linalg.matrix_rank(a) < 3:
                raise FitError(f"motor {i + 1} of joints {', '.join(map(str, tr.joints))} does not move in both "
                               "directions: its friction cannot be fitted")
            if not stribeck:
                params[:, i] = np.linalg.lstsq(a, y[:, i], rcond=None)[0]
                continue
            speed = np.abs(w[:, i])
            best = None
            for vs in np.geomspace(*np.percentile(speed[metrics.in_motion(speed)], [2, 60]), VS_GRID):
                ab = np.column_stack([a, s * np.exp(-np.square(w[:, i] / vs))])
                coef, *_ = np.linalg.lstsq(ab, y[:, i], rcond=None)
                sse = float(np.sum(np.square(ab @ coef - y[:, i])))
                if best is None or sse < best[0]:
                    best = (sse, coef, vs)
            _, (fv, fc, offset, bump), vs = best
            params[:, i] = fv, fc, offset, fc + bump, vs
        model = cls(tr.joints, tr.ratio, *params)
        return model, {"joints": {str(j): figures(model.predict_group(qd)[:, c] - tau_f[:, c])
                                  for c, j in enumerate(tr.joints)}, "rows": int(len(qd))}

    # ------------------------------------------------------- as a FrictionModel

    def member(self, joint) -> "GroupMember":
        """The view of this model that predicts joint ``joint``'s friction from its rows."""
        i = self.index(joint)
        if i is None:
            raise DataError(f"joint {joint} is not in the coupled group {', '.join(map(str, self.joints))}")
        return GroupMember(self, i)

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        """Refused: the group's joints are predicted together (``predict_group``) or one of them
        through ``member`` (``view``), as every command applies a group's model."""
        raise ModelFileError(f"a model of the coupled group of joints {', '.join(map(str, self.joints))}: "
                             "apply it to one joint through its member (CoupledModel.member)")

    def required_inputs(self) -> set[str]:
        return {"t", "qd"} | {partner_key(j) for j in self.joints}

    def get_params(self) -> dict:
        return {"joints": list(self.joints)}

    def get_arrays(self) -> dict[str, np.ndarray]:
        return {"ratio": self.ratio, **{name: getattr(self, name) for name in self.names()}}

    def children(self) -> dict[str, FrictionModel]:
        return {} if self.motors is None else {motor_name(i): m for i, m in enumerate(self.motors)}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "CoupledModel":
        if set(params) != {"joints"} or not isinstance(params["joints"], list):
            raise ValueError("a coupled model records its joints, and nothing else")
        if children:
            names = [motor_name(i) for i in range(len(params["joints"]))]
            if set(children) != set(names) or set(arrays) != {"ratio"}:
                raise ValueError(f"a coupled model of motor models holds {', '.join(names)} and the ratio")
            return cls(params["joints"], arrays["ratio"], motors=[children[n] for n in names])
        return cls(params["joints"], arrays["ratio"], arrays["fv"], arrays["fc"], arrays["offset"],
                   arrays.get("fs"), arrays.get("vs"))

    def describe(self) -> str:
        if self.motors is not None:
            return self._describe_motors()
        lines = [f"coupled group of joints {', '.join(map(str, self.joints))}: friction per motor, "
                 "f = fv*theta_d + fc*sign(theta_d) + offset"
                 + (" + (fs - fc)*sign(theta_d)*exp(-(theta_d/vs)^2)" if self.stribeck else "") + ", tau_f = R^T f"]
        lines.append("  R (motor rows, joint columns):")
        lines += ["    " + "  ".join(f"{x:>10.6g}" for x in row) for row in self.ratio]
        for i in range(len(self.joints)):
            lines.append(f"  motor {i + 1}: " + "  ".join(f"{n} {getattr(self, n)[i]:.6g} {PARAM_INFO[n][0]}"
                                                        for n in self.names()))
        return "\n".join(lines)

    def _describe_motors(self) -> str:
        lines = [f"coupled group of joints {', '.join(map(str, self.joints))}: friction per motor, "
                 "f_i = a model of motor i's velocity theta_d_i (no load input), tau_f = R^T f"]
        lines.append("  R (motor rows, joint columns):")
        lines += ["    " + "  ".join(f"{x:>10.6g}" for x in row) for row in self.ratio]
        for i, motor in enumerate(self.motors):
            lines.append(f"  motor {i + 1} (its qd is the motor velocity theta_d_{i + 1}; tau_g is 0: "
                         "a load term does not act):")
            lines += ["    " + line for line in motor.describe().splitlines()]
        return "\n".join(lines)


def motor_name(i: int) -> str:
    """The child name of motor model i (0-based) in a model file."""
    return f"motor_{i + 1}"


def motor_signals(w: np.ndarray) -> dict[str, np.ndarray]:
    """What a motor model reads: its velocity ``qd`` = w (n,) [rad/s] and no load (``tau_g`` 0)."""
    return {"qd": w, "tau_g": np.zeros_like(w)}


@register
class GroupMember(FrictionModel):
    """Joint ``index`` of a coupled model: ``predict`` reads the joint's ``qd`` and its partners'
    velocities ``qd@<joint>`` (n,) at the same times. Saved as a model of that joint (kind
    ``coupled-member``): the group is its child ``group``, the joint its one parameter."""

    kind = "coupled-member"

    def __init__(self, group: CoupledModel, index: int):
        self.group, self.i = group, index
        self.joint = group.joints[index]
        self.partners = [j for c, j in enumerate(group.joints) if c != index]

    def predict(self, signals: dict[str, np.ndarray], state: Any = None) -> tuple[np.ndarray, Any]:
        missing = [partner_key(j) for j in self.partners if partner_key(j) not in signals]
        if missing:
            raise DataError(f"the friction of joint {self.joint} depends on joints {', '.join(map(str, self.partners))} "
                            f"(coupled group), and their rows are missing")
        cols = [signals["qd"] if c == self.i else signals[partner_key(j)] for c, j in enumerate(self.group.joints)]
        return self.group.predict_group(np.column_stack(cols))[:, self.i], None

    def required_inputs(self) -> set[str]:
        return {"t", "qd"} | {partner_key(j) for j in self.partners}

    def children(self) -> dict[str, FrictionModel]:
        return {"group": self.group}

    def get_params(self) -> dict:
        return {"joint": self.joint}

    @classmethod
    def from_parts(cls, params: dict, arrays: dict[str, np.ndarray], children: dict) -> "GroupMember":
        group = children.get("group")
        if not hasattr(group, "member") or set(params) != {"joint"}:
            raise ValueError("a member of a coupled group records its group and its joint, and nothing else")
        return group.member(params["joint"])

    def describe(self) -> str:
        return "\n".join([f"joint {self.joint} of the coupled group of joints {', '.join(map(str, self.group.joints))} "
                          f"(reads the velocities of joints {', '.join(map(str, self.partners))} too):"]
                         + ["  " + line for line in self.group.describe().splitlines()])


def view(model: FrictionModel, joint) -> FrictionModel:
    """The model that predicts ``joint``'s rows: a coupled group's member (``CoupledModel.member``),
    any other model itself."""
    return model.member(joint) if hasattr(model, "member") else model


def partners_read(model: FrictionModel) -> list[str]:
    """The joints (as text, in name order) whose velocities ``qd@<joint>`` ``model`` reads: those
    of a member's group, also under a model built on a member (adapted, fixed)."""
    return sorted(name[len(partner_key("")):] for name in model.required_inputs() if name.startswith(partner_key("")))


def add_partners(model: FrictionModel, log, table, **reading) -> None:
    """Add to ``log.signals`` (one joint's ``fricli.core.logs.Log``) the velocities ``qd@<p>``
    [rad/s] that ``model`` reads (``partners_read``), from joint p's rows of ``table`` (the long-format
    log ``log`` was read from, read the same way: ``reading`` as ``logs.from_table``) at ``log``'s
    times. LogError (INPUT) when the log has no usable rows of p or none at some of those times."""
    reading = {k: v for k, v in reading.items() if k in ("kt", "cutoff_hz", "drop_invalid", "zero")}
    t = log.signals["t"]
    for p in partners_read(model):
        try:
            sig = logs.from_table(table, name=log.name, joint=p, **reading).signals
        except LogError:
            raise LogError(f"{log.name}: the friction of joint {log.joint} depends on joint {p} (they share motors), "
                           f"and the log has no usable rows of joint {p}") from None
        at = np.minimum(np.searchsorted(sig["t"], t), len(sig["t"]) - 1)
        if not np.array_equal(sig["t"][at], t):
            raise LogError(f"{log.name}: joint {log.joint} and joint {p} share motors, but their rows are not at "
                           "the same times")
        log.signals[partner_key(p)] = sig["qd"][at]


def figures(err: np.ndarray) -> dict:
    """MAE, RMSE, max of an error (n,) [Nm]."""
    a = np.abs(err)
    return {"mae": float(a.mean()), "rmse": float(np.sqrt(np.mean(err ** 2))), "max": float(a.max())}


def group_rows(table, group, name: str, **reading) -> tuple[np.ndarray, list]:
    """The times t (n,) [s] and the ``fricli.core.logs.Log`` of every joint of ``group`` in ``table``
    (long format); refused unless every joint has rows at the same times."""
    quiet = {k: v for k, v in reading.items() if k != "warn"}   # the log's notes once, with the first joint
    datas = [logs.from_table(table, name=name, joint=j, **(reading if i == 0 else quiet)) for i, j in enumerate(group)]
    t = datas[0].signals["t"]
    for j, d in zip(group[1:], datas[1:]):
        other = d.signals["t"]
        if len(other) != len(t) or not np.array_equal(other, t):
            raise DataError(f"{name}: joints {group[0]} and {j} share motors, but their rows are not at the same "
                            "times: the coupled group needs every joint's row of every sample")
    return t, datas


def stack(datas: list, column: str) -> np.ndarray:
    """(n, k): ``column`` of each joint's log."""
    return np.column_stack([d.signals[column] for d in datas])


def fit_group(datas: list, transmission: Transmission, *, stribeck: bool = False) -> tuple[CoupledModel, dict]:
    """The coupled model of the joints of ``datas`` (their logs, rows at the same times) with
    their transmission (its joints in the same order)."""
    target = np.column_stack([logs.friction_target(d.signals) for d in datas])
    return CoupledModel.fit(transmission.joints, transmission.ratio, stack(datas, "qd"), target, stribeck=stribeck)


def save_group(path: str, model: CoupledModel, data, *, fit: dict, **provenance) -> dict:
    """Write ``model`` to ``path``: a model file that records its joints as ``joints`` (``joint``
    null), with units and provenance from ``data``, the log of one of the group's joints."""
    from fricli import models
    from fricli.core import modelfile

    spec, arrays = models.to_parts(model)
    meta = modelfile.base_meta()
    meta.update(kind=model.kind, model=spec, joint=None, joints=list(model.joints), axis=data.axis,
                units=data.units, inputs=["qd", "t"],
                provenance=models.provenance(data, rows_used=len(data) * len(model.joints), **provenance), fit=fit)
    modelfile.write(path, meta, arrays)
    return meta


def partner_signals(table, joint, name: str, **reading) -> dict[str, np.ndarray]:
    """For the rows of ``joint`` in ``table`` (long format), what the diagnosis's coupling effect
    reads: the velocities ``qd@<p>`` [rad/s] of the joints p that share motors with it, and the
    direction ``sign_motor@<m>`` of each motor m that turns with ``joint`` and another joint (a
    motor is named by the joint of its row of R); {} when the log records no transmission or the
    joint shares no motor with another, or the log lacks the other joints' rows."""
    from fricli.core import transmission

    try:
        tr = transmission.of_schema(table.schema.metadata)
    except ValueError:
        return {}
    if tr is None:
        return {}
    group = next((g for g in tr.coupled_groups() if any(str(tr.joints[i]) == str(joint) for i in g)), None)
    if group is None:
        return {}
    sub = tr.sub(group)
    c = next(i for i, j in enumerate(sub.joints) if str(j) == str(joint))
    order = [c] + [i for i in range(len(group)) if i != c]
    reading = {k: v for k, v in reading.items() if k != "warn"}     # noted when the joint's own rows were read
    try:
        _, datas = group_rows(table, [sub.joints[i] for i in order], name, **reading)
    except LogError:
        return {}
    qd = np.empty((len(datas[0]), len(group)))
    for i, d in zip(order, datas):
        qd[:, i] = d.signals["qd"]
    out = {partner_key(sub.joints[i]): qd[:, i] for i in order[1:]}
    w = sub.motor_velocities(qd)
    for m in range(len(group)):
        if sub.ratio[m, c] != 0 and np.count_nonzero(sub.ratio[m]) > 1:
            out[f"sign_motor@{sub.joints[m]}"] = np.sign(w[:, m])
    return out
