"""A robot recording (+ mapping, + optional URDF) -> one long-format log in the log contract.

Rows are grouped by joint, in the mapping's order; every column is in canonical units (s, rad,
rad/s, rad/s^2, A, Nm, degC; m and N on linear axes) with the unit in the field metadata.
The Parquet schema metadata key ``fricli.import`` records the source, the drive gains, the
dropped rows and, with a URDF, the robot model options and which of qd/qdd were derived.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os

import numpy as np

from fricli.core import logs
from fricli.core.errors import LogError
from fricli.core import transmission
from fricli.robot.mapping import Mapping
from fricli.robot.recording import KINDS, Recording, read_recording

META_KEY = b"fricli.import"


@dataclasses.dataclass
class Imported:
    table: object                  # pyarrow.Table
    recording: Recording
    meta: dict
    notices: list = dataclasses.field(default_factory=list)   # (warning | note, one line) of ``import_log``
    mapping: Mapping | None = None   # the mapping imported with (a bag's: its joints filled in)
    name: str = ""                   # the recording's name (stdin; several files' joined by +)
    source: str = ""                 # what was imported: the name, or a bag's topic in it


def is_bag(path: str) -> bool:
    """True when ``path`` is a ROS bag (a rosbag2 folder or a ROS 1 .bag file)."""
    from fricli.robot import rosbag

    return rosbag.is_bag(path)


def check_files(recordings: list[str], mapping: Mapping, mapping_name: str = "the mapping") -> None:
    """LogError when a recording in several files (``mapping.files``) is not given as that many files."""
    if (len(recordings) > 1 or mapping.files) and len(recordings) != len(mapping.files):
        raise LogError(f"{mapping_name}: the mapping names {len(mapping.files)} files "
                       f"({', '.join(mapping.files) or 'none'}), but {len(recordings)} recordings were given")


def import_log(recordings: str | list[str], mapping: str | Mapping | None = None, *, output: str | None = None,
               urdf: str | None = None, topic: str | None = None, kt=None, rotor_inertia=None,
               match: str | None = None, gravity=None, payload_mass: float | None = None, payload_com=None,
               payload_frame: str | None = None, held=(), cutoff_hz: float | str | None = None,
               drop_backward: bool = False) -> Imported:
    """``fricli import``: one long-format log of a recording, written to ``output`` when given
    (a Parquet file, - for stdout). ``recordings``: a ROS bag (read with ``topic``), the files of
    a recording in several files (the mapping's ``files``), or one delimited text file (- for
    stdin); ``mapping``: a TOML mapping file's path or a ``Mapping`` (optional for a bag). The
    command line's overrides as keywords: ``kt``, ``rotor_inertia`` {joint: value}, ``match``,
    ``gravity``, ``payload_mass`` [kg], ``payload_com`` (3,) [m], ``payload_frame``, ``held`` URDF joints; with ``urdf`` tau_g and tau_dyn are added
    (``cutoff_hz``: of the derived qd, qdd). Options that do not go together raise ``OptionError``
    naming the option. ``Imported.notices`` holds the warnings and notes on what was dropped or
    assumed, in order (the command prints them on stderr)."""
    from fricli.core.logs import write_table
    from fricli.fitting.optionspec import OptionError
    from fricli.robot import mapping as mp

    recordings = [recordings] if isinstance(recordings, str) else list(recordings)
    if not recordings:
        raise OptionError("no recording given", "recordings")
    recording = recordings[0]
    bag = is_bag(recording)
    if bag:   # a folder that is no bag says so before its mapping is read as a bag's
        from fricli.robot import rosbag

        rosbag.bag_paths(recording)
    if len(recordings) > 1 and (bag or mapping is None):
        raise OptionError("several recordings are the files of one text recording: give a mapping (--mapping "
                          "MAP.toml) with their 'files' (docs/robot-import.md)", "mapping")
    if mapping is None and not bag:
        if recording != "-" and not os.path.exists(recording):
            raise LogError(f"{recording}: no such file, folder or bag")
        raise OptionError("a text recording needs a mapping (--mapping MAP.toml; docs/robot-import.md)", "mapping")
    if topic is not None and not bag:
        raise OptionError("--topic applies to a ROS bag", "topic")
    mapping_name = mapping if isinstance(mapping, str) else "the mapping"
    if isinstance(mapping, str):
        mapping = mp.load_mapping(mapping, bag=bag)
    elif mapping is None:
        mapping = Mapping(time=None, joints=[])
    if (held or mapping.held) and urdf is None:
        raise OptionError("--hold (robot.hold) names URDF joints: it applies with --urdf", "held")
    if len(recordings) > 1 or mapping.files:
        check_files(recordings, mapping, mapping_name)
        if "-" in recordings:
            raise OptionError("the files of a recording in several files cannot be read from stdin", "recordings")
    payload = mp.payload_option(mapping.payload, payload_mass, payload_com, payload_frame)
    result = _import(recordings, mapping, bag, urdf=urdf, topic=topic, kt=kt, rotor_inertia=rotor_inertia,
                     match=match, gravity=gravity, payload=payload, held=held, cutoff_hz=cutoff_hz,
                     drop_backward=drop_backward)
    if output is not None:
        write_table(result.table, output)
    return result


def _import(recordings: list[str], mapping: Mapping, bag: bool, *, urdf, topic, kt, rotor_inertia, match, gravity,
            payload, held, cutoff_hz, drop_backward) -> Imported:
    from fricli.core.logs import read_bytes
    from fricli.robot import mapping as mp

    recording = recordings[0]
    name = " + ".join(recordings) if len(recordings) > 1 or mapping.files else log_name(recording)
    read = None
    if bag:
        from fricli.robot import rosbag
        from fricli.robot.dynamics import held_joints

        leave_out = held_joints(urdf, (*mapping.held, *held)) if urdf is not None else ()
        read = rosbag.read_bag(recording, mapping, topic, drop_backward=drop_backward, leave_out=leave_out)
        mapping = read.mapping
    mp.apply_overrides(mapping, kt=kt, rotor_inertia=rotor_inertia, match=match, gravity=gravity or None,
                       payload=payload, held=held)
    model = None
    if urdf is not None:
        from fricli.robot.dynamics import load_model

        model = load_model(urdf, mapping)
    if bag:
        extra = {"topic": read.topic, "stamps": read.stamps, "time_origin_ns": read.origin_ns,
                 "reordered": None if read.reordered is None else
                 {"count": read.reordered.count, "messages": read.reordered.ranges}}
        result = build_log(read.recording, mapping, name, read.sha256, model=model, cutoff_hz=cutoff_hz,
                           unit="message", extra=extra)
    elif mapping.files:
        result = import_files([read_bytes(r) for r in recordings], mapping, list(recordings), model=model,
                              cutoff_hz=cutoff_hz, drop_backward=drop_backward)
    else:
        result = import_recording(read_bytes(recording), mapping, name, model=model, cutoff_hz=cutoff_hz,
                                  drop_backward=drop_backward)
    result.mapping, result.name, result.source = mapping, name, f"{read.topic} in {name}" if bag else name
    result.notices = _notices(result.meta, name, read)
    return result


def log_name(path: str) -> str:
    return "stdin" if path == "-" else path


def _notices(meta: dict, name: str, read) -> list[tuple[str, str]]:
    """The warnings and notes of an import, in the order they are told."""
    out = []
    if read is not None:
        for field, d in read.partly_empty.items():
            out.append(("warning", f"warning: {name}: {d.count} {'messages' if d.count != 1 else 'message'} on "
                        f"{read.topic} {'hold' if d.count != 1 else 'holds'} no {field} "
                        f"(first at message {d.first_line}): the {field} of every message is left out"
                        + (" (qd and qdd are derived from the positions)" if field == "velocity" else "")))
        if read.stamps == "receive":
            out.append(("note", f"note: {name}: the messages on {read.topic} all have the same header stamp (unset or "
                        "set once): t is the time the bag received them"))
        if read.standalone:
            out.append(("note", f"note: {name}: no rosbag2 metadata.yaml (a recording that did not end cleanly?): "
                        f"read {', '.join(read.standalone)} as "
                        f"{'it is' if len(read.standalone) == 1 else 'they are'}"))
        if read.unread:
            out.append(("warning", f"warning: {name}: {read.unread} of the messages the bag's metadata lists on "
                        f"{read.topic} could not be read (a damaged or unfinished file): they are missing from the "
                        "log"))
    unit = meta["counted_in"]
    for d in meta["dropped"].values():
        rows = unit if unit == "message" else "row"
        out.append(("warning", f"warning: {name}: dropped {d['count']} {rows}{'s' if d['count'] != 1 else ''} with "
                    f"{d['what']} ({where(d, unit)}{': ' + d['example'] if d.get('example') else ''})"))
    if read is not None and read.reordered is not None:
        d = read.reordered
        out.append(("warning", f"warning: {name}: {d.count} {'messages list' if d.count != 1 else 'message lists'} "
                    f"the joints in another order than most messages "
                    f"({where({'count': d.count, 'messages': d.ranges}, 'message')}): reordered by name"))
    step = meta["time_step_s"]
    if logs.implausible_step(step):
        out.append(("warning", f"warning: {name}: the median time step is {step:.3g} s, which no controller samples "
                    "at: check the time column's unit in the mapping (s, ms, us or ns; a time in ms mapped as s "
                    "makes a 1 kHz log a 1 Hz one)"))
    if meta["i_m_left_out"]:
        left = meta["i_m_left_out"]
        out.append(("note", f"note: {name}: the effort of joint{'s' if len(left) > 1 else ''} {', '.join(left)} is a "
                    "current and of the others not: tau_m holds each joint's torque, and the log has no i_m column"))
    if meta.get("blank_lines"):
        k = meta["blank_lines"]
        out.append(("note", f"note: {name}: {k:,} blank line{'s' if k > 1 else ''} between the rows "
                    f"{'take' if k > 1 else 'takes'} no sample (rows are counted by data line, without them)"))
    for joint, text in meta.get("rate_mismatch", {}).items():
        out.append(("warning", f"warning: {name}, joint {joint}: {text}"))
    for joint, found in meta.get("not_measured", {}).items():
        out += [("note", f"note: {name}, joint {joint}: {note}") for note in found.values()]
    if meta["unterminated_last_line"]:
        out.append(("note", f"note: {name}: the last line (line {meta['unterminated_last_line']}) has no line end; "
                    "it is complete and kept"))
    return out


def where(entry: dict, unit: str) -> str:
    """'first at line 5', or 'lines 1-4, 9' from the runs of dropped lines when known; for a
    recording in several files, each file's ('pos.csv: line 101; cur.csv: line 301')."""
    if "files" in entry:
        return "; ".join(f"{name}: {where(d, unit)}" for name, d in entry["files"].items())
    runs = entry.get(f"{unit}s")
    if runs is None:
        return f"first at {unit} {entry[f'first_{unit}']}"
    shown = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs[:5])
    more = f", ... ({len(runs)} runs)" if len(runs) > 5 else ""
    return f"{unit}{'s' if entry['count'] != 1 else ''} {shown}{more}"


