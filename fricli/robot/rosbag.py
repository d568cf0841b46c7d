"""A ROS bag's sensor_msgs/JointState topic -> the Recording and Mapping a CSV import makes.

Reads rosbag2 (MCAP or sqlite3 storage: the bag's folder) and ROS 1 ``.bag`` files with
``rosbags`` (pure Python, extra ``fricli[ros]``). ``position``, ``velocity`` and ``effort`` of
each joint become ``q``, ``qd`` and ``tau_m`` (or what the mapping says the effort is); messages
are numbered from 1 in the order the bag holds them, and defects are reported by message number
(docs/robot-import.md):

    a joint of the log missing from a message       -> message dropped (reported)
    arrays of another length than the joint names   -> message dropped (reported)
    a non-finite value                              -> message dropped (reported)
    joints in another order than most messages -> reordered by name (reported)
    empty velocity arrays                           -> no qd (derived like a CSV's missing qd)
    then as for a CSV: garbage, duplicate and backward times (``recording.consistent_rows``)
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
from pathlib import Path

import numpy as np

from fricli.core.errors import LogError, MissingDependencyError
from fricli.robot.mapping import Column, JointMap, Mapping, effort_column
from fricli.robot.recording import KINDS, MIN_ROWS, Defect, Recording, consistent_rows, listing, ranges

JOINT_STATE = "sensor_msgs/msg/JointState"
INSTALL = "pip install 'fricli[ros]'"
SUFFIXES = (".bag", ".mcap", ".db3")
MCAP_MAGIC = b"\x89MCAP0\r\n"
FIELDS = {"position": "q", "velocity": "qd", "effort": "effort"}


def is_bag(path: str) -> bool:
    """Whether ``path`` names a ROS bag: a folder, or a .bag, .mcap or .db3 file."""
    return path != "-" and (Path(path).is_dir() or Path(path).suffix in SUFFIXES)


@dataclasses.dataclass
class Bag:
    """What was read: the recording (values keyed by ``"<joint>/<field>"``), its mapping, the
    topic, where ``t`` came from (``header`` stamps or ``receive`` times), the time [ns] that is
    t = 0, and the messages whose joints came in another order than most messages'."""

    recording: Recording
    mapping: Mapping
    topic: str
    stamps: str
    origin_ns: int
    reordered: Defect | None
    sha256: str
    # fields ("velocity", ...) left out because some usable messages had them empty: those messages
    partly_empty: dict[str, Defect] = dataclasses.field(default_factory=dict)
    unread: int = 0     # messages the bag's metadata lists on the topic that could not be read
    # storage files read without a metadata.yaml (a rosbag2 recording that did not end cleanly)
    standalone: list[str] = dataclasses.field(default_factory=list)


def _rosbags():
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise MissingDependencyError(f"reading a ROS bag needs rosbags: {INSTALL}") from None
    return AnyReader, AnyReaderError, get_typestore(Stores.ROS2_HUMBLE)


def bag_paths(path: str) -> list[Path]:
    """What rosbags opens: a ROS 1 file, a rosbag2 folder (a storage file's folder) with its
    metadata.yaml, or without one (a recording that did not end cleanly) its storage files."""
    p = Path(path)
    if not p.exists():
        raise LogError(f"{path}: no such bag")
    folder = p.parent if p.is_file() and p.suffix in (".mcap", ".db3") else p
    if not folder.is_dir() or (folder / "metadata.yaml").exists():
        return [folder]
    if p.is_file():
        return [p]
    files = sorted((f for f in p.iterdir() if f.suffix in (".mcap", ".db3") and f.is_file()), key=_split_index)
    if not files:
        raise LogError(f"{path}: a folder without a rosbag2 metadata.yaml or .mcap/.db3 storage files: not a ROS bag")
    if len({f.suffix for f in files}) > 1:
        raise LogError(f"{path}: a folder without metadata.yaml that holds both .mcap and .db3 files: give one file")
    return files


def _split_index(f: Path) -> tuple:
    """Name order with the split number (``run_10.mcap`` after ``run_9.mcap``) read as a number."""
    stem, _, number = f.stem.rpartition("_")
    return (stem, int(number)) if number.isdigit() else (f.stem, -1)


def _mcap_ends(f: Path) -> bool:
    """Whether an MCAP file ends with the format's magic bytes, as a finished recording does."""
    with open(f, "rb") as fh:
        fh.seek(max(f.stat().st_size - len(MCAP_MAGIC), 0))
        return fh.read() == MCAP_MAGIC


