"""The fleet manifest (TOML): robots, their logs, joints, the pipeline per joint and its options.

    [fleet]
    history = "history"          # Parquet dataset the runs append to (relative to the manifest)
    models = "models"            # models/ROBOT/jointJ/STEM.npz
    pipeline = "identify"        # identify | train-base | adapt (default for every robot)
    diagnose = false             # also record the effects each new model misses (slow)

    [defaults]                   # any robot key, for every robot
    logs = "{robot}/joint{joint}/*.parquet"
    joints = [1, 2, 3, 4, 5, 6]

    [options.identify]           # options of each pipeline, as the command's long options
    hold = 0.2                   # (fricli.fitting.optionspec; checked when the manifest is read)

    [[robot]]
    name = "robot001"
    pipeline = "adapt"                              # overrides [fleet] pipeline
    base = "bases/{robot}/joint{joint}.npz"         # adapt: the model to adapt

Paths are relative to the manifest's folder; ``{robot}`` and ``{joint}`` are replaced; ``logs``
is a glob (or a list of globs). Every (robot, joint, log file) is one job.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import glob
import os
import re
import tomllib

from fricli.fitting import optionspec
from fricli.core.errors import FricliError, NOTHING_RAN

PIPELINES = ("identify", "train-base", "adapt")
_TABLES = {"fleet", "defaults", "options", "robot"}
_FLEET_KEYS = {"history", "models", "pipeline", "diagnose"}
_ROBOT_KEYS = {"name", "logs", "joints", "pipeline", "base", "options", "diagnose"}
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
_DATE = re.compile(r"(\d{4})-(\d{2})-(\d{2})")


class ManifestError(FricliError):
    """A manifest that cannot be read or is incomplete: nothing can run."""

    exit_code = NOTHING_RAN


@dataclasses.dataclass(frozen=True)
class Job:
    """One (robot, joint, log) job. Paths are absolute."""

    robot: str
    joint: str
    log: str
    date: str              # ISO date of the data (from the log's path, else its modification day)
    pipeline: str
    model: str             # output model file
    options: tuple         # sorted (name, value) pairs of the pipeline's options
    base: str | None = None
    diagnose: bool = False  # also look for effects the new model misses (fricli diagnose)
    clash: str = ""         # the other logs of this robot joint whose model is this job's file: it fails

    @property
    def key(self) -> str:
        return f"{self.robot}/{self.joint}/{os.path.basename(self.log)}"


@dataclasses.dataclass(frozen=True)
class Manifest:
    path: str
    history: str
    jobs: tuple[Job, ...]
    unmatched: tuple[str, ...] = ()   # "robot R joint J: no log matches GLOB", one per robot joint without logs


def data_date(path: str) -> str:
    """The day a log's data is from: the last YYYY-MM-DD in its path, else its modification day (UTC)."""
    found = _DATE.findall(path)
    for y, m, d in reversed(found):
        try:
            return dt.date(int(y), int(m), int(d)).isoformat()
        except ValueError:
            continue
    return dt.datetime.fromtimestamp(os.path.getmtime(path), dt.timezone.utc).date().isoformat()


def _fill(template: str, robot: str, joint) -> str:
    return template.replace("{robot}", robot).replace("{joint}", str(joint))


def _check_options(where: str, options) -> dict:
    if not isinstance(options, dict):
        raise ManifestError(f"{where}: options must be a table")
    for name, value in options.items():
        if isinstance(value, dict):
            raise ManifestError(f"{where}: option {name} must be a value, not a table")
    return {k.replace("-", "_"): v for k, v in options.items()}


def inside(path: str, root: str) -> bool:
    """Whether ``path`` (symbolic links resolved) is ``root`` or lies under it."""
    real, top = os.path.realpath(path), os.path.realpath(root)
    return real == top or real.startswith(top.rstrip(os.sep) + os.sep)


def _confine(manifest: str, root: str, what: str, path: str) -> None:
    if not inside(path, root):
        raise ManifestError(f"{manifest}: {what} {path} is outside the manifest's folder {root}; a manifest reads "
                            "and writes only under its folder unless it is trusted (--allow-outside)")