def _signals(mapping: Mapping, rec: Recording, name: str) -> tuple[np.ndarray, list[dict], str]:
    """Time [s] and, per joint, its signals in canonical units; and the axis kind."""
    t = mapping.time.values(rec.values[mapping.time.key]) * mapping.time.factor
    per_joint = []
    for jm in mapping.joints:
        sig = {s: c.values(rec.values[c.key]) * c.factor for s, c in jm.columns.items()}
        if "i_m" in sig:
            if jm.kt is None:
                raise LogError(f"{name}: joint {jm.name} has a current column i_m but no drive gain: "
                               f"give kt in the mapping or --kt {jm.name}=VALUE [Nm/A]")
            sig["tau_m"] = sig["i_m"] * jm.kt
        per_joint.append(sig)
    if mapping.transmission is not None:
        to_joints(mapping.transmission, per_joint)
    kinds = {c.kind for jm in mapping.joints for c in jm.columns.values()} - {None}
    return t, per_joint, kinds.pop() if kinds else "rotary"


def to_joints(tr, per_joint: list[dict]) -> None:
    """Replace the motor-side signals theta, theta_d, tau_motor (n,) of each joint by the joint-side
    q, qd, tau_m of the transmission ``tr`` (fricli.core.transmission), in place."""
    for motor, joint_side, convert in (("theta", "q", tr.joint_positions), ("theta_d", "qd", tr.joint_velocities),
                                       ("tau_motor", "tau_m", tr.joint_torques)):
        if all(motor in sig for sig in per_joint):
            values = convert(np.column_stack([sig.pop(motor) for sig in per_joint]))
            for k, sig in enumerate(per_joint):
                sig[joint_side] = values[:, k].copy()


