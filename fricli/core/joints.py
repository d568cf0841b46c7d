"""The joint rule: which joints a run covers and which model applies to which joint.

Every command decides through this module (docs/joints.md):

- A log without a ``joint`` column holds one joint of unknown name. ``--joint J`` on it is an
  error: it can neither select nor relabel its rows.
- On a log with a ``joint`` column, ``--joint J`` selects J (an error lists the joints there are);
  without it a fitting command covers every joint of the log.
- A model file records the joint it was fitted on. Applying a model fitted on joint A to rows of
  a known different joint B is refused (``JointMismatch``, exit code 4, naming both). A model
  with no recorded joint, or a log without a joint column, never conflicts.
- A single model file on a log of several joints applies to its own joint (or ``--joint``); a
  model set (a folder, ``fricli.core.modelset``) applies each joint's model to that joint's rows.
- A model may cover a group of joints (joints that share motors, ``fricli.models.coupled``): its
  file records them as ``joints``, and it applies to each of their rows (``covers``).

Joints are compared by their text (``2`` in a model file matches joint ``"2"`` of a log, and
joint ``2.0`` of a joint column written as floats).
"""

from __future__ import annotations

import dataclasses

from fricli.core.errors import LogError, ModelFileError


class JointMismatch(ModelFileError):
    """A model fitted on one joint applied to rows of another (exit code 4, MODEL)."""


def text(joint) -> str:
    """A joint as text: ``2`` for 2, "2" and 2.0 alike (a joint column written as floats)."""
    if isinstance(joint, float) and joint.is_integer():
        return str(int(joint))
    return str(joint)


def same(a, b) -> bool:
    return text(a) == text(b)


def listed(joints) -> str:
    return ", ".join(text(j) for j in joints)


def mismatch(model_name: str, model_joint, log_name: str, log_joint) -> JointMismatch:
    """The one message for the wrong-joint case."""
    return JointMismatch(f"{model_name}: the model was fitted on joint {model_joint}, not on joint {log_joint} "
                         f"of {log_name}; give the model of joint {log_joint} (or a model folder)")


def named(values: list, name: str) -> list | None:
    """The distinct values of a log's ``joint`` column as the log's joints: None when every value
    is missing (a column of nulls names no joint, like no column); some missing is refused. A
    float NaN is missing too (it is no joint, and equals no row's joint)."""
    values = [None if isinstance(v, float) and v != v else v for v in values]
    if values and all(v is None for v in values):
        return None
    if any(v is None for v in values):
        raise LogError(f"{name}: the 'joint' column has missing values: every row needs its joint")
    return values


def select(log_joints: list | None, requested, name: str) -> list:
    """Joints of the log a run covers: ``[None]`` for a log without a joint column, ``[J]`` for
    ``--joint J``, else every joint in the log's order. ``log_joints``: the log's joints, or None
    when it has no joint column."""
    if log_joints is None:
        if requested is not None:
            raise LogError(f"{name}: the log has no 'joint' column, so --joint {requested} can neither select "
                           "nor relabel its rows; leave --joint out")
        return [None]
    if not log_joints:   # a joint column but no rows: refused as empty by the reader
        return [requested]
    if requested is None:
        return list(log_joints)
    match = [j for j in log_joints if same(j, requested)]
    if not match:
        raise LogError(f"{name}: no joint {requested} in the log (it holds {listed(log_joints)})")
    return match[:1]


def several(log_joints: list | None, name: str, hint: str = "choose one with --joint") -> LogError:
    return LogError(f"{name}: the log holds joints {listed(log_joints)}: {hint}")


def covers(meta: dict) -> list:
    """The joints a model file covers: its ``joints`` (a model of a coupled group) or its ``joint``."""
    group = meta.get("joints")
    return list(group) if isinstance(group, list) and group else [meta.get("joint")]


def check(model_joint, log_joint, model_name: str, log_name: str) -> None:
    """Refuse a model fitted on a known joint for rows of a known different joint."""
    if model_joint is not None and log_joint is not None and not same(model_joint, log_joint):
        raise mismatch(model_name, model_joint, log_name, log_joint)


@dataclasses.dataclass
class Source:
    """Where models come from: one file (``paths`` = {its joint or None: path}) or a model set
    folder (``folder`` true, one path per recorded joint; see fricli.core.modelset)."""

    name: str
    paths: dict                    # joint (as recorded; None: no joint) -> model file
    folder: bool = False

    def model_for(self, joint):
        for j, path in self.paths.items():
            if same(j, joint):
                return j, path
        return None


def pair(source: Source, log_joints: list | None, requested, log_name: str,
         joint_option: bool = True) -> list[tuple[object, str]]:
    """(joint of the log, model file) for every joint a run that applies models covers.

    A single model file: on a log of several joints it covers its own joint (or ``--joint``); its
    joint must match. A model set: every covered joint needs its model; on a log without a joint
    column the set must hold exactly one model. ``joint_option``: whether the command takes
    ``--joint`` (the messages advise it only then)."""
    covered = select(log_joints, requested, log_name)
    if not source.folder and len(source.paths) > 1:   # one file of a coupled group: each of its joints
        if covered == [None]:
            raise ModelFileError(f"{source.name}: a model of joints {listed(source.paths)}, but {log_name} has no "
                                 "'joint' column to find their rows by")
        found = [j for j in covered if source.model_for(j)]
        if not found:
            what = f"joint {covered[0]}" if requested is not None or len(covered) == 1 else f"joints {listed(covered)}"
            raise JointMismatch(f"{source.name}: the model was fitted on joints {listed(source.paths)}, not on "
                                f"{what} of {log_name}")
        return [(j, source.model_for(j)[1]) for j in found]
    if not source.folder:
        (model_joint, path), = source.paths.items()
        if log_joints is not None and requested is None and len(log_joints) > 1:
            if model_joint is None:
                raise several(log_joints, log_name, "choose one with --joint, or give a model folder" if joint_option
                              else "give a model folder (one model per joint) or a model fitted on one of them")
            found = [j for j in log_joints if same(j, model_joint)]
            if not found:
                raise JointMismatch(f"{source.name}: the model was fitted on joint {model_joint}, but {log_name} "
                                    f"holds joints {listed(log_joints)}; give the model of each joint "
                                    "(a model folder)")
            covered = found
        check(model_joint, covered[0], source.name, log_name)
        return [(covered[0], path)]
    if covered == [None]:
        if len(source.paths) != 1:
            raise ModelFileError(f"{source.name}: holds models of joints {listed(source.paths)}, but {log_name} "
                                 "has no 'joint' column to match them to; give one model file")
        return [(None, next(iter(source.paths.values())))]
    out = []
    for joint in covered:
        found = source.model_for(joint)
        if found is None:
            held = listed(source.paths)
            hint = (f"--joint {held} applies it alone" if len(source.paths) == 1 else "--joint J chooses one of them") \
                if joint_option else "give a model of every joint, or one joint's model file"
            raise JointMismatch(f"{source.name}: no model for joint {joint} of {log_name} (the folder holds "
                                f"joints {held}; {hint})")
        out.append((joint, found[1]))
    return out
