"""The mapping of a robot recording: which text column holds what, in which unit, per joint.

A mapping is a TOML file (see docs/robot-import.md). Columns are given by 1-based index or,
when the file has a header line, by header name. Example::

    header = false
    time = {column = 1, unit = "s"}

    [[joints]]
    name = 1
    q = {column = 2, unit = "rad"}
    i_m = {column = 14, unit = "A"}
    kt = 10.0

A recording may come in several files joined row by row (``files``), keep its time as a sample
rate (``time = {rate = HZ}``), scale and offset any column, and hold motor-side signals (``theta``,
``theta_d``, ``tau_motor``) that a ``[transmission]`` maps to the joints (docs/robot-import.md,
"Motor-side recordings and coupled wrists").
"""

from __future__ import annotations

import dataclasses
import math
import tomllib

from fricli.core import files
from fricli.core.errors import LogError
from fricli.core.logs import DEFAULT_GRAVITY, column_unit

# per-joint signals a mapping may name, with their default unit
SIGNALS = {"q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "i_m": "A", "tau_m": "Nm",
           "tau_ext": "Nm", "temp": "degC"}
# motor-side signals (with a [transmission]) and the joint-side signal each becomes
MOTOR_SIGNALS = {"theta": ("q", "rad"), "theta_d": ("qd", "rad/s"), "tau_motor": ("tau_m", "Nm")}
MATCHES = ("name", "order")
JOINS = ("rows", "time")
_TOP_KEYS = {"header", "delimiter", "decimal", "time", "joints", "robot", "files", "join", "transmission"}
_JOINT_KEYS = {"name", "urdf", "kt", "rotor_inertia", *SIGNALS, *MOTOR_SIGNALS}
_COLUMN_KEYS = {"column", "unit", "file", "scale", "offset"}
_TRANSMISSION_KEYS = {"gear_ratios", "ratio", "offset", "rotor_inertia"}
_ROBOT_KEYS = {"match", "gravity", "payload", "hold"}
_PAYLOAD_KEYS = {"mass", "com", "frame"}
# a ROS bag's mapping: what a JointState's effort is, per joint (docs/robot-import.md)
EFFORTS = {"tau_m": "joint-side torque [Nm]", "i_m": "motor current [A], with kt [Nm/A]",
           "motor_torque": "motor-side torque [Nm], with gear_ratio"}
_BAG_TOP_KEYS = {"joints", "robot"}
_BAG_JOINT_KEYS = {"name", "urdf", "effort", "kt", "gear_ratio", "rotor_inertia"}


@dataclasses.dataclass(frozen=True)
class Column:
    """A text column: ``ref`` is a 1-based index (int) or a header name (str), in file number
    ``file`` (0: the first) of the mapping's ``files``. Its value is ``scale * raw + offset`` in
    ``unit``. A time kept as a sample rate has ``ref`` None and ``rate`` [Hz]."""

    ref: int | str | None
    unit: str
    factor: float          # to the canonical unit
    kind: str | None       # "rotary", "linear" or None (time, current, temperature)
    file: int = 0
    scale: float = 1.0
    offset: float = 0.0
    rate: float | None = None

    @property
    def key(self):
        """The column's key in a recording's values: ``ref`` in the first file, else (file, ref)."""
        return self.ref if self.file == 0 else (self.file, self.ref)

    def values(self, raw):
        """``scale * raw + offset``, each applied only when it changes something (a -0.0 stays -0.0)."""
        out = raw if self.scale == 1.0 else raw * self.scale
        return out if self.offset == 0.0 else out + self.offset


@dataclasses.dataclass(frozen=True)
class Payload:
    """A point mass [kg] at ``com`` [m] in the frame named ``frame`` of the robot description."""

    mass: float
    com: tuple[float, float, float]
    frame: str


@dataclasses.dataclass
class JointMap:
    name: int | str                 # the joint's name in the log
    columns: dict[str, Column]      # signal -> column
    kt: float | None = None         # drive gain [Nm/A]: torque constant x gear ratio
    rotor_inertia: float = 0.0      # reflected to the joint side [kg m^2]
    urdf: str | None = None         # the URDF joint's name when matching by name