def robot_terms(model, mapping: Mapping, t: np.ndarray, per_joint: list[dict], axis: str,
                 cutoff_hz: float | str | None = None) -> dict:
    """Add tau_g and tau_dyn (and derived qd/qdd) to ``per_joint`` (one dict of signals of shape
    (n,) per joint of ``mapping``, all at times ``t``) in place; the record of it. ``cutoff_hz``: of
    the low-pass for derived qd/qdd [Hz]; ``logs.AUTO_CUTOFF``: chosen (``choose_cutoff``); None: chosen
    when every joint has tau_m, else the log contract's ``logs.DEFAULT_CUTOFF_HZ``."""
    from fricli.robot.dynamics import check_kind, require_positions

    if mapping.match is None:
        raise LogError("choose how the log's joints match the URDF's: match = \"name\" or \"order\" under "
                       "[robot] in the mapping, or --match name|order")
    order = model.match([jm.urdf or str(jm.name) for jm in mapping.joints], mapping.match)
    for jm, sig, k in zip(mapping.joints, per_joint, order):
        check_kind(model, k, jm.name, axis, f"; a joint the robot model need not move (a gripper's) can be held at "
                   f"zero with --hold {model.joints[k]} and left out of the mapping (a ROS bag without a mapping "
                   "leaves held joints out itself)")
        require_positions(sig, f"joint {jm.name}")
    # a rotary joint recorded wrapped to one turn (a continuous joint, or a revolute one whose limits
    # pass +-pi, as some drivers report it) jumps by 2 pi, which no joint moves in one sample: velocity
    # and acceleration are derived from its unwrapped position (the log keeps q as recorded; the terms
    # read it through cos q, sin q, the Maxwell-slip elements take the step less the turn)
    unwrapped = [str(jm.name) for jm, sig, k in zip(mapping.joints, per_joint, order)
                 if model.kinds[k] == "rotary" and logs.wraps(sig["q"])]
    derivable = [dict(sig, q=np.unwrap(sig["q"])) if str(jm.name) in unwrapped else sig
                 for jm, sig in zip(mapping.joints, per_joint)]
    choice = None
    if cutoff_hz == logs.AUTO_CUTOFF or (cutoff_hz is None and all("tau_m" in sig for sig in per_joint)):
        choice = choose_cutoff(model, mapping, order, t, derivable)
    if cutoff_hz is None or cutoff_hz == logs.AUTO_CUTOFF:
        cutoff_hz = logs.DEFAULT_CUTOFF_HZ if choice is None else choice["cutoff_hz"]
    derived: dict[str, list] = {}
    for jm, sig, source in zip(mapping.joints, per_joint, derivable):
        motion = {"t": t, **{c: source[c] for c in ("q", "qd", "qdd") if c in source}}
        for column in logs.derive_motion(motion, cutoff_hz).get("columns", []):
            derived.setdefault(column, []).append(jm.name)
            sig[column] = motion[column]
    stack = lambda column: np.column_stack([per_joint[order.index(k)][column] for k in range(len(order))])  # noqa: E731
    inertia = [mapping.joints[order.index(k)].rotor_inertia for k in range(len(order))]
    tau_g, tau_dyn = model.terms(stack("q"), stack("qd"), stack("qdd"), np.array(inertia))
    for sig, k in zip(per_joint, order):
        sig["tau_g"], sig["tau_dyn"] = tau_g[:, k], tau_dyn[:, k]
    payload = mapping.payload
    return {
        "urdf": model.name, "urdf_path": os.path.abspath(model.name), "urdf_sha256": model.sha256,
        "match": mapping.match,
        "joints": {str(jm.name): model.joints[k] for jm, k in zip(mapping.joints, order)},
        "unwrapped": unwrapped,
        "gravity": list(mapping.gravity),
        # where the URDF gives the armature it replaces the mapping's rotor inertia: none is applied (null)
        "rotor_inertia": {str(jm.name): jm.rotor_inertia if np.isnan(model.armature[k]) else None
                          for jm, k in zip(mapping.joints, order)},
        "payload": dataclasses.asdict(payload) if payload is not None else None,
        "held": list(model.held),
        "derived": {"columns": derived, "cutoff_hz": cutoff_hz, "filtered": logs.lowpass_applies(t, cutoff_hz),
                    **({"cutoff_choice": choice} if choice else {})} if derived else {},
    }


