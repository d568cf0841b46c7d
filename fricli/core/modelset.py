"""A model set: a folder of model files, one per joint, as whole-arm commands write and read it.

    DIR/joint_<name>.npz     the model of joint <name> (characters other than letters, digits,
                             ``.``, ``_`` and ``-`` written as ``_``)

The joint a file belongs to is the ``joint`` recorded in its meta, not its name. Other files in
the folder are ignored. Each file is written atomically on its own, so a joint that fails leaves
the other joints' files valid (docs/joints.md).
"""

from __future__ import annotations

import os
import re
from typing import Callable

from fricli.core import modelfile
from fricli.core.errors import FricliError, LogError, ModelFileError, OutputError
from fricli.core.joints import Source, covers, listed, pair, same, select, several, text


def file_name(joint) -> str:
    return "joint_" + re.sub(r"[^A-Za-z0-9._-]", "_", text(joint)) + ".npz"


def path_for(folder: str, joint) -> str:
    return os.path.join(folder, file_name(joint))


def group_file_name(joints) -> str:
    """The file of a model that covers several joints (a coupled group): joints_<a>_<b>.npz."""
    return "joints_" + "_".join(re.sub(r"[^A-Za-z0-9.-]", "_", text(j)) for j in joints) + ".npz"


def listing(folder: str) -> dict:
    """{recorded joint: path} of the model files in ``folder``, in name order."""
    try:
        names = sorted(n for n in os.listdir(folder) if n.endswith(".npz") and not n.startswith("."))
    except OSError as exc:
        raise ModelFileError(f"{folder}: cannot read the folder ({exc.strerror})") from None
    out: dict = {}
    for name in names:
        path = os.path.join(folder, name)
        meta, _ = modelfile.read(path)
        for joint in covers(meta):
            if joint is None:
                raise ModelFileError(f"{path}: records no joint; a model folder holds one model per named joint")
            other = next((out[j] for j in out if same(joint, j)), None)
            if other is not None:
                raise ModelFileError(f"{folder}: two models of joint {joint} ({os.path.basename(other)} and {name}): "
                                     "move one out of the folder")
            out[joint] = path
    if not out:
        raise ModelFileError(f"{folder}: no model files (.npz) in the folder")
    return out


def source(path: str) -> Source:
    """A model file or a model set folder as a ``joints.Source``."""
    if os.path.isdir(path):
        return Source(path, listing(path), folder=True)
    meta, _ = modelfile.read(path)
    return Source(path, {j: path for j in covers(meta)})


def paired(source: Source, table, log_name: str, requested=None) -> dict:
    """{joint: model file} of a run that applies ``source``'s models to the joints of the log
    ``table`` (``--joint`` ``requested``): the joint rule's pairing (``joints.pair``)."""
    from fricli.core import logs

    return dict(pair(source, logs.joints_of(table, log_name), requested, log_name))


def output_folder(output: str, covered: list, log_joints: list | None, log_name: str) -> str | None:
    """The folder to write one model per joint into, or None for one model file at ``output``.

    A folder when the run covers several joints, or ``output`` is an existing folder or ends
    with "/". The folder is made when missing (its parent must exist)."""
    names = [file_name(j) for j in covered]
    if len(set(names)) < len(names):
        raise LogError(f"{log_name}: joints {listed(covered)} do not give distinct file names")
    if os.path.isdir(output) or output.endswith(os.sep):
        if covered == [None]:
            raise OutputError(f"{output} names a folder, but {log_name} has no 'joint' column to name a model "
                              "file by: give -o FILE.npz")
        if os.path.isdir(output):
            return output
    elif len(covered) <= 1:
        return None
    elif output == "-" or output.endswith(".npz") or os.path.exists(output):
        raise several(log_joints, log_name, "choose one with --joint, or give -o a folder for one model per joint")
    parent = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(parent):
        raise OutputError(f"cannot write {output}: folder {parent} does not exist")
    try:
        os.makedirs(output, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {output}: {exc.strerror}") from None
    return output


def plan(log_joints: list | None, requested, output: str, log_name: str,
         source: Source | None = None) -> tuple[dict, str | None]:
    """({joint: input model file or None}, output folder or None) of a run that writes models:
    the joints by the joint rule (paired with ``source``'s models when it starts from models),
    and where their models go (``output_folder``)."""
    if source is None:
        pairs = {j: None for j in select(log_joints, requested, log_name)}
    else:
        pairs = dict(pair(source, log_joints, requested, log_name))
    return pairs, output_folder(output, list(pairs), log_joints, log_name)


class PartialFailure(FricliError):
    """Some joints of a whole-arm run failed; the others' outputs are written. The exit code is
    the first failure's."""


def each_joint(covered: list, work: Callable[[object], None], what: str = "models") -> list:
    """Run ``work(joint)`` for every joint; a joint's FricliError does not stop the others.
    Returns the joints done; raises ``PartialFailure`` naming the failed joints after the rest,
    those that failed for the same reason together."""
    done, failed = [], []
    for joint in covered:
        try:
            work(joint)
            done.append(joint)
        except FricliError as exc:
            if len(covered) == 1:
                raise
            failed.append((joint, exc))
    if failed:
        first = failed[0][1]
        reasons: dict[str, list] = {}     # joints failing for the same reason are named together
        for joint, exc in failed:
            reasons.setdefault(str(exc), []).append(joint)
        err = PartialFailure("; ".join(f"joint{'s' if len(js) > 1 else ''} {listed(js)}: {reason}"
                                       for reason, js in reasons.items())
                             + (f" ({what} of joints {listed(done)} written)" if done else ""))
        err.exit_code = first.exit_code
        raise err
    return done
