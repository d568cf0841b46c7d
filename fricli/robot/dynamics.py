"""Rigid-body terms from a URDF with Pinocchio (the optional extra ``fricli[robot]``).

For joint positions q, velocities qd and accelerations qdd, arrays of shape (n, joints) in the
URDF's joint order (rad or m, per second, per second squared):

    tau_g   = g(q)                              gravity torque [Nm or N]
    tau_dyn = M(q) qdd + C(q, qd) qd + I_r qdd  with reflected rotor inertias I_r [kg m^2]

A URDF may carry the reflected rotor inertias itself, in Pinocchio's SRDF form (what
``fricli calibrate`` writes; ``pin.loadRotorParameters`` reads the same element):
``<rotor_params><joint name="J" mass="I_rotor" gear_ratio="N"/></rotor_params>`` under
``<robot>``, armature = I_rotor * N^2. For those joints it replaces a rotor inertia given otherwise.

Rotors coupled through a transmission (``fricli.core.transmission``) also need the per-motor rotor
inertias J_m and the ratio matrix R, for the cross-term of R^T diag(J_m) R that a diagonal armature
cannot hold. ``fricli calibrate`` writes them under ``<robot>`` in an element of fricli's own, which
URDF parsers ignore (``TRANSMISSION``)::

    <fricli_transmission>
      <motor joint="J5" rotor_inertia="J_m"><ratio joint="J5" value="R55"/></motor>
      <motor joint="J6" rotor_inertia="J_m"><ratio joint="J5" value="R65"/><ratio joint="J6" value="R66"/></motor>
    </fricli_transmission>

(one motor per joint listed, named by that joint; each ``ratio`` an entry of its row of R). The
diagonal of R^T diag(J_m) R is those joints' armature (``rotor_params`` may repeat it and must then
agree); its off-diagonal part, ``RobotModel.cross_inertia``, is added to tau_dyn as well.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
import sys
import tempfile

import numpy as np

from fricli.core.errors import LogError, MissingDependencyError, ModelFileError
from fricli.core.logs import DEFAULT_GRAVITY
from fricli.robot.mapping import Payload

INSTALL = "pip install 'fricli[robot]'"
TRANSMISSION = "fricli_transmission"   # the URDF element of per-motor rotor inertias (module docstring)


def pinocchio():
    """The pinocchio module, or MissingDependencyError (exit 10) with the install line."""
    try:
        import pinocchio as pin
    except ImportError:
        raise MissingDependencyError(f"--urdf needs Pinocchio: {INSTALL}") from None
    return pin


@contextlib.contextmanager
def _c_stderr():
    """What C code writes to file descriptor 2 meanwhile, kept from the user: yields a function
    giving its lines (stripped, without empty ones) once the block has ended."""
    sys.stderr.flush()
    saved = os.dup(2)
    lines: list[str] = []
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lambda: lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            lines += [ln.strip() for ln in tmp.read().decode("utf-8", "replace").splitlines() if ln.strip()]


class RobotModel:
    """A URDF's rigid-body model with a gravity vector [m/s^2] and an optional point payload."""

    def __init__(self, urdf_text: str, name: str, gravity=DEFAULT_GRAVITY, payload: Payload | None = None,
                 held: tuple[str, ...] = ()):
        pin = pinocchio()
        self.name = name
        self.sha256 = hashlib.sha256(urdf_text.encode("utf-8")).hexdigest()
        self.held: tuple[str, ...] = ()
        if "<xacro:" in urdf_text:
            raise ModelFileError(f"{name}: a xacro file, not a URDF: expand it first (xacro {name} > robot.urdf, "
                                 "or save the robot_description a running robot publishes)")
        if held:
            urdf_text, self.held = hold_joints(urdf_text, name, held)
        try:
            with _c_stderr() as said:    # the URDF parser prints its complaints itself
                model = pin.buildModelFromXML(urdf_text)
        except Exception as exc:  # pinocchio raises ValueError/RuntimeError for bad XML
            why = " ".join(" ".join(said()[:1]).removeprefix("Error:").split()) or (
                str(exc).splitlines()[0] if str(exc) else str(exc))
            raise ModelFileError(f"{name}: not a usable URDF ({why})") from None
        if model.nv == 0:
            raise ModelFileError(f"{name}: the URDF has no moving joints")
        self.links = link_inertials(urdf_text, name)   # each link's own (10,), before Pinocchio merges fixed links
        check_axes(urdf_text, name)
        self.joints = list(model.names)[1:]
        self.kinds = []
        self.continuous = []  # continuous joints: pinocchio's configuration is (cos q, sin q)
        for joint in model.joints[1:]:
            short = joint.shortname().removeprefix("JointModel")
            if joint.nv != 1 or short[:1] not in ("R", "P") or short.startswith("Planar"):
                raise ModelFileError(f"{name}: joint type {joint.shortname()} is not supported "
                                     "(revolute, continuous and prismatic only)")
            self.kinds.append("rotary" if short[0] == "R" else "linear")
            self.continuous.append(joint.nq == 2)
        # each joint's position limits (joints, 2) [rad or m]; NaN for a continuous joint
        self.limits = np.array([(model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]) if j.nq == 1
                                else (np.nan, np.nan) for j in model.joints[1:]], dtype=float).reshape(-1, 2)
        self.payload_parameters = np.zeros((model.nv, 10))   # a declared payload in each body's parameters
        if payload is not None and payload.mass > 0:
            if not model.existFrame(payload.frame):
                frames = ", ".join(dict.fromkeys(f.name for f in model.frames if f.name != "universe"))
                raise ModelFileError(f"{name}: no frame {payload.frame!r} for the payload; the frames are: {frames}")
            frame = model.frames[model.getFrameId(payload.frame)]
            point = frame.placement.act(pin.Inertia(payload.mass, np.asarray(payload.com, dtype=float), np.zeros((3, 3))))
            model.inertias[frame.parentJoint] = model.inertias[frame.parentJoint] + point
            if frame.parentJoint > 0:
                self.payload_parameters[frame.parentJoint - 1] = point.toDynamicParameters()
        self.armature = rotor_params(urdf_text, name, model)  # (joints,), NaN where the URDF gives none
        # per-motor rotor inertias (URDF joint names), or None; their cross-term (joints, joints) [kg m^2]
        self.transmission = urdf_transmission(urdf_text, name, model)
        self.cross_inertia = np.zeros((model.nv, model.nv))
        if self.transmission is not None:
            idx = [self.joints.index(j) for j in self.transmission.joints]
            self.cross_inertia[np.ix_(idx, idx)] = self.transmission.cross_inertia()
            for j, a in zip(idx, self.transmission.armature()):
                if not np.isnan(self.armature[j]) and not np.isclose(self.armature[j], a, rtol=1e-9, atol=0.0):
                    raise ModelFileError(f"{name}: rotor_params of joint {self.joints[j]!r} ({self.armature[j]:.6g} "
                                         f"kg m^2) differs from the diagonal of its {TRANSMISSION} ({a:.6g} kg m^2)")
                self.armature[j] = a
        model.armature = np.nan_to_num(self.armature)
        model.gravity = pin.Motion(np.asarray(gravity, dtype=float), np.zeros(3))
        self._with_g = model
        self._no_g = model.copy()
        self._no_g.gravity = pin.Motion.Zero()

    def match(self, urdf_names: list[str | None], how: str) -> list[int]:
        """For each log joint, the index of its URDF joint. ``how``: "order" (the i-th log joint
        is the i-th moving URDF joint) or "name" (``urdf_names``). ModelFileError when they differ."""
        n_log, n_urdf = len(urdf_names), len(self.joints)
        if how == "order":
            if n_log != n_urdf:
                raise ModelFileError(f"{self.name}: {n_urdf} moving joints, but the log has {n_log}: "
                                     "matching by order needs the same count")
            return list(range(n_urdf))
        missing = [u for u in urdf_names if u not in self.joints]
        if missing and missing[0] in self.held:
            raise ModelFileError(f"{self.name}: joint {missing[0]!r} is held at zero (--hold, or hold = [...] in the "
                                 "mapping), but the log records it: hold only joints the log does not record")
        if missing:
            raise ModelFileError(f"{self.name}: no joint {missing[0]!r} (it has {', '.join(self.joints)})")
        dup = next((u for u in urdf_names if urdf_names.count(u) > 1), None)
        if dup is not None:
            raise ModelFileError(f"{self.name}: joint {dup!r} is matched by two log joints")
        unmatched = [j for j in self.joints if j not in urdf_names]
        if unmatched:
            kind = self.kinds[self.joints.index(unmatched[0])]
            raise ModelFileError(f"{self.name}: joint {unmatched[0]!r} ({'prismatic' if kind == 'linear' else 'revolute'}"
                                 f"{', and ' + str(len(unmatched) - 1) + ' more' if len(unmatched) > 1 else ''}) is not "
                                 "in the log: every moving joint needs its position. Joints the controller does not "
                                 "record (a gripper's fingers) can be held at their zero position: --hold JOINT, or "
                                 "hold = [...] under [robot] in the mapping (docs/robot-import.md)")
        return [self.joints.index(u) for u in urdf_names]

    def terms(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
              rotor_inertia: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(tau_g, tau_dyn), each (n, joints), for inputs of shape (n, joints) in URDF order."""
        zeros = np.zeros_like(q)
        config = self.configuration(q)
        tau_g = _rnea(self._with_g, config, zeros, zeros)
        tau_dyn = _rnea(self._no_g, config, qd, qdd)
        if rotor_inertia is not None:  # not where the URDF's own armature (in tau_dyn already) applies
            tau_dyn += qdd * np.where(np.isnan(self.armature), np.asarray(rotor_inertia, dtype=float), 0.0)
        if self.cross_inertia.any():
            tau_dyn += qdd @ self.cross_inertia.T
        return tau_g, tau_dyn


    @property
    def pin_model(self):
        """The Pinocchio model, with gravity, armature and payload."""
        return self._with_g

    def configuration(self, q: np.ndarray) -> np.ndarray:
        """Pinocchio's configurations (n, nq) for joint positions q (n, joints)."""
        if not any(self.continuous):
            return q
        parts = [np.column_stack([np.cos(q[:, k]), np.sin(q[:, k])]) if unbounded else q[:, k:k + 1]
                 for k, unbounded in enumerate(self.continuous)]
        return np.hstack(parts)


def hold_joints(urdf_text: str, name: str, held) -> tuple[str, tuple[str, ...]]:
    """``urdf_text`` with the joints ``held`` (and those that mimic them) made ``type="fixed"`` at
    their zero position: their links then move with their parents (Pinocchio merges them into the
    parent body). Returns the text and the joints held, in the URDF's order. ModelFileError for a
    name that is no moving joint of the URDF."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(urdf_text)
    except ET.ParseError as exc:
        raise ModelFileError(f"{name}: not a usable URDF ({exc})") from None
    joints = {j.get("name"): j for j in root.findall("joint")}
    moving = [n for n, j in joints.items() if j.get("type") in ("revolute", "continuous", "prismatic")]
    for joint in held:
        if joint not in moving:
            raise ModelFileError(f"{name}: no moving joint {joint!r} to hold (its moving joints: {', '.join(moving)})")
    wanted = set(held)
    wanted |= {n for n in moving if (m := joints[n].find("mimic")) is not None and m.get("joint") in wanted}
    for joint in wanted:
        element = joints[joint]
        element.set("type", "fixed")
        for mimic in element.findall("mimic"):
            element.remove(mimic)
    return ET.tostring(root, encoding="unicode"), tuple(n for n in moving if n in wanted)


def link_inertials(urdf_text: str, name: str) -> dict[str, np.ndarray]:
    """Each URDF link's own inertial parameters (10,) in its frame (Pinocchio's dynamic parameters:
    m, m c, inertia at the frame's origin). ModelFileError for a mass that is negative or no finite
    number: Pinocchio would merge such a link into its parent body without complaint, into nonsense."""
    import xml.etree.ElementTree as ET

    pin = pinocchio()
    try:
        links = ET.fromstring(urdf_text).findall("link")
    except ET.ParseError as exc:
        raise ModelFileError(f"{name}: not a usable URDF ({exc})") from None

    def numbers(element, key, default):
        return [float(v) for v in (element.get(key, default) if element is not None else default).split()]

    out = {}
    for link in links:
        inertial, who = link.find("inertial"), f"{name}: link {link.get('name')!r}"
        if inertial is None:
            out[link.get("name")] = np.zeros(10)
            continue
        try:
            mass = numbers(inertial.find("mass"), "value", "0")[0]
            xyz, rpy = (numbers(inertial.find("origin"), key, "0 0 0") for key in ("xyz", "rpy"))
            moments = inertial.find("inertia")
            get = {k: numbers(moments, k, "0")[0] for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
            rot = pin.rpy.rpyToMatrix(np.array(rpy, dtype=float))
        except (ValueError, IndexError, TypeError):
            raise ModelFileError(f"{who}: its <inertial> holds a value that is no number") from None
        if len(xyz) != 3 or len(rpy) != 3:
            raise ModelFileError(f"{who}: its <inertial> origin needs three numbers in xyz and in rpy")
        if not (math.isfinite(mass) and mass >= 0):
            raise ModelFileError(f"{who}: mass {mass:g} kg: a link's mass is a finite number, not negative")
        tensor = np.array([[get["ixx"], get["ixy"], get["ixz"]], [get["ixy"], get["iyy"], get["iyz"]],
                           [get["ixz"], get["iyz"], get["izz"]]])
        check_inertia(tensor, who)
        c = np.array(xyz, dtype=float)   # the inertia at the frame's origin by the parallel-axis theorem
        i_o = rot @ tensor @ rot.T + mass * (c @ c * np.eye(3) - np.outer(c, c))
        out[link.get("name")] = np.array([mass, *(mass * c), i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2], i_o[1, 2],
                                          i_o[2, 2]])
    return out


def check_axes(urdf_text: str, name: str) -> None:
    """ModelFileError for a moving joint whose <axis xyz> is zero (once Pinocchio has read the URDF:
    three numbers): Pinocchio builds the joint all the same, and its torques come out zero."""
    import xml.etree.ElementTree as ET

    for joint in ET.fromstring(urdf_text).iter("joint"):
        axis = joint.find("axis")
        if joint.get("type") != "fixed" and axis is not None and \
                not np.linalg.norm([float(v) for v in axis.get("xyz", "1 0 0").split()]) > 1e-9:
            raise ModelFileError(f"{name}: joint {joint.get('name')!r} has the axis {axis.get('xyz')!r}: a joint's "
                                 "axis is a direction, not zero")


def check_kind(robot: "RobotModel", k: int, log_joint, axis: str, hint: str = "") -> None:
    """ModelFileError when URDF joint ``k`` (revolute or prismatic) is not of the kind of the log's
    joint ``log_joint`` (``axis``: its units', rotary or linear)."""
    if robot.kinds[k] != axis:
        raise ModelFileError(f"{robot.name}: joint {robot.joints[k]} is {robot.kinds[k]}, but log joint {log_joint} "
                             f"is {axis}{hint}")


def require_positions(signals: dict, where: str) -> None:
    """LogError when a joint's signals hold no positions q: the rigid-body terms are of q (a log
    may hold qd alone, which friction needs)."""
    if "q" not in signals:
        raise LogError(f"{where}: the robot model needs positions q, and there are none")


def check_inertia(tensor: np.ndarray, who: str) -> None:
    """ModelFileError unless a link's rotational inertia (3, 3) [kg m^2] is finite and positive
    semi-definite (no principal moment below 0, beyond rounding): a negative moment of inertia has
    no body, and Pinocchio would take it without complaint."""
    if not np.isfinite(tensor).all():
        raise ModelFileError(f"{who}: its <inertia> holds a value that is not finite")
    for axis in ("xx", "yy", "zz"):
        k = "xyz".index(axis[0])
        if tensor[k, k] < 0:
            raise ModelFileError(f"{who}: i{axis} {tensor[k, k]:g} kg m^2: a moment of inertia is not negative")
    moments = np.linalg.eigvalsh(tensor)
    if moments[0] < -1e-9 * max(1.0, float(np.abs(moments).max())):
        raise ModelFileError(f"{who}: its inertia tensor has a negative principal moment ({moments[0]:.3g} kg m^2): "
                             "the products of inertia are too large for its moments")


def rotor_params(urdf_text: str, name: str, model) -> np.ndarray:
    """Armature [kg m^2] per moving joint (URDF order) from ``<robot><rotor_params>``; NaN where
    the URDF gives none. ModelFileError for a joint it does not have or a value that is no number."""
    import xml.etree.ElementTree as ET

    out = np.full(model.nv, np.nan)
    if "rotor_params" not in urdf_text:
        return out
    root = ET.fromstring(urdf_text)
    joints = list(model.names)[1:]
    for element in root.findall("rotor_params/joint"):
        joint = element.get("name")
        if joint not in joints:
            raise ModelFileError(f"{name}: rotor_params names joint {joint!r}, which is not a moving joint")
        try:
            value = float(element.get("mass", "nan")) * float(element.get("gear_ratio", "1")) ** 2
        except ValueError:
            value = float("nan")
        if not np.isfinite(value) or value < 0:
            raise ModelFileError(f"{name}: rotor_params of joint {joint!r}: mass and gear_ratio must be "
                                 "finite numbers, the mass not negative")
        out[joints.index(joint)] = value
    return out


def urdf_transmission(urdf_text: str, name: str, model):
    """The ``<robot><fricli_transmission>`` of a URDF as a ``Transmission`` over URDF joint names
    (rotor inertias J_m per motor, ratio matrix R), or None. ModelFileError when it is malformed."""
    import xml.etree.ElementTree as ET

    from fricli.core.transmission import Transmission

    element = ET.fromstring(urdf_text).find(TRANSMISSION) if TRANSMISSION in urdf_text else None
    if element is None:
        return None
    where = f"{name}: {TRANSMISSION}"
    joints = list(model.names)[1:]
    motors = [m.get("joint") for m in element.findall("motor")]
    if not motors:
        raise ModelFileError(f"{where}: no <motor joint=\"J\" rotor_inertia=\"J_m\"> in it")
    for joint in motors:
        if joint not in joints or motors.count(joint) > 1:
            raise ModelFileError(f"{where}: the motor of joint {joint!r} is listed twice or names no moving joint")
    ratio, inertia = np.zeros((len(motors), len(motors))), np.zeros(len(motors))

    def number(value, what):
        try:
            return float(value)
        except (TypeError, ValueError):
            raise ModelFileError(f"{where}: {what} is {value!r}, not a number") from None

    for i, motor in enumerate(element.findall("motor")):
        inertia[i] = number(motor.get("rotor_inertia"), f"rotor_inertia of the motor of joint {motors[i]!r}")
        for entry in motor.findall("ratio"):
            if entry.get("joint") not in motors:
                raise ModelFileError(f"{where}: the motor of joint {motors[i]!r} has a ratio to joint "
                                     f"{entry.get('joint')!r}, whose motor is not listed")
            ratio[i, motors.index(entry.get("joint"))] = number(entry.get("value"), f"a ratio of the motor of joint "
                                                                                      f"{motors[i]!r}")
    try:
        return Transmission(motors, ratio, rotor_inertia=inertia)
    except ValueError as exc:
        raise ModelFileError(f"{where}: {exc}") from None


def _rnea(model, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """Inverse dynamics for every row: shape (n, nv)."""
    pin = pinocchio()
    if len(q) and hasattr(pin, "rneaInParallel"):  # one call for all samples (pinocchio >= 3)
        pool = pin.ModelPool(model, 1)
        out = pin.rneaInParallel(1, pool, np.asfortranarray(q.T), np.asfortranarray(qd.T), np.asfortranarray(qdd.T))
        # (nv, n), or (n,) for a model of one joint: pinocchio returns a vector then
        return np.ascontiguousarray(np.asarray(out).reshape(model.nv, len(q)).T)
    return _rnea_rows(model, q, qd, qdd)


def _rnea_rows(model, q, qd, qdd) -> np.ndarray:
    pin = pinocchio()
    data = model.createData()
    out = np.empty_like(q)
    for k in range(len(q)):
        out[k] = pin.rnea(model, data, q[k], qd[k], qdd[k])
    return out


def _urdf_text(path: str) -> str:
    from fricli.core import files

    data = files.read_bytes(path, ModelFileError, "URDF file", "URDF file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ModelFileError(f"{path}: cannot read ({exc})") from None


def load_model(path: str, mapping) -> RobotModel:
    """The URDF at ``path`` with the mapping's gravity, payload and held joints."""
    pinocchio()  # the install hint comes before any complaint about the file
    return RobotModel(_urdf_text(path), path, gravity=mapping.gravity, payload=mapping.payload, held=mapping.held)


def held_joints(path: str, held) -> tuple[str, ...]:
    """The joints of the URDF at ``path`` that holding ``held`` holds: those and the ones that mimic them."""
    return hold_joints(_urdf_text(path), path, held)[1] if held else ()