def _sha256(paths: list[Path]) -> str:
    """sha256 of the bag's bytes: its files' (a folder's in name order), in the order read."""
    h = hashlib.sha256()
    for p in paths:
        for f in sorted(x for x in ([p] if p.is_file() else p.rglob("*")) if x.is_file()):
            with open(f, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
    return h.hexdigest()


def _messages(path: str, topic: str | None):
    """(topic, [(receive time [ns], stamp [ns], names, position, velocity, effort)]) of the
    JointState topic ``topic`` (or the bag's only one)."""
    AnyReader, AnyReaderError, default = _rosbags()
    p = bag_paths(path)
    try:
        with AnyReader(p, default_typestore=default) as reader:
            states = sorted({c.topic for c in reader.connections if c.msgtype == JOINT_STATE})
            if topic is None:
                if not states:
                    raise LogError(f"{path}: no {JOINT_STATE} topic in the bag (topics: "
                                   f"{', '.join(sorted(reader.topics)) or 'none'})")
                if len(states) > 1:
                    raise LogError(f"{path}: {len(states)} JointState topics ({', '.join(states)}): choose one "
                                   "with --topic")
                topic = states[0]
            elif topic not in states:
                kind = reader.topics[topic].msgtype if topic in reader.topics else None
                raise LogError(f"{path}: topic {topic} " + (f"is {kind}, not {JOINT_STATE}" if kind else
                               "is not in the bag") + f" (JointState topics: {', '.join(states) or 'none'})")
            connections = [c for c in reader.connections if c.topic == topic]
            listed = sum(int(c.msgcount or 0) for c in connections)
            out = []
            for conn, received, raw in reader.messages(connections=connections):
                msg = reader.deserialize(raw, conn.msgtype)
                stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
                out.append((received, stamp, tuple(msg.name),
                            *(np.asarray(getattr(msg, f), dtype=np.float64) for f in FIELDS)))
    except LogError:
        raise
    except Exception as exc:   # AnyReaderError, OSError, and what a damaged file makes its decoders raise
        files = [g for f in p for g in (sorted(f.glob("*.mcap")) if f.is_dir() else [f])]
        cut = [f.name for f in files if f.suffix == ".mcap" and not _mcap_ends(f)]
        hint = (f"; {', '.join(cut)} is cut short (a recording that did not end cleanly?): the mcap tool "
                "recovers what it holds, `mcap recover FILE -o FIXED.mcap`" if cut else "")
        raise LogError(f"{path}: not a readable ROS bag ({type(exc).__name__}: {exc}){hint}") from None
    return topic, out, p, listed


def read_bag(path: str, mapping: Mapping | None = None, topic: str | None = None, *,
             drop_backward: bool = False, leave_out=()) -> Bag:
    """Read the JointState topic of the bag at ``path``. ``mapping`` (``parse_bag_mapping``) names
    the joints to import and what their effort is; without it the joints that the most messages name
    but those in ``leave_out`` (joints the robot model holds), effort as joint-side torque [Nm].
    LogError (exit 3) when nothing is usable."""
    topic, msgs, p, listed = _messages(path, topic)
    if not msgs:
        raise LogError(f"{path}: topic {topic} holds no messages")
    if mapping is None or not mapping.joints:
        sets = collections.Counter(frozenset(m[2]) for m in msgs)
        common = max(sets, key=sets.get)           # the first of the most frequent
        by_order = collections.Counter(m[2] for m in msgs if frozenset(m[2]) == common)
        names = max(by_order, key=by_order.get)        # the order most messages list them in (the first of those)
        names = tuple(n for n in names if n not in leave_out)
        if not names:
            raise LogError(f"{path}: the messages on {topic} name no joints")
        base = mapping or Mapping(time=None, joints=[])
        mapping = dataclasses.replace(base, joints=[JointMap(name=n, columns=effort_column("tau_m")) for n in names])
    # JointState names are the robot description's joint names
    mapping = dataclasses.replace(mapping, match=mapping.match or "name")
    names = [jm.name for jm in mapping.joints]
    n = len(msgs)
    values = {f: np.full((n, len(names)), np.nan) for f in FIELDS}
    empty = {f: np.zeros(n, dtype=bool) for f in FIELDS}
    kinds = np.full(n, "", dtype=object)
    ranks = np.full(n, -1)               # which order the joints come in, per message
    orders: dict[tuple, tuple] = {}      # names of a message -> (indices of the log's joints, rank)
    keys: dict[tuple | None, int] = {}   # order of the log's joints in a message -> rank
    examples: dict[str, str] = {}        # what is wrong with the first message of each kind
    for k, (_, _, msg_names, *arrays) in enumerate(msgs):
        if msg_names not in orders:
            where = {m: i for i, m in enumerate(msg_names)}
            index = np.array([where[m] for m in names]) if all(m in where for m in names) else None
            key = tuple(np.argsort(index)) if index is not None else None
            orders[msg_names] = (index, keys.setdefault(key, len(keys)))
        index, rank = orders[msg_names]
        if index is None or len(set(msg_names)) != len(msg_names):
            kinds[k] = "missing_joints"
            if "missing_joints" not in examples:
                absent = [m for m in names if m not in msg_names]
                examples["missing_joints"] = (f"no {absent[0]!r} among {', '.join(msg_names[:8]) or 'no names'}"
                                              if absent else "a joint named twice")
            continue
        if any(len(a) not in (0, len(msg_names)) for a in arrays):
            kinds[k] = "malformed"
            continue
        ranks[k] = rank
        for f, a in zip(FIELDS, arrays):
            if len(a):
                values[f][k] = a[index]
            else:
                empty[f][k] = True
    numbers = np.arange(1, n + 1)
    ok = kinds == ""
    if not ok.any():
        raise LogError(f"{path}: no usable message on {topic} ({listing(_dropped(kinds, numbers, examples), 'message')})")
    present = {f: not empty[f][ok].any() for f in FIELDS}     # a field empty in any message is not used
    if not present["position"] and not present["velocity"]:
        raise LogError(f"{path}: the messages on {topic} hold neither positions nor velocities")
    if not present["effort"]:
        raise LogError(f"{path}: the messages on {topic} hold no efforts: a log needs a motor torque or current")
    used = [f for f in FIELDS if present[f]]
    partly = {f: np.flatnonzero(ok & empty[f]) for f in FIELDS if not present[f] and not empty[f][ok].all()}
    partly = {f: Defect(len(at), int(at[0]) + 1, ranges(at + 1)) for f, at in partly.items()}   # message numbers
    finite = np.all([np.isfinite(values[f]).all(axis=1) for f in used], axis=0)
    kinds[ok & ~finite] = "non_numeric"
    if (ok & ~finite).any():
        k = int(np.flatnonzero(ok & ~finite)[0])
        f = next(f for f in used if not np.isfinite(values[f][k]).all())
        j = int(np.flatnonzero(~np.isfinite(values[f][k]))[0])
        examples["non_numeric"] = f"{f} of {names[j]} is {values[f][k, j]}"
    keep = kinds == ""
    if not keep.any():
        hint = "; a joint that never has a value can be left out: a mapping lists the joints to import" \
            if "non_numeric" in examples and len(names) > 1 else ""
        raise LogError(f"{path}: no usable message on {topic} ({listing(_dropped(kinds, numbers, examples), 'message')})"
                       f"{hint}")
    stamps = np.array([m[1] for m in msgs], dtype=np.int64)
    source = "receive" if np.unique(stamps[keep]).size == 1 else "header"   # unset, or set once
    t_ns = stamps if source == "header" else np.array([m[0] for m in msgs], dtype=np.int64)

    cols: dict[str, np.ndarray] = {}
    joints, signals = [], []
    for j, jm in enumerate(mapping.joints):
        columns = {}
        for f in used:
            ref = f"{jm.name}/{f}"
            cols[ref] = values[f][:, j]
            if f == "effort":
                (signal, c), = jm.columns.items()
                columns[signal] = dataclasses.replace(c, ref=ref)
            else:
                columns[FIELDS[f]] = Column(ref=ref, unit="rad" if f == "position" else "rad/s", factor=1.0,
                                            kind="rotary")
        signals += [cols[c.ref] * c.factor for c in columns.values()]
        joints.append(dataclasses.replace(jm, columns=columns))
    mapping = dataclasses.replace(mapping, time=Column(ref="t", unit="s", factor=1.0, kind=None), joints=joints)

    idx = np.flatnonzero(keep)
    mid = int(np.median(t_ns[idx]))        # differences of integer ns keep the stamps' resolution
    good, found = consistent_rows((t_ns[idx] - mid) / 1e9, [s[idx] for s in signals], numbers[idx], name=path,
                                  drop_backward=drop_backward, unit="message",
                                  shown_from=(int(t_ns[idx[0]]) - mid) / 1e9)   # t from the first message
    keep[idx[~good]] = False
    if keep.sum() < MIN_ROWS:
        count = int(keep.sum())
        usable = f"only {count} usable message{'s' if count > 1 else ''}" if count else "no usable messages"
        raise LogError(f"{path}: {usable} on {topic}" + (f" ({listing(found, 'message')})" if found else ""))
    origin = int(t_ns[keep][0])
    cols["t"] = (t_ns - origin) / 1e9
    dropped = _dropped(kinds, numbers, examples)
    defects = {kind: dropped.get(kind, found.get(kind)) for kind in KINDS if kind in dropped or kind in found}
    rec = Recording(values={ref: v[keep] for ref, v in cols.items()}, lines=numbers[keep], defects=defects,
                    n_fields=0)
    turned = keep & (ranks != np.bincount(ranks[keep]).argmax())     # another order than most messages
    moved = Defect(int(turned.sum()), int(numbers[turned][0]), ranges(numbers[turned])) if turned.any() else None
    return Bag(recording=rec, mapping=mapping, topic=topic, stamps=source, origin_ns=origin, reordered=moved,
               sha256=_sha256(p), partly_empty=partly, unread=max(listed - n, 0),
               standalone=[f.name for f in p if f.is_file() and f.suffix in (".mcap", ".db3")])


def _dropped(kinds: np.ndarray, numbers: np.ndarray, examples: dict) -> dict[str, Defect]:
    """The messages dropped, by kind (``kinds`` (n,): the kind of each message, "" when kept)."""
    out = {}
    for kind in KINDS:
        at = np.flatnonzero(kinds == kind)
        if len(at):
            out[kind] = Defect(len(at), int(numbers[at[0]]), ranges(numbers[at]), example=examples.get(kind))
    return out