def load(path: str, *, allow_outside: bool = False) -> Manifest:
    """Read a manifest and list its jobs; ManifestError when it cannot be used.

    A manifest is confined to its folder: the history, the models, the bases and every log its
    globs match must lie under the folder that holds it (symbolic links resolved), so a manifest
    from elsewhere can neither read other files into models and the history nor write outside
    its folder. ``allow_outside`` lifts that for a manifest the user trusts."""
    from fricli.core import files

    data = files.read_bytes(path, ManifestError, "manifest", "manifest")
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ManifestError(f"{path}: not valid TOML ({exc})") from None
    root = os.path.dirname(os.path.abspath(path))
    _known(path, "table", set(raw), _TABLES, "[fleet], [defaults], [options.PIPELINE], [[robot]]")
    fleet = raw.get("fleet", {})
    defaults = raw.get("defaults", {})
    all_options = raw.get("options", {})
    robots = raw.get("robot", [])
    if not isinstance(fleet, dict) or not isinstance(defaults, dict) or not isinstance(all_options, dict):
        raise ManifestError(f"{path}: [fleet], [defaults] and [options] must be tables")
    if not isinstance(robots, list) or not robots:
        raise ManifestError(f"{path}: no [[robot]] entries")
    _known(f"{path}: [fleet]", "key", set(fleet), _FLEET_KEYS, ", ".join(sorted(_FLEET_KEYS)))
    _known(f"{path}: [options]", "pipeline", set(all_options), set(PIPELINES), ", ".join(PIPELINES))
    history = os.path.join(root, str(fleet.get("history", "history")))
    models_dir = os.path.join(root, str(fleet.get("models", "models")))
    confine = (lambda what, p: None) if allow_outside else (lambda what, p: _confine(path, root, what, p))
    confine("the history", history)
    confine("the models folder", models_dir)
    jobs, seen, unmatched = [], set(), []
    for index, entry in enumerate(robots):
        if not isinstance(entry, dict):
            raise ManifestError(f"{path}: robot {index + 1} is not a table")
        robot = {**defaults, **entry}
        unknown = set(robot) - _ROBOT_KEYS
        name = robot.get("name")
        where = f"{path}: robot {name or index + 1}"
        if unknown:
            raise ManifestError(f"{where}: unknown key {sorted(unknown)[0]!r} (use {', '.join(sorted(_ROBOT_KEYS))})")
        if not _plain_name(name):
            raise ManifestError(f"{where}: name must be letters, digits, '.', '_' or '-', not dots alone")
        if name in seen:
            raise ManifestError(f"{where}: the name is used twice")
        seen.add(name)
        pipeline = robot.get("pipeline", fleet.get("pipeline", "identify"))
        if pipeline not in PIPELINES:
            raise ManifestError(f"{where}: unknown pipeline {pipeline!r} (choose from {', '.join(PIPELINES)})")
        if pipeline == "adapt" and not isinstance(robot.get("base"), str):
            raise ManifestError(f"{where}: the adapt pipeline needs base = \"MODEL.npz\"")
        joint_list = robot.get("joints", [None])   # no joints: the log's single joint
        if not isinstance(joint_list, list) or not joint_list:
            raise ManifestError(f"{where}: joints must be a non-empty list")
        odd = [j for j in (joint_list if "joints" in robot else []) if not (
            isinstance(j, int) and not isinstance(j, bool)
            or isinstance(j, str) and j.strip(".") and not set(j) & {"/", "\\", "\0"})]
        if odd:
            raise ManifestError(f"{where}: joint {odd[0]!r}: a joint is a whole number or a name without '/' or "
                                "'\\', not dots alone")
        listed = [str(j) for j in joint_list]
        twice = sorted({j for j in listed if listed.count(j) > 1})
        if twice:
            raise ManifestError(f"{where}: joint {twice[0]} is listed twice in joints")
        patterns = robot.get("logs")
        patterns = [patterns] if isinstance(patterns, str) else patterns
        if not isinstance(patterns, list) or not patterns or not all(isinstance(p, str) for p in patterns):
            raise ManifestError(f"{where}: logs must be a glob or a list of globs")
        diagnose = robot.get("diagnose", fleet.get("diagnose", False))
        if not isinstance(diagnose, bool):
            raise ManifestError(f"{where}: diagnose must be true or false")
        options = _check_options(where, all_options.get(pipeline, {}))
        options.update(_check_options(where, robot.get("options", {})))
        if "joint" in options:
            raise ManifestError(f"{where}: option 'joint' is set by joints = [...], not by the options")
        whole = sorted(set(options) & optionspec.WHOLE_LOG & set(optionspec.options_of(pipeline)))
        if whole:
            raise ManifestError(f"{where}: option {whole[0]!r} fits several joints into one model; a fleet job "
                                f"fits one joint (use fricli {pipeline} --coupling)")
        try:
            checked = optionspec.check(pipeline, options)
        except optionspec.OptionError as exc:
            raise ManifestError(f"{where}: {exc}") from None
        options = {k: checked[k] for k in options}   # as the command passes them (50 -> 50.0)
        for joint in joint_list:
            jname = "" if joint is None else str(joint)
            files = sorted({os.path.abspath(f) for p in patterns
                            for f in glob.glob(os.path.join(root, _fill(p, name, jname)))})
            if not files:
                unmatched.append(f"robot {name}{f' joint {jname}' if jname else ''}: no log matches "
                                 + " or ".join(_fill(p, name, jname) for p in patterns))
            first = len(jobs)
            for log in files:
                confine(f"robot {name}'s log", log)
                stem = os.path.splitext(os.path.basename(log))[0]
                model = os.path.join(models_dir, name, f"joint{jname}" if jname else "joint", f"{stem}.npz")
                base = robot.get("base")
                if base:
                    confine(f"robot {name}'s base", os.path.join(root, _fill(base, name, jname)))
                jobs.append(Job(robot=name, joint=jname, log=log, date=data_date(log), pipeline=pipeline,
                                model=model, options=tuple(sorted(options.items())),
                                base=os.path.join(root, _fill(base, name, jname)) if base else None,
                                diagnose=diagnose))
            jobs[first:] = _clashes(jobs[first:])
    written = {os.path.realpath(job.model) for job in jobs}
    drifting = next((job for job in jobs if job.base and os.path.realpath(job.base) in written), None)
    if drifting is not None:   # a base a job writes: each night's models adapted from the last night's
        raise ManifestError(f"{path}: robot {drifting.robot}: the base {drifting.base} is a model a job of this "
                            "manifest writes: give adapt a base outside the models folder")
    return Manifest(path=os.path.abspath(path), history=history, jobs=tuple(jobs), unmatched=tuple(unmatched))


def _plain_name(name) -> bool:
    """Whether ``name`` may name a folder or file of the fleet's output: text of letters, digits,
    '.', '_' and '-' that is not '.' or '..' (which would lead out of the folder)."""
    return isinstance(name, str) and bool(_NAME.match(name)) and bool(name.strip("."))


def _clashes(jobs: list[Job]) -> list[Job]:
    """``jobs`` (one robot joint's) with ``clash`` set where logs of one file name (in two folders the
    globs match, or ``a.parquet`` and ``a.pq``) would write one model file: run, each would overwrite
    the other's model every night and neither would be up to date."""
    by_model: dict = {}
    for job in jobs:
        by_model.setdefault(job.model, []).append(job.log)
    return [dataclasses.replace(job, clash=", ".join(log for log in by_model[job.model] if log != job.log))
            if len(by_model[job.model]) > 1 else job for job in jobs]


def _known(where: str, what: str, found: set, allowed: set, listed: str) -> None:
    """ManifestError naming the first of ``found`` not in ``allowed`` (a misspelt key would be ignored)."""
    unknown = sorted(found - allowed)
    if unknown:
        raise ManifestError(f"{where}: unknown {what} {unknown[0]!r} (use {listed})")