@dataclasses.dataclass
class Mapping:
    time: Column
    joints: list[JointMap]
    header: bool = False
    delimiter: str = ","
    decimal: str = "."                # the decimal mark: "." or "," (then the delimiter is another)
    match: str | None = None
    gravity: tuple[float, float, float] = DEFAULT_GRAVITY
    payload: Payload | None = None
    files: tuple[str, ...] = ()       # labels of the input files, in the order they are given
    join: str = "rows"                # how several files' rows pair up: "rows" (row by row) or "time"
    transmission: object = None       # fricli.core.transmission.Transmission of motor-side signals
    held: tuple[str, ...] = ()        # URDF joints held at their zero position (not in the log)

    def joint(self, name: str) -> JointMap:
        """The joint whose log name reads ``name``."""
        for jm in self.joints:
            if str(jm.name) == str(name):
                return jm
        raise LogError(f"no joint {name} in the mapping (it has {', '.join(str(j.name) for j in self.joints)})")


def _fail(where: str, text: str):
    raise LogError(f"{where}: {text}")


def _unknown(table: dict, allowed: set, where: str) -> None:
    extra = sorted(set(table) - allowed)
    if extra:
        _fail(where, f"unknown key {extra[0]!r} (allowed: {', '.join(sorted(allowed))})")


