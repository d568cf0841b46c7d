"""What a log's models miss, joint by joint, and the robot model checked once for the whole arm
(``fricli diagnose``): ``diagnose_arm``.

Each joint of the log is diagnosed with its own model (``fricli.fitting.diagnosis.driver``);
with ``output`` each fixed model is written through the one planner (``fricli.fitting.plan.fit_log``:
its lock, its job record, ``if_changed``). On a whole-arm log imported with a URDF, gravity or
acceleration errors on several joints are the robot model's: the run reports them once, with
what a calibration changes. With ``calibrate`` it closes the loop (``diagnose --fix
--calibrate``): the robot model is calibrated on the log (``fricli.robot.calibration.recalibrate``),
written as a URDF with its report, tau_g and tau_dyn are recomputed from it, and each joint's
model is refitted on the recomputed log, diagnosed and fixed there.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Callable

from fricli.core import jobs, logs, modelset, timewindow
from fricli.core.errors import FricliError, ModelFileError, OutputError
from fricli.fitting import optionspec
from fricli.fitting.optionspec import OptionError

WINDOW = ("time_from", "time_until")


@dataclasses.dataclass
class JointDiagnosis:
    """One joint of a run: ``model`` its input model file; ``diagnosis`` what was found
    (``fricli.fitting.diagnosis.driver.Diagnosis``; None when ``output`` was up to date);
    ``data`` the joint's log as diagnosed (``logs.Log``); with a fix, ``output`` the fixed
    model's file, ``made`` what was written there (``fricli.fitting.runs.Made``; None: up to
    date, untouched) and ``digest`` the log's sha256; ``refitted``: the input model was refitted
    on the log recomputed with the calibrated robot model; ``several``: one of several joints of
    the run, each with its own model."""

    joint: object
    model: str
    diagnosis: object = None
    data: logs.Log | None = None
    output: str | None = None
    made: object = None
    digest: str | None = None
    refitted: bool = False
    several: bool = False

    @property
    def unchanged(self) -> bool:
        return self.output is not None and self.made is None


@dataclasses.dataclass
class ArmDiagnosis:
    """What ``diagnose_arm`` found and wrote: ``joints`` {joint: JointDiagnosis} in the order
    done; ``several``: several joints, each with its own model; ``folder``: the results are
    those of a model folder's run (keyed by joint in ``to_json``); ``robot_model``: the
    robot-model check of a whole-arm log, or what ``calibrate`` changed (None: no check);
    ``calibrated_urdf``: the URDF written by ``calibrate``; ``notices``: (warning | note, line)
    in order; ``unchanged``: every output was up to date (``if_changed``) and nothing was done."""

    joints: dict
    several: bool
    folder: bool
    robot_model: dict | None = None
    calibrated_urdf: str | None = None
    notices: list = dataclasses.field(default_factory=list)
    unchanged: bool = False

    @property
    def results(self) -> dict:
        """{joint: the diagnosis as JSON (``Diagnosis.to_json``)} of the joints diagnosed."""
        return {j: r.diagnosis.to_json() for j, r in self.joints.items() if r.diagnosis is not None}

    def to_json(self) -> dict | None:
        """What ``fricli diagnose --json`` prints: the one joint's result, or {"joints": {joint:
        result}} (with "robot_model" when there is one); None when nothing was diagnosed."""
        results = self.results
        if not results:
            return None
        if self.folder:
            out = {"joints": {str(j): r for j, r in results.items()}}
            if self.robot_model is not None:
                out["robot_model"] = self.robot_model
            return out
        return next(iter(results.values()))


def diagnose_arm(models, log, output=None, *, calibrate=None, urdf=None, friction=None, if_changed: bool = False,
                 say: Callable[[str], None] | None = None, warn: Callable[[str], None] | None = None,
                 done: Callable[[JointDiagnosis], None] | None = None, **options) -> ArmDiagnosis:
    """``fricli diagnose MODELS LOG [--fix -o OUTPUT] [--calibrate CAL.urdf]`` (see the module's docstring).

    ``models``: a model file or a model folder (one model per joint); ``log``: a log file (- for
    stdin); ``output``: where the fixed models go (a .npz file, or a folder for one per joint;
    None: diagnose only); ``calibrate``: the calibrated URDF to write (needs ``output``, a
    whole-arm log and a model folder); ``urdf``: the URDF the log's tau_g and tau_dyn came from
    (default: the one its import recorded); ``friction``: the friction fitted with the robot
    model, linear or stribeck (None: ``calibration.LOOP_FRICTION``, recorded as not given);
    ``if_changed``: leave the outputs made from the same log bytes by the same job untouched
    (with ``calibrate``: before calibrating); ``options``: ``fricli.Diagnosis``'s (folds, min_gain,
    alpha, effects, max_effects, no_carry, accept_implausible) and ``fricli.read_log``'s (joint,
    kt, cutoff, drop_invalid, no_gravity, no_dynamics, time_from, time_until).

    ``say(line)``: progress; ``warn(line)``: warnings (both also in ``notices``); ``done(joint)``:
    each ``JointDiagnosis`` as it ends. OptionError naming the option for options that do not go
    together; LockedError when another job holds an output."""
    from fricli.fitting import plan

    notices: list = []
    tell = _Teller(notices, say, warn)
    opts, reading, window = _options(options, output, calibrate, urdf, friction, if_changed)
    log, models = os.fspath(log), os.fspath(models)
    if output is not None:
        output = os.fspath(output)
        folder = os.path.dirname(os.path.abspath(output))
        if not os.path.isdir(folder):
            raise OutputError(f"cannot write {output}: folder {folder} does not exist")
    source = modelset.source(models)
    table, digest = plan.read_log(log, window, tell.warn)
    name = plan.log_name(log)
    pairs = modelset.paired(source, table, name, opts["joint"])
    several = len(pairs) > 1
    joints: dict = {}
    result = ArmDiagnosis(joints, several, several, notices=notices)

    def finished(item: JointDiagnosis) -> None:
        item.several = several
        joints[item.joint] = item
        if done is not None:
            done(item)

    def made(outcome, refitted: bool = False) -> None:
        m = outcome.made    # None: up to date, untouched
        finished(JointDiagnosis(outcome.label, m.base if m else outcome.base, m.diagnosis if m else None,
                                m.data if m else None, outcome.output, m, outcome.digest, refitted and m is not None))

    if calibrate is not None:
        if not several:
            raise OptionError("calibrate needs a whole-arm log and a model folder (one model per joint)", "calibrate")
        shared = [j for j, path in pairs.items() if list(pairs.values()).count(path) > 1]
        if shared:
            raise ModelFileError(f"{models}: --calibrate refits each joint's model on the recomputed log, but joints "
                                 f"{', '.join(map(str, shared))} share the model of their coupled group, which it does "
                                 "not refit: leave --calibrate out, or give models of one joint each")
        opts = _calibrate_options(opts, table, urdf)
        if if_changed:
            fresh = plan.up_to_date("diagnose", log, output, opts, read=(table, digest), inputs=source, window=window)
            if fresh is not None:
                for outcome in fresh.outcomes:
                    made(outcome)
                result.unchanged = True
                return result
        before = _diagnose_all(pairs, table, name, digest, reading, opts, tell)
        cal, table = _calibrate(table, name, urdf, os.fspath(calibrate), opts["cutoff"], tell, friction)
        run = plan.fit_log("diagnose", log, output, opts, inputs=source, read=(table, digest), window=window,
                           if_changed=if_changed, refit=True, warn=tell.warn, done=lambda o: made(o, True))
        result.folder, result.calibrated_urdf = run.folder is not None, os.fspath(calibrate)
        result.unchanged = run.unchanged
        if not run.unchanged:
            result.robot_model = _calibrated_record(before, result.results, cal, os.fspath(calibrate))
        return result
    if output is not None:
        run = plan.fit_log("diagnose", log, output, opts, inputs=source, read=(table, digest), window=window,
                           if_changed=if_changed, warn=tell.warn, done=made)
        result.folder, result.unchanged = run.folder is not None, run.unchanged
        if run.unchanged:
            return result
    else:
        _diagnose_all(pairs, table, name, digest, reading, opts, tell, finished)
    if several:
        result.robot_model = _robot_model_check(result.results, table, name, log, urdf, opts["cutoff"], tell)
    return result


class _Teller:
    """``say`` and ``warn`` as given, each line kept in ``notices`` as (note | warning, line)."""

    def __init__(self, notices: list, say, warn):
        self.notices, self._say, self._warn = notices, say, warn

    def say(self, line: str) -> None:
        self.notices.append(("note", line))
        if self._say is not None:
            self._say(line)

    def warn(self, line: str) -> None:
        self.notices.append(("warning", line))
        if self._warn is not None:
            self._warn(line)


def _bound(option: str, value):
    if value is None or isinstance(value, timewindow.Bound):
        return value
    try:
        return timewindow.Bound.parse(str(value))
    except ValueError as exc:
        raise OptionError(f"diagnose_arm option {option}: {exc}", option) from None


def _options(options: dict, output, calibrate, urdf, friction, if_changed: bool) -> tuple[dict, dict, object]:
    """(the options diagnose records, the reading of each joint's log, the time window), checked."""
    from fricli.estimators.base import READING
    from fricli.estimators.jobs import diagnose_spec, diagnose_options

    if calibrate is not None and output is None:
        raise OptionError("calibrate applies to a fix (it recomputes the log before fixing the friction): give output",
                          "calibrate")
    if friction is not None and calibrate is None:
        raise OptionError("friction applies to calibrate", "friction")
    if friction not in (None, "linear", "stribeck"):
        raise OptionError(f"diagnose_arm option friction = {friction!r}: expected linear or stribeck", "friction")
    if output is not None and os.fspath(output) == "-":
        raise OptionError("output: a fix writes model files: give a .npz file or a folder, not -", "output")
    if if_changed and output is None:
        raise OptionError("if_changed applies to a fix (the models it writes): give output", "if_changed")
    given = {k.replace("-", "_"): v for k, v in options.items()}
    window = timewindow.Window(*(_bound(k, given.pop(k, None)) for k in WINDOW))
    spec = diagnose_spec()
    known = {**spec, **READING, **{k: None for k in WINDOW}}
    unknown = [k for k in given if k not in known]
    if unknown:
        raise OptionError(f"unknown diagnose_arm option {unknown[0]!r} (known: {', '.join(sorted(known))})", unknown[0])
    diag = optionspec.check_values({k: v for k, v in given.items() if k in spec}, spec, "diagnose_arm")
    read = optionspec.check_values({k: v for k, v in given.items() if k in READING}, READING, "diagnose_arm")
    opts = diagnose_options(diag, read, urdf=None if urdf is None else os.fspath(urdf),
                            calibrated=None if calibrate is None else os.fspath(calibrate), calibrate_friction=friction)
    r = {n: o.default for n, o in READING.items()} | read
    zero = tuple(column for flag, column in optionspec.ZERO_FLAGS.items() if r[flag])
    reading = {"kt": r["kt"], "cutoff_hz": r["cutoff"], "drop_invalid": r["drop_invalid"], "zero": zero}
    return opts, reading, window


def _diagnose_all(pairs: dict, table, name: str, digest: str, reading: dict, opts: dict, tell: _Teller,
                  done: Callable | None = None) -> dict:
    """{joint: Diagnosis.to_json()} of every joint of ``table`` with its model; ``done``: told of
    each joint (and the robot-model notes warned) when given."""
    from fricli import models
    from fricli.fitting.diagnosis import driver
    from fricli.models import coupled

    found = {}
    kwargs = {**reading, "warn": tell.warn}

    def work(j):
        data = logs.from_table(table, name=name, sha256=digest, joint=j, **kwargs)
        base, meta = models.load(pairs[j])
        base = coupled.view(base, j)
        coupled.add_partners(base, data, table, **kwargs)   # what the model reads (a group's member)
        data.signals.update(coupled.partner_signals(table, j, name, **kwargs))   # the coupling effect's
        models.check_log(meta, data, pairs[j])
        note = models.robot_model_note(meta, data, pairs[j])
        if note and done is not None:
            tell.warn(note)
        result = driver.diagnose(base, data, folds=opts["folds"], min_gain=opts["min_gain"], alpha=opts["alpha"],
                                 only=opts["only"], max_effects=opts["max_effects"],
                                 accept_implausible=opts["accept_implausible"])
        if done is not None:
            done(JointDiagnosis(j, pairs[j], result, data))
        found[j] = result.to_json()

    modelset.each_joint(list(pairs), work, what="results")
    return found


def _urdf_of(table, urdf) -> str | None:
    """The URDF given, or the one the log's import recorded when it is still there."""
    from fricli.robot import calibration as cb

    if urdf:
        return os.fspath(urdf)
    recorded = cb.recorded_urdf(table)
    return recorded if recorded and os.path.isfile(recorded) else None


def _calibrate_options(opts: dict, table, urdf) -> dict:
    """``opts`` with the sha256 of the URDF the robot model is calibrated from (an input of the
    models written, for ``if_changed``) when it is there."""
    path = _urdf_of(table, urdf)
    if path is not None and os.path.isfile(path):
        return {**opts, "urdf_sha256": jobs.file_sha256(path)}
    return opts


def _cutoff_hz(cutoff) -> float:
    return logs.DEFAULT_CUTOFF_HZ if cutoff is None else cutoff


def _calibrate(table, name: str, urdf, output: str, cutoff, tell: _Teller, friction: str | None):
    """Calibrate the log's robot model with ``friction`` (None: ``LOOP_FRICTION``), write ``output``
    and its report: (Calibration, the table with tau_g and tau_dyn recomputed from it)."""
    from fricli.robot import calibration as cb

    friction = friction or cb.LOOP_FRICTION
    path = _urdf_of(table, urdf)
    if path is None:
        raise OptionError("calibrate needs the URDF the log was imported with: give urdf", "urdf")
    tell.say(f"calibrating the robot model of {path} on {name} ...")
    cal, text, new = cb.recalibrate(table, name, path, friction=friction, cutoff_hz=_cutoff_hz(cutoff))
    cb.write(text, {"log": name, "urdf": path, "output": output, **cal.report}, output)
    for line in cb.warnings(cal.report):
        tell.warn(f"warning: {line}")
    tell.say(f"calibrated the robot model of {name} ({path}) -> {output}; tau_g and tau_dyn recomputed from it")
    return cal, new


def _fit_lines(cal, joints_: list) -> str:
    fit = cal.report["fit"]
    return ", ".join(f"joint {j} {fit[str(j)]['rms_before']:.3g} -> {fit[str(j)]['rms_after']:.3g} Nm"
                     for j in joints_ if str(j) in fit)


def _robot_model_check(results: dict, table, name: str, log: str, urdf, cutoff, tell: _Teller) -> dict | None:
    """Once per whole-arm log imported with a URDF: gravity or acceleration errors on several joints are the
    robot model's; the calibration that fixes them and, when the URDF is at hand, what it changes."""
    from fricli.fitting.diagnosis import driver
    from fricli.robot import calibration as cb

    if cb.recorded_urdf(table) is None and urdf is None:
        return None
    flagged = driver.robot_model_joints(results)
    if len(flagged) < 2:
        return None
    path = _urdf_of(table, urdf)
    who = ", ".join(str(j) for j in flagged)
    command = f"fricli calibrate {log} --urdf {path or 'ROBOT.urdf'} --friction {cb.LOOP_FRICTION} -o CAL.urdf"
    out = {"joints": [str(j) for j in flagged], "command": command, "fit": None}
    summary = f"robot-model errors on joints {who}: calibrate the robot model: `{command}`"
    if path is None:
        summary += " (give --urdf to see what it changes)"
        out["summary"] = summary
        return out
    tell.say(f"robot-model errors on joints {who}: calibrating the robot model on {name} to show what it changes ...")
    try:
        cal, _, _ = cb.recalibrate(table, name, path, friction=cb.LOOP_FRICTION, cutoff_hz=_cutoff_hz(cutoff))
    except FricliError as exc:       # the check is advice: the diagnosis stands without it
        out["summary"] = f"{summary} (the calibration on this log fails: {exc})"
        return out
    out["fit"] = {j: cal.report["fit"][j] for j in out["joints"] if j in cal.report["fit"]}
    out["suspicious"] = cal.report["suspicious"]
    out["summary"] = (f"{summary}; RMS in motion of tau_m minus the robot model and {cb.LOOP_FRICTION} friction on "
                      "this log, CAD -> "
                      f"calibrated: {_fit_lines(cal, flagged)}; then --fix --calibrate CAL.urdf refits the friction "
                      "on it")
    return out


def _calibrated_record(before: dict, after: dict, cal, output: str) -> dict:
    """What ``calibrate`` changed: per joint the held-out MAE with the CAD robot model and the friction model
    given -> with the calibrated robot model, its refitted friction and the added effects."""
    from fricli.fitting.diagnosis import driver

    flagged = driver.robot_model_joints(before)
    rows = {str(j): {"mae_before": before[j]["mae_before"], "mae_after": after[j]["mae_after"],
                     "model_errors_before": before[j].get("model_errors", []),
                     "model_errors_after": after[j].get("model_errors", [])} for j in after}
    change = ", ".join(f"joint {j} {r['mae_before']:.3g} -> {r['mae_after']:.3g}" for j, r in rows.items())
    fit = ", ".join(f"joint {j} {f['rms_before']:.3g} -> {f['rms_after']:.3g} Nm" for j, f in cal.report["fit"].items())
    summary = (f"robot-model errors on joints {', '.join(str(j) for j in flagged) or 'none'}: calibrated the robot "
               f"model -> {output} (RMS in motion of tau_m minus the robot model and {cal.report['friction']['kind']} "
               f"friction, CAD -> calibrated: {fit})\n"
               f"held-out MAE, CAD robot model + friction model -> calibrated robot model + refitted and fixed "
               f"friction: {change}")
    return {"joints": [str(j) for j in flagged], "calibrated_urdf": output, "fit": cal.report["fit"],
            "suspicious": cal.report["suspicious"], "mae": rows, "summary": summary}