CUTOFF_GRID = (2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 70.0, 100.0, 150.0, 200.0, 300.0, 500.0)  # Hz
CHOICE_ROWS = 20_000   # rows the robot model is evaluated on per cut-off, evenly spaced


def choose_cutoff(model, mapping: Mapping, order: list[int], t: np.ndarray, per_joint: list[dict]) -> dict | None:
    """The low-pass cut-off [Hz] for the qd/qdd a log lacks (``logs.derive_motion``) with which the robot
    model explains tau_m best: for each cut-off of ``CUTOFF_GRID`` below the Nyquist frequency and for
    none (the Nyquist frequency itself), the RMS over each joint's rows in motion of tau_m - tau_g left
    by least squares on the joint's linear friction (qd, sign(qd), 1) and its tau_dyn with a gain of its
    own (a CAD inertia off by a factor must not make a lower cut-off look better), on at most
    ``CHOICE_ROWS`` rows; the geometric mean over the joints decides. Too low a cut-off takes
    acceleration the arm has out of tau_dyn, too high a one puts in what differentiation makes of
    encoder steps and of vibration the torque does not carry. None when nothing is derived or no joint
    moves, or when the log is too short for any low-pass to apply (``logs.lowpass_applies``)."""
    from fricli.core import metrics

    if all("qd" in sig and "qdd" in sig for sig in per_joint):
        return None
    if not all("tau_m" in sig for sig in per_joint):
        raise LogError("--cutoff auto chooses the cut-off by how well the robot model explains the joint torque: "
                       "map tau_m (or i_m with its kt) for every joint, or give the cut-off in Hz")
    if not logs.lowpass_applies(t, CUTOFF_GRID[0]):    # too few rows to filter: every cut-off is the same
        return None
    nyquist = 0.5 / float(np.median(np.diff(t)))
    grid = [c for c in CUTOFF_GRID if c < nyquist * (1 - 1e-6)] + [nyquist]
    rows = np.unique(np.linspace(0, len(t) - 1, min(len(t), CHOICE_ROWS)).astype(np.int64))
    joints = [per_joint[order.index(k)] for k in range(len(order))]          # URDF order
    tau = np.column_stack([sig["tau_m"][rows] for sig in joints])
    inertia = np.array([mapping.joints[order.index(k)].rotor_inertia for k in range(len(order))])
    still = metrics.held_still(np.column_stack([sig["q"] for sig in joints]))    # nothing to choose by
    scores = []
    for cutoff in grid:
        motions = [{"t": t, **{c: sig[c] for c in ("q", "qd", "qdd") if c in sig}} for sig in joints]
        for motion in motions:
            logs.derive_motion(motion, cutoff)
        q, qd, qdd = (np.column_stack([m[c][rows] for m in motions]) for c in ("q", "qd", "qdd"))
        tau_g, tau_dyn = model.terms(q, qd, qdd, inertia)
        rms = []
        for k in np.flatnonzero(~still):
            moving = metrics.in_motion(qd[:, k])
            cols = np.column_stack([qd[moving, k], np.sign(qd[moving, k]), np.ones(int(moving.sum())),
                                    tau_dyn[moving, k]])
            left = (tau - tau_g)[moving, k]
            if len(left) > cols.shape[1]:
                rms.append(float(np.sqrt(np.mean(np.square(left - cols @ np.linalg.lstsq(cols, left, rcond=None)[0])))))
        scores.append(float(np.exp(np.mean(np.log(np.maximum(rms, 1e-300))))) if rms else np.inf)
    if not np.isfinite(scores).any():        # no joint in motion: nothing to choose by
        return None
    best = int(np.argmin(scores))
    return {"cutoff_hz": grid[best], "candidates_hz": grid, "score": scores, "rows": int(len(rows)),
            "default_hz": logs.DEFAULT_CUTOFF_HZ}