def _number(value, where: str, *, positive: bool = False, nonnegative: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(where, f"expected a finite number, got {value!r}")
    if positive and value <= 0:
        _fail(where, f"must be positive, got {value!r}")
    if nonnegative and value < 0:
        _fail(where, f"must not be negative, got {value!r}")
    return float(value)


def _vector3(value, where: str) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        _fail(where, f"expected three numbers, got {value!r}")
    return tuple(_number(v, where) for v in value)


def _column(spec, signal: str, where: str, default_unit: str, files: tuple = ()) -> Column:
    extra = {}
    if isinstance(spec, dict):
        _unknown(spec, _COLUMN_KEYS, where)
        if "column" not in spec:
            _fail(where, "missing key 'column'")
        ref, unit = spec["column"], spec.get("unit", default_unit)
        extra = {k: _number(spec[k], f"{where}.{k}") for k in ("scale", "offset") if k in spec}
        if extra.get("scale") == 0.0:
            _fail(f"{where}.scale", "must not be zero")
        if "file" in spec:
            if spec["file"] not in files:
                _fail(f"{where}.file", f"expected one of the mapping's files ({', '.join(map(repr, files)) or 'none'}), "
                      f"got {spec['file']!r}")
            extra["file"] = files.index(spec["file"])
    else:
        ref, unit = spec, default_unit
    if isinstance(ref, bool) or not isinstance(ref, (int, str)) or (isinstance(ref, int) and ref < 1) or ref == "":
        _fail(where, f"a column is a 1-based index or a header name, got {ref!r}")
    if not isinstance(unit, str):
        _fail(where, f"unit must be a string, got {unit!r}")
    try:
        kind, factor = column_unit(signal, unit)
    except LogError as exc:
        _fail(where, str(exc))
    return Column(ref=ref, unit=unit, factor=factor, kind=kind, **extra)


def _time(spec, where: str, files: tuple) -> Column:
    """The time column, or ``{rate = HZ}``: no time column, row k of the files at k / rate [s]."""
    if isinstance(spec, dict) and "rate" in spec:
        _unknown(spec, {"rate"}, where)
        return Column(ref=None, unit="s", factor=1.0, kind=None,
                      rate=_number(spec["rate"], f"{where}.rate", positive=True))
    return _column(spec, "t", where, "s", files)


def _transmission(spec, joints: list, where: str):
    """The [transmission] table: ``gear_ratios`` (k,) signed, or ``ratio`` (k, k) (rows: motors,
    columns: joints, both in the order of [[joints]]); ``offset`` (k,) the motor angles at joint
    zero [rad] and ``rotor_inertia`` (k,) motor-side [kg m^2], both optional."""
    from fricli.core.transmission import Transmission

    if not isinstance(spec, dict):
        _fail(where, "expected a table")
    _unknown(spec, _TRANSMISSION_KEYS, where)
    if ("gear_ratios" in spec) == ("ratio" in spec):
        _fail(where, "needs exactly one of gear_ratios (per joint, signed) and ratio (a matrix)")
    k = len(joints)

    def vector(key):
        v = spec[key]
        if not isinstance(v, list) or len(v) != k:
            _fail(f"{where}.{key}", f"expected {k} numbers, one per joint in the order of [[joints]]")
        return [_number(x, f"{where}.{key}") for x in v]

    if "ratio" in spec:
        rows = spec["ratio"]
        if not isinstance(rows, list) or len(rows) != k or any(not isinstance(r, list) or len(r) != k for r in rows):
            _fail(f"{where}.ratio", f"expected {k} rows of {k} numbers (rows: motors, columns: joints)")
        ratio = [[_number(x, f"{where}.ratio") for x in r] for r in rows]
    else:
        ratios = vector("gear_ratios")
        if 0.0 in ratios:
            _fail(f"{where}.gear_ratios", "a gear ratio must not be zero")
        ratio = [[r if i == j else 0.0 for j in range(k)] for i, r in enumerate(ratios)]
    offset = vector("offset") if "offset" in spec else None
    inertia = vector("rotor_inertia") if "rotor_inertia" in spec else None
    try:
        return Transmission([jm.name for jm in joints], ratio, offset, inertia)
    except ValueError as exc:
        _fail(where, str(exc))


def _files(doc: dict, name: str) -> tuple[tuple, str]:
    files = doc.get("files", [])
    if not isinstance(files, list) or any(not isinstance(f, str) or not f for f in files) \
            or len(set(files)) < len(files):
        _fail(f"{name}: files", f"expected distinct labels of the input files, got {files!r}")
    join = doc.get("join", "rows")
    if join not in JOINS:
        _fail(f"{name}: join", f"expected 'rows' or 'time', got {join!r}")
    return tuple(files), join


def _payload(spec, where: str) -> Payload:
    if not isinstance(spec, dict):
        _fail(where, "expected a table with mass, com and frame")
    _unknown(spec, _PAYLOAD_KEYS, where)
    missing = sorted(_PAYLOAD_KEYS - set(spec))
    if missing:
        _fail(where, f"missing key {missing[0]!r}")
    if not isinstance(spec["frame"], str) or not spec["frame"]:
        _fail(f"{where}.frame", "expected a frame name")
    return Payload(mass=_number(spec["mass"], f"{where}.mass", nonnegative=True),
                   com=_vector3(spec["com"], f"{where}.com"), frame=spec["frame"])


def parse_mapping(doc: dict, name: str = "mapping") -> Mapping:
    """A ``Mapping`` from a parsed TOML document; LogError (exit 3) on any mistake."""
    _unknown(doc, _TOP_KEYS, name)
    header = doc.get("header", False)
    if not isinstance(header, bool):
        _fail(f"{name}: header", "expected true or false")
    delimiter = doc.get("delimiter", ",")
    if not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in "\r\n\"":
        _fail(f"{name}: delimiter", f"expected one character, got {delimiter!r}")
    decimal = doc.get("decimal", ".")
    if decimal not in (".", ","):
        _fail(f"{name}: decimal", f'expected "." or ",", got {decimal!r}')
    if decimal == delimiter:
        _fail(f"{name}: decimal", f"the decimal mark {decimal!r} is also the delimiter: set the delimiter the file "
              'uses between fields (delimiter = ";" or "\\t")')
    if "time" not in doc:
        _fail(name, "missing key 'time' (the time column, or {rate = HZ})")
    files, join = _files(doc, name)
    time = _time(doc["time"], f"{name}: time", files)
    if join == "time" and time.ref is None:
        _fail(f"{name}: join", "join = \"time\" needs a time column in every file, not a sample rate")
    motor_side = "transmission" in doc
    joints_doc = doc.get("joints")
    if not isinstance(joints_doc, list) or not joints_doc:
        _fail(name, "needs at least one [[joints]] table")
    joints: list[JointMap] = []
    for i, spec in enumerate(joints_doc, start=1):
        where = f"{name}: joints #{i}"
        if not isinstance(spec, dict):
            _fail(where, "expected a table")
        _unknown(spec, _JOINT_KEYS, where)
        jname = spec.get("name")
        if isinstance(jname, bool) or not isinstance(jname, (int, str)) or jname == "":
            _fail(where, f"'name' (the joint's name in the log, an integer or a string) is required, got {jname!r}")
        columns = {s: _column(spec[s], s, f"{where}.{s}", unit, files) for s, unit in SIGNALS.items() if s in spec}
        columns.update({s: _column(spec[s], joint_side, f"{where}.{s}", unit, files)
                        for s, (joint_side, unit) in MOTOR_SIGNALS.items() if s in spec})
        if motor_side:
            joint_sided = sorted(set(columns) & {"q", "qd", "qdd", "i_m", "tau_m"})
            if joint_sided:
                _fail(where, f"with a [transmission], positions and torques are motor-side: theta or theta_d, "
                      f"and tau_motor (not {joint_sided[0]})")
            if "theta" not in columns and "theta_d" not in columns:
                _fail(where, "needs a column for theta or theta_d (motor side)")
            if "tau_motor" not in columns:
                _fail(where, "needs a column for tau_motor (motor side; a current times its torque constant in scale)")
        else:
            motor = sorted(set(columns) & set(MOTOR_SIGNALS))
            if motor:
                _fail(where, f"{motor[0]} is a motor-side signal: it needs a [transmission] (docs/robot-import.md)")
            if "q" not in columns and "qd" not in columns:
                _fail(where, "needs a column for q or qd")
            if ("i_m" in columns) == ("tau_m" in columns):
                _fail(where, "needs exactly one of i_m (with kt) and tau_m")
        kinds = {c.kind for c in columns.values()} - {None}
        if len(kinds) > 1:
            _fail(where, "mixes rotary (rad, Nm) and linear (m, N) units")
        kt = _number(spec["kt"], f"{where}.kt", positive=True) if "kt" in spec else None
        if kt is not None and "tau_m" in columns:
            _fail(where, "kt applies to a current column i_m, not to tau_m")
        urdf = spec.get("urdf")
        if urdf is not None and (not isinstance(urdf, str) or not urdf):
            _fail(f"{where}.urdf", "expected a URDF joint name")
        joints.append(JointMap(name=jname, columns=columns, kt=kt, urdf=urdf,
                               rotor_inertia=_number(spec.get("rotor_inertia", 0.0), f"{where}.rotor_inertia",
                                                     nonnegative=True)))
    names = [str(j.name) for j in joints]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        _fail(name, f"joint {dup} appears twice")
    if len({type(j.name) for j in joints}) > 1:
        _fail(name, "joint names must be all integers or all strings")
    kinds = {c.kind for j in joints for c in j.columns.values()} - {None}
    if len(kinds) > 1:
        _fail(name, "mixes rotary and linear joints: a log holds one kind (import them separately; with --urdf, "
                    "map the arm's joints and hold the others: hold = [...] under [robot], or --hold JOINT)")
    _check_once(time, joints, name)
    transmission = _transmission(doc["transmission"], joints, f"{name}: transmission") if motor_side else None
    if transmission is not None and "rotor_inertia" in doc["transmission"] and any(j.rotor_inertia for j in joints):
        _fail(name, "rotor inertias are given twice: per joint (joint side) and in [transmission] (motor side)")
    if len(files) == 1:
        _fail(f"{name}: files", "a single file needs no 'files' (give it on the command line)")
    used = {c.file for j in joints for c in j.columns.values()}
    unused = [f for i, f in enumerate(files) if i not in used]
    if unused:
        _fail(f"{name}: files", f"no column is read from file {unused[0]!r}")
    return Mapping(time=time, joints=joints, header=header, delimiter=delimiter, decimal=decimal, files=files,
                   join=join,                    transmission=transmission, **_robot(doc, name))


def _check_once(time: Column, joints: list[JointMap], name: str) -> None:
    """LogError when a column is mapped to two signals (the time, or two signals of the joints): a
    typo that would import one signal as another. A temperature may be shared (one sensor)."""
    seen = {} if time.ref is None else {(time.file, time.ref): "the time"}
    for jm in joints:
        for signal, column in jm.columns.items():
            if signal == "temp":
                continue
            key, what = (column.file, column.ref), f"joint {jm.name}'s {signal}"
            if key in seen:
                _fail(name, f"column {column.ref!r} is mapped twice ({seen[key]} and {what}): a column holds one "
                            "signal of one joint")
            seen[key] = what


def _robot(doc: dict, name: str) -> dict:
    """match, gravity, payload and held joints from the mapping's [robot] table."""
    robot = doc.get("robot", {})
    if not isinstance(robot, dict):
        _fail(f"{name}: robot", "expected a table")
    _unknown(robot, _ROBOT_KEYS, f"{name}: robot")
    match = robot.get("match")
    if match is not None and match not in MATCHES:
        _fail(f"{name}: robot.match", f"expected 'name' or 'order', got {match!r}")
    gravity = _vector3(robot["gravity"], f"{name}: robot.gravity") if "gravity" in robot else DEFAULT_GRAVITY
    payload = _payload(robot["payload"], f"{name}: robot.payload") if "payload" in robot else None
    held = robot.get("hold", [])
    if not (isinstance(held, list) and all(isinstance(h, str) and h for h in held)):
        _fail(f"{name}: robot.hold", "expected a list of URDF joint names")
    return {"match": match, "gravity": gravity, "payload": payload, "held": tuple(held)}


def effort_column(effort: str, gear_ratio: float = 1.0) -> dict[str, Column]:
    """The signal a JointState's effort becomes: ``{"tau_m": ...}`` (joint-side, or motor-side
    times ``gear_ratio``) or ``{"i_m": ...}``; its ``ref`` is ``"effort"``."""
    if effort == "i_m":
        return {"i_m": Column(ref="effort", unit="A", factor=1.0, kind=None)}
    return {"tau_m": Column(ref="effort", unit="Nm", factor=gear_ratio if effort == "motor_torque" else 1.0,
                            kind="rotary")}


def parse_bag_mapping(doc: dict, name: str = "mapping") -> Mapping:
    """A ROS bag's ``Mapping`` (time None; each joint's columns hold only its effort, see
    ``effort_column``) from a parsed TOML document; LogError (exit 3) on any mistake."""
    _unknown(doc, _BAG_TOP_KEYS, f"{name} (a ROS bag's mapping)")
    joints_doc = doc.get("joints", [])
    if not isinstance(joints_doc, list):
        _fail(name, "'joints' must be [[joints]] tables")
    joints: list[JointMap] = []
    for i, spec in enumerate(joints_doc, start=1):
        where = f"{name}: joints #{i}"
        if not isinstance(spec, dict):
            _fail(where, "expected a table")
        _unknown(spec, _BAG_JOINT_KEYS, where)
        jname = spec.get("name")
        if not isinstance(jname, str) or not jname:
            _fail(where, f"'name' (the joint's name in the JointState messages) is required, got {jname!r}")
        effort = spec.get("effort", "tau_m")
        if effort not in EFFORTS:
            _fail(f"{where}.effort", f"expected one of {', '.join(repr(e) for e in EFFORTS)}, got {effort!r}")
        if "kt" in spec and effort != "i_m":
            _fail(where, "kt applies to effort = \"i_m\" (a current)")
        if "gear_ratio" in spec and effort != "motor_torque":
            _fail(where, "gear_ratio applies to effort = \"motor_torque\"")
        if effort == "motor_torque" and "gear_ratio" not in spec:
            _fail(where, "effort = \"motor_torque\" needs gear_ratio (joint-side torque = gear_ratio x effort)")
        ratio = _number(spec["gear_ratio"], f"{where}.gear_ratio", positive=True) if "gear_ratio" in spec else 1.0
        urdf = spec.get("urdf")
        if urdf is not None and (not isinstance(urdf, str) or not urdf):
            _fail(f"{where}.urdf", "expected a URDF joint name")
        joints.append(JointMap(name=jname, columns=effort_column(effort, ratio), urdf=urdf,
                               kt=_number(spec["kt"], f"{where}.kt", positive=True) if "kt" in spec else None,
                               rotor_inertia=_number(spec.get("rotor_inertia", 0.0), f"{where}.rotor_inertia",
                                                     nonnegative=True)))
    names = [j.name for j in joints]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        _fail(name, f"joint {dup} appears twice")
    return Mapping(time=None, joints=joints, **_robot(doc, name))


def load_mapping(path: str, *, bag: bool = False) -> Mapping:
    """Read a TOML mapping file (of a ROS bag with ``bag``); LogError (exit 3) when it is missing
    or wrong."""
    text = files.read_bytes(path, LogError, "mapping file", "mapping file")
    try:
        # a byte order mark, as editors on Windows save UTF-8 and UTF-16 text, is no TOML
        doc = tomllib.loads(text.decode("utf-16" if text[:2] in (b"\xff\xfe", b"\xfe\xff") else "utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise LogError(f"{path}: not a valid TOML mapping ({str(exc).splitlines()[0]})") from None
    return parse_bag_mapping(doc, path) if bag else parse_mapping(doc, path)


def parse_overrides(pairs, what: str, *, nonnegative: bool = False) -> dict[str, float]:
    """``("JOINT=VALUE", ...)`` -> {joint: value}; LogError on a malformed pair."""
    out: dict[str, float] = {}
    for pair in pairs:
        joint, sep, value = pair.partition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not sep or not joint or not math.isfinite(number) or number < 0 or (number == 0 and not nonnegative):
            raise LogError(f"{what}: expected JOINT=VALUE with a {'non-negative' if nonnegative else 'positive'} "
                           f"number, got {pair!r}")
        out[joint] = number
    return out


def merge_payload(base: Payload | None, mass=None, com=None, frame=None) -> Payload:
    """``base`` with the given fields replaced (mass 0 kg and com at the frame's origin by default)."""
    return Payload(mass=float(mass) if mass is not None else (base.mass if base else 0.0),
                   com=tuple(float(c) for c in com) if com is not None else (base.com if base else (0.0, 0.0, 0.0)),
                   frame=frame if frame is not None else base.frame)


def payload_option(base: Payload | None, mass=None, com=None, frame=None) -> Payload | None:
    """The payload of --payload-mass, --payload-com, --payload-frame over ``base`` (the mapping's,
    or None): None when none of them is given; OptionError when no frame carries it."""
    if mass is None and com is None and frame is None:
        return None
    if frame is None and base is None:
        from fricli.fitting.optionspec import OptionError

        raise OptionError("--payload-mass/--payload-com need --payload-frame (or robot.payload in the mapping)",
                          "payload_frame")
    return merge_payload(base, mass, com, frame)


def apply_overrides(mapping: Mapping, *, kt=None, rotor_inertia=None, match=None, gravity=None,
                    payload: Payload | None = None, held=()) -> Mapping:
    """``mapping`` with options from the command line taking precedence (in place; returned)."""
    for joint, value in (kt or {}).items():
        jm = mapping.joint(joint)
        if "tau_m" in jm.columns:
            raise LogError(f"--kt {joint}={value:g}: joint {joint} has a torque column tau_m, not a current")
        jm.kt = value
    for joint, value in (rotor_inertia or {}).items():
        mapping.joint(joint).rotor_inertia = value
    if match is not None:
        mapping.match = match
    if gravity is not None:
        mapping.gravity = tuple(float(g) for g in gravity)
    if payload is not None:
        mapping.payload = payload
    if held:
        mapping.held = tuple(dict.fromkeys((*mapping.held, *held)))
    return mapping