_ORDER = ("t", "joint", "q", "qd", "qdd", "i_m", "tau_m", "tau_g", "tau_dyn", "tau_ext", "temp")


def import_recording(data: bytes, mapping: Mapping, name: str, *, model=None,
                     cutoff_hz: float | str | None = None, drop_backward: bool = False) -> Imported:
    """Parse ``data`` with ``mapping`` into a long-format table; with ``model`` (a
    ``fricli.robot.dynamics.RobotModel``) add tau_g and tau_dyn."""
    rec = read_recording(data, mapping, name, drop_backward=drop_backward)
    return build_log(rec, mapping, name, hashlib.sha256(data).hexdigest(), model=model, cutoff_hz=cutoff_hz)


def import_files(datas: list[bytes], mapping: Mapping, names: list[str], *, model=None,
                 cutoff_hz: float | str | None = None, drop_backward: bool = False) -> Imported:
    """``import_recording`` of a recording in several files (``mapping.files``, fricli.robot.joined)."""
    from fricli.robot.joined import read_joined

    rec = read_joined(datas, mapping, names, drop_backward=drop_backward)
    digest = hashlib.sha256(b"".join(hashlib.sha256(d).digest() for d in datas)).hexdigest()
    return build_log(rec, mapping, " + ".join(names), digest, model=model, cutoff_hz=cutoff_hz,
                     extra={"files": dict(zip(mapping.files, names)),
                            "files_sha256": [hashlib.sha256(d).hexdigest() for d in datas]})


def dropped_record(defects: dict, unit: str = "line") -> dict:
    """The metadata record of dropped rows: per kind its count, first line (or message), what it is
    and, when known, the [first, last] runs of lines."""
    out = {}
    for kind, d in defects.items():
        out[kind] = {"count": d.count, f"first_{unit}": d.first_line, "what": KINDS[kind]}
        if d.ranges is not None:
            out[kind][f"{unit}s"] = d.ranges
        if d.example:
            out[kind]["example"] = d.example
        if d.files:   # a recording in several files: each file's own, by its line numbers
            out[kind]["files"] = {name: {k: v for k, v in dropped_record({kind: f}, unit)[kind].items() if k != "what"}
                                  for name, f in d.files.items()}
    return out


def build_log(rec: Recording, mapping: Mapping, name: str, source_sha256: str, *, model=None,
              cutoff_hz: float | str | None = None, unit: str = "line", extra: dict | None = None) -> Imported:
    """The long-format table of ``rec`` (read with ``mapping``), its metadata recording the source
    (``extra`` added), the dropped rows (numbered by ``unit``) and, with ``model``, the robot terms."""
    t, per_joint, axis = _signals(mapping, rec, name)
    # a qd or qdd column that cannot be a measurement (zeros a recorder filled in): unknown, not a value
    # (with the robot terms it is derived, and the log holds the derived column; else kept as recorded)
    unmeasured = {str(jm.name): dict(logs.not_measured({"t": t, **sig}, kept=model is None))
                  for jm, sig in zip(mapping.joints, per_joint)}
    unmeasured = {j: found for j, found in unmeasured.items() if found}
    mismatch = {str(jm.name): text for jm, sig in zip(mapping.joints, per_joint)
                if (text := logs.rate_mismatch({"t": t, **sig}, "check the units of the time, q and qd in the mapping"))}
    if model is not None:
        for jm, sig in zip(mapping.joints, per_joint):
            for column in unmeasured.get(str(jm.name), {}):
                del sig[column]
    tr = mapping.transmission
    if model is not None and tr is not None and tr.rotor_inertia.any():   # motor-side inertias, reflected
        for jm, armature in zip(mapping.joints, tr.armature()):
            jm.rotor_inertia = float(armature)
    robot = robot_terms(model, mapping, t, per_joint, axis, cutoff_hz) if model is not None else None
    cross = tr.cross_inertia() if robot is not None and tr is not None else None
    if cross is not None and model.transmission is not None:   # the URDF's own rotor inertias (in tau_dyn) win
        own = [robot["joints"][str(jm.name)] in model.transmission.joints for jm in mapping.joints]
        cross[own, :] = cross[:, own] = 0.0
    if cross is not None and cross.any():
        # the rotors' cross-inertia R^T J_m R off its diagonal: a diagonal armature leaves it out of tau_dyn
        torque = np.column_stack([sig["qdd"] for sig in per_joint]) @ cross.T
        for k, sig in enumerate(per_joint):
            sig["tau_dyn"] = sig["tau_dyn"] + torque[:, k]
        robot["cross_inertia"] = cross.tolist()
    if robot is not None:
        from fricli.robot import sanity

        order = model.match([jm.urdf or str(jm.name) for jm in mapping.joints], mapping.match)
        robot["mapping_check"] = sanity.check(model, mapping, order, per_joint, tr)
    units = dict(logs.CANONICAL[axis])
    units = {"t": "s", "q": units["q"], "qd": units["qd"], "qdd": units["qdd"], "i_m": "A", "temp": "degC",
             **{c: units["tau"] for c in logs.TORQUES}}
    currents = [str(jm.name) for jm, sig in zip(mapping.joints, per_joint) if "i_m" in sig]
    if currents and len(currents) < len(per_joint):     # tau_m holds them: a current is no column of its own
        for sig in per_joint:
            sig.pop("i_m", None)
    present = [c for c in _ORDER if c == "t" or c == "joint" or all(c in sig for sig in per_joint)]
    partial = sorted({c for sig in per_joint for c in sig} - set(present))
    if partial:
        raise LogError(f"{name}: column {partial[0]!r} is mapped for some joints only: map it for every joint")
    n = len(t)
    names = [jm.name for jm in mapping.joints]
    columns = {}
    for c in present:
        if c == "t":
            columns[c] = np.tile(t, len(names))
        elif c == "joint":
            columns[c] = np.repeat(np.array(names, dtype=np.int64 if isinstance(names[0], int) else object), n)
        else:
            columns[c] = np.concatenate([sig[c] for sig in per_joint])
    table = logs.table_from_arrays(columns, {c: units[c] for c in present if c in units})
    meta = {
        "source": name, "source_sha256": source_sha256, **(extra or {}), "rows": n, "counted_in": unit,
        "dropped": dropped_record(rec.defects, unit),
        "unterminated_last_line": int(rec.unterminated) if rec.unterminated else None,
        "kt": {str(jm.name): jm.kt for jm in mapping.joints if jm.kt is not None},
        "i_m_left_out": currents if "i_m" not in present else [],
        "robot": robot, "time_step_s": float(np.median(np.diff(t))) if n > 1 else None,
        "not_measured": unmeasured, "rate_mismatch": mismatch,
    }
    if rec.blank_lines and (mapping.time.ref is None or (mapping.files and mapping.join == "rows")):
        meta["blank_lines"] = rec.blank_lines   # rows counted by data line: these took no row
    schema_meta = {**(table.schema.metadata or {}), META_KEY: json.dumps(meta).encode()}
    if tr is not None and tr.coupled_groups():   # for identify --coupling (a diagonal one is fully applied)
        schema_meta[transmission.META_KEY] = tr.to_json().encode()
    table = table.replace_schema_metadata(schema_meta)
    return Imported(table=table, recording=rec, meta=meta)
