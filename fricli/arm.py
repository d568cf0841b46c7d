"""A whole arm in one call: a recording, its mapping and the robot's URDF -> calibrated robot
model, friction models per joint, their scores against the linear baseline on held-out data,
a report and a C header, each step's output kept in one folder (``fricli fit-arm``).

The steps, and what each writes into ``out``:

1. ``fit-cad.parquet``: the recording imported with the given (CAD) URDF (``fricli import``);
2. ``lugre/``: the extended LuGre model of every joint (``fricli identify``);
3. ``robot.urdf`` and ``robot.calibration.json``: the robot model calibrated on the recording
   with Stribeck friction (``fricli calibrate --friction stribeck``);
4. ``fit.parquet``: the recording imported again with the calibrated URDF;
5. ``fixed/``: each LuGre model refitted on that log, with the effects it still misses added
   (``fricli diagnose --fix --calibrate``);
6. ``validate/``: the held-out recordings imported with each URDF, scored (``ArmReport.scores``);
7. ``friction.h`` (``fricli export``), ``report.json`` and ``report.md``.

Held-out data: the recordings given as ``validate`` (other runs, e.g. of other days); without
them the last ``holdout`` share of the recording's time, which no step fits on. The baseline is
the standard model Fv*qd + Fc*sign(qd) + offset fitted by least squares on every row the models
are fitted on (robot model: the CAD URDF's); the score is the RMS over the rows in motion of
tau_m minus the whole model (robot model + friction): the same figure for two robot models.

``if_changed``: a step whose inputs (file contents and options) are those of the last run
(``out/fit-arm.json``) and whose outputs are still as it wrote them is not redone.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from typing import Callable

import numpy as np

from fricli.core import jobs, logs, metrics, modelset, timewindow
from fricli.core.atomic import atomic_write_bytes
from fricli.core.errors import FricliError, LogError
from fricli.fitting.optionspec import OptionError

STEPS_FILE = "fit-arm.json"
CUTOFF_HZ = 10.0        # Hz: the derived qd, qdd of the import (excitation of identification runs < 1 Hz)
HOLDOUT = 0.25          # share of the recording's time held out when no validation recording is given


@dataclasses.dataclass
class ArmReport:
    """What ``fit_arm`` made: ``outputs`` {step: path}; ``scores`` {joint: {"linear", "lugre",
    "fixed": RMS in motion [Nm], "ratio": fixed / linear, "rows": rows in motion scored}};
    ``mean_ratio``; ``held_out``: what was scored; ``notices``: (warning | note, line) in order;
    ``redone``: the steps run (the others were up to date)."""

    outputs: dict
    scores: dict
    mean_ratio: float
    held_out: str
    notices: list
    redone: list

    @property
    def unchanged(self) -> bool:
        return not self.redone

    def to_json(self) -> dict:
        return {"outputs": self.outputs, "scores": self.scores, "mean_ratio": self.mean_ratio,
                "held_out": self.held_out, "notices": [line for _, line in self.notices], "redone": self.redone}


def fit_arm(recordings: list[str], mapping: str, urdf: str, out: str, *, validate: list[str] = (),
            holdout: float | None = None, cutoff_hz: float = CUTOFF_HZ, prefix: str = "friction",
            if_changed: bool = False, say: Callable[[str], None] = lambda s: None) -> ArmReport:
    """Run every step into the folder ``out`` (made when missing; see the module's docstring).

    ``recordings``: the recording (its files, for a recording in several files) read with the
    mapping file ``mapping``; ``urdf``: the robot's (CAD) URDF; ``validate``: held-out recordings
    of the same robot, each read with the same mapping; ``holdout``: the share of the recording's
    time held out (default ``HOLDOUT`` without ``validate``, 0 with); ``prefix``: of the C names;
    ``say(line)``: progress. OptionError naming the option for ``holdout`` out of (0, 1) or given
    with ``validate``; LogError naming an input file that is not there (nothing is written then);
    LockedError when another run holds ``out``."""
    from fricli.core.files import path_arg

    def paths(given, what: str) -> list[str]:   # one file given alone, not in a list: that file
        return [path_arg(p, what, "fit_arm") for p in ([given] if isinstance(given, (str, os.PathLike)) else given)]

    recordings, validate = paths(recordings, "recordings"), paths(validate, "validate")
    mapping, urdf, out = (path_arg(v, w, "fit_arm") for v, w in ((mapping, "mapping"), (urdf, "urdf"), (out, "out")))
    if holdout is not None and validate:
        raise OptionError("holdout applies without validate (the validation recordings are held out)", "holdout")
    share = (0.0 if validate else HOLDOUT) if holdout is None else float(holdout)
    if not (0.0 < share < 1.0 or validate):
        raise OptionError(f"fit_arm option holdout = {holdout!r}: expected a share in (0, 1)", "holdout")
    check_inputs(list(recordings), mapping, urdf, list(validate))
    os.makedirs(out, exist_ok=True)
    run = _Steps(out, if_changed, say)
    earlier = bool(run.record)   # the folder holds a run before this one
    with jobs.output_lock(os.path.join(out, STEPS_FILE)):
        try:
            window = timewindow.Window(None, timewindow.Bound.parse(f"{100 * (1 - share):g}%")) if share else None
            fit_cad = run.imported("fit-cad.parquet", recordings, mapping, urdf, cutoff_hz)
            lugre = run.models("lugre", "identify", fit_cad, window)
            cal_urdf = run.calibrated("robot.urdf", fit_cad, urdf, window, cutoff_hz)
            fit = run.imported("fit.parquet", recordings, mapping, cal_urdf, cutoff_hz)
            fixed = run.models("fixed", "diagnose", fit, window, inputs=lugre, urdf=cal_urdf)
            if validate:
                pairs = [(run.imported(f"validate/{name}-cad.parquet", [v], mapping, urdf, cutoff_hz),
                          run.imported(f"validate/{name}.parquet", [v], mapping, cal_urdf, cutoff_hz))
                         for v, name in zip(validate, _names(validate))]
                held = f"{len(validate)} validation recording{'s' if len(validate) > 1 else ''}"
            else:
                pairs = [(fit_cad, fit)]
                held = f"the last {share:.0%} of the recording's time"
            header = run.exported("friction.h", fixed, prefix)
            scores = run.last_scores() if not run.redone else None
            if not run.redone and (scores is None or not all(os.path.isfile(os.path.join(out, f))
                                                             for f in ("report.md", "report.json"))):
                run.redone.append("report")   # the report missing or damaged: made again, with its notes
                run.notices = run.notices or run.last_notices
            if scores is None:
                say("scoring on held-out data ...")
                scores = score(fit_cad, window, lugre, fixed, pairs, None if validate else share)
                run.notices += worse_after_calibration(scores)
            ratios = [s["ratio"] for s in scores.values() if np.isfinite(s["ratio"])]
            report = ArmReport({"import": fit_cad, "identify": lugre, "calibrate": cal_urdf, "import_calibrated": fit,
                                "diagnose": fixed, "export": header}, scores,
                               float(np.mean(ratios)) if ratios else float("nan"), held,
                               list(dict.fromkeys(run.notices)), run.redone)
            if run.redone:
                _write_report(out, report, recordings, urdf)
            run.save()
        except FricliError as exc:   # say which files are this run's: the others are of the run before
            if earlier and run.redone:
                exc.args = (f"{exc} (in {out}, this run redid {', '.join(run.redone)}; its other files are of the "
                            "run before)",)
            raise
    return report


def _names(paths: list[str]) -> list[str]:
    """Each recording's file name without its extension; -2, -3, ... added to a name taken before."""
    out = []
    for path in paths:
        name = os.path.basename(os.path.normpath(path))
        stem = name.rsplit(".", 1)[0] if "." in name else name
        k, unique = 1, stem
        while unique in out:
            k += 1
            unique = f"{stem}-{k}"
        out.append(unique)
    return out


class _Steps:
    """Each step run, or skipped when ``if_changed`` and its record in STEPS_FILE matches."""

    def __init__(self, out: str, if_changed: bool, say: Callable):
        self.out, self.if_changed, self.say = out, if_changed, say
        self.path = os.path.join(out, STEPS_FILE)
        self.notices, self.redone = [], []
        self.last_notices: list = []   # the notices of the last run's report (``last_scores``)
        try:
            with open(self.path, encoding="utf-8") as fh:
                self.record = json.load(fh).get("steps", {})
        except (OSError, ValueError, AttributeError):
            self.record = {}
        if not isinstance(self.record, dict) or not all(   # a record of another shape: every step is redone
                isinstance(r, dict) and isinstance(r.get("outputs"), dict) for r in self.record.values()):
            self.record = {}

    def _fresh(self, name: str, key: dict, outputs: list[str]) -> bool:
        seen = self.record.get(name)
        return (self.if_changed and seen is not None and seen.get("key") == key
                and all(os.path.isfile(p) and jobs.file_sha256(p) == seen["outputs"].get(os.path.relpath(p, self.out))
                        for p in outputs))

    def _done(self, name: str, key: dict, outputs: list[str]) -> None:
        self.redone.append(name)
        self.record[name] = {"key": key, "outputs": {os.path.relpath(p, self.out): jobs.file_sha256(p)
                                                     for p in outputs}}

    def _files(self, folder: str) -> list[str]:
        return sorted(os.path.join(folder, f) for f in os.listdir(folder) if f.endswith(".npz"))

    def imported(self, name, recordings, mapping_path, urdf, cutoff_hz) -> str:
        from fricli.robot.importing import import_log

        path = os.path.join(self.out, name)
        key = {"recordings": [jobs.file_sha256(r) for r in recordings], "mapping": jobs.file_sha256(mapping_path),
               "urdf": jobs.file_sha256(urdf), "cutoff_hz": cutoff_hz}
        if self._fresh(name, key, [path]):
            return path
        self.say(f"import: {' + '.join(recordings)} with {urdf} -> {path}")
        os.makedirs(os.path.dirname(path), exist_ok=True)
        done = import_log(list(recordings), mapping_path, output=path, urdf=urdf, cutoff_hz=cutoff_hz)
        self.notices += done.notices
        for finding in (done.meta.get("robot") or {}).get("mapping_check", {}).get("findings", []):
            self.notices.append(("warning", f"{done.name}: the mapping disagrees with {urdf}: {finding['message']}"))
        self._done(name, key, [path])
        return path

    def models(self, name, pipeline, log, window, inputs=None, urdf=None) -> str:
        from fricli.fitting import plan

        folder = os.path.join(self.out, name)
        os.makedirs(folder, exist_ok=True)
        self.say(f"{pipeline}: every joint of {log} -> {folder}/")
        opts = diagnose_options(urdf) if pipeline == "diagnose" else {}
        made = plan.fit_log(pipeline, log, folder, opts, inputs=inputs, window=window, if_changed=self.if_changed,
                            refit=pipeline == "diagnose", warn=lambda line: self.notices.append(("warning", line)))
        for outcome in made.outcomes:
            for line in (outcome.made.summary.get("warnings", []) if outcome.made else []):
                self.notices.append(("warning", f"joint {outcome.label}: {line}"))
        if not made.unchanged:
            self.redone.append(name)
        return folder

    def calibrated(self, name, log, urdf, window, cutoff_hz) -> str:
        from fricli.robot import calibration as cb

        path = os.path.join(self.out, name)
        report = cb.report_path(path)
        key = {"log": jobs.file_sha256(log), "urdf": jobs.file_sha256(urdf),
               "window": window.to_json() if window else None, "cutoff_hz": cutoff_hz, "friction": cb.LOOP_FRICTION}
        if self._fresh(name, key, [path, report]):
            return path
        self.say(f"calibrate: the robot model of {urdf} on {log} -> {path}")
        table, _ = logs.read_table(log)
        table = timewindow.slice_table(table, window, log)
        cal, text, _ = cb.recalibrate(table, log, urdf, friction=cb.LOOP_FRICTION, cutoff_hz=cutoff_hz)
        cb.write(text, {"log": log, "urdf": urdf, "output": path, **cal.report}, path)
        self.notices += [("warning", line) for line in cb.warnings(cal.report)]
        self._done(name, key, [path, report])
        return path

    def exported(self, name, folder, prefix) -> str:
        from fricli.export.c import export

        path = os.path.join(self.out, name)
        key = {"models": [jobs.file_sha256(p) for p in self._files(folder)], "prefix": prefix}
        if self._fresh(name, key, [path]):
            return path
        self.say(f"export: {folder}/ -> {path}")
        atomic_write_bytes(path, export(folder, prefix).encode())
        self._done(name, key, [path])
        return path

    def last_scores(self) -> dict | None:
        """The scores of the last run's report when ``if_changed`` and it is there (nothing was redone)."""
        try:
            with open(os.path.join(self.out, "report.json"), encoding="utf-8") as fh:
                last = json.load(fh)
            scores = last["scores"]
            self.last_notices = [("note", str(line)) for line in last.get("notices", [])]
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None
        if not self.if_changed or not isinstance(scores, dict):
            return None
        return {j: {k: float("nan") if v is None else v for k, v in row.items()} for j, row in scores.items()}

    def save(self) -> None:
        if self.redone or not os.path.isfile(self.path):
            body = json.dumps({"steps": self.record}, indent=2, sort_keys=True) + "\n"
            atomic_write_bytes(self.path, body.encode())


def diagnose_options(urdf: str | None = None) -> dict:
    """diagnose --fix --calibrate's options at their defaults (what the command records), with the
    sha256 of the calibrated URDF when given."""
    from fricli.estimators.jobs import diagnose_options as options

    return options(**({} if urdf is None else {"urdf_sha256": jobs.file_sha256(urdf)}))


def linear_columns(sig: dict) -> np.ndarray:
    """The standard model's regressor [qd, sign(qd), 1], shape (n, 3)."""
    qd = sig["qd"]
    return np.column_stack([qd, np.sign(qd), np.ones_like(qd)])


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else float("nan")


def score(fit_cad: str, window, lugre: str, fixed: str, pairs: list, holdout: float | None) -> dict:
    """{joint: scores} (``ArmReport.scores``): the linear baseline (fitted on ``fit_cad``'s rows in
    ``window``) and the LuGre models on the logs of the CAD URDF, the fixed models on those of the
    calibrated one; ``pairs``: (CAD log, calibrated log) of each held-out recording; ``holdout``:
    score only the last share of their time (the held-out part of the fitting recording)."""
    from fricli.estimators import load_model, read_log

    table, _ = logs.read_table(fit_cad)
    scores = {}
    for joint in logs.joints_of(table, fit_cad) or [None]:
        key = None if joint is None else str(joint)
        until = None if window is None else str(window.stop)
        sig = read_log(fit_cad, joint=key, time_until=until).signals
        coef = np.linalg.lstsq(linear_columns(sig), logs.friction_target(sig), rcond=None)[0]
        models = {name: load_model(modelset.path_for(folder, joint))
                  for name, folder in (("lugre", lugre), ("fixed", fixed))}
        errors = {"linear": [], "lugre": [], "fixed": []}
        for cad, cal in pairs:
            since = None if not holdout else f"{100 * (1 - holdout):g}%"
            for which, path in (("linear", cad), ("lugre", cad), ("fixed", cal)):
                data = read_log(path, joint=key, time_from=since)
                sig = data.signals
                pred = linear_columns(sig) @ coef if which == "linear" else models[which].predict(data)
                moving = metrics.in_motion(sig["qd"])
                errors[which].append((logs.friction_target(sig) - pred)[moving])
        row = {k: _rms(np.concatenate(v)) for k, v in errors.items()}
        row["ratio"] = row["fixed"] / row["linear"] if row["linear"] > 0 else float("nan")
        row["rows"] = int(sum(e.size for e in errors["fixed"]))
        row["linear_coef"] = {"Fv": float(coef[0]), "Fc": float(coef[1]), "offset": float(coef[2])}
        scores[key] = row
    return scores


def worse_after_calibration(scores: dict) -> list[tuple[str, str]]:
    """A warning per joint whose fixed model, on the calibrated robot model, scores worse on the
    held-out rows than its LuGre model on the CAD one by more than two standard errors of an RMS
    over its rows (2 / sqrt(2 rows) relative, white residuals assumed) (``scores`` as ``score``
    returns them)."""
    return [("warning", f"joint {joint}: the fixed model on the calibrated robot model scores {s['fixed']:.4g} on the "
                        f"held-out rows, worse than the LuGre model on the CAD one ({s['lugre']:.4g}): for this joint "
                        "the LuGre (CAD) model is the better of the two. Look at what the calibration moved "
                        "(robot.calibration.json: an offset traded against a constant gravity torque, a breakaway "
                        "the refit lost)")
            for joint, s in scores.items() if s["fixed"] > s["lugre"] * (1 + 2 / math.sqrt(2 * max(s["rows"], 1)))]


def _write_report(out: str, report: ArmReport, recordings: list[str], urdf: str) -> None:
    from fricli.core import jsontext

    atomic_write_bytes(os.path.join(out, "report.json"), jsontext.dumps(report.to_json()).encode())
    atomic_write_bytes(os.path.join(out, "report.md"), markdown(report, recordings, urdf).encode())


def markdown(report: ArmReport, recordings: list[str], urdf: str) -> str:
    """report.md: the score table per joint and the files of each step."""
    lines = [f"# fit-arm: {' + '.join(map(os.path.basename, recordings))}", "",
             f"Robot model: {os.path.basename(urdf)}, calibrated -> {os.path.basename(report.outputs['calibrate'])}. "
             f"Scored on {report.held_out}: RMS over the rows in motion of tau_m minus the whole model "
             "(robot model + friction) [Nm].", "",
             "| joint | linear baseline | LuGre (CAD) | fixed (calibrated) | fixed / linear | rows in motion |",
             "|---|---|---|---|---|---|"]
    for joint, s in report.scores.items():
        lines.append(f"| {joint} | {s['linear']:.4g} | {s['lugre']:.4g} | {s['fixed']:.4g} | {s['ratio']:.3f} | "
                     f"{s['rows']:,} |")
    lines += ["", f"Mean ratio fixed / linear: {report.mean_ratio:.3f}.", "", "Files:", ""]
    lines += [f"- {step}: `{os.path.basename(os.path.normpath(path))}`" for step, path in report.outputs.items()]
    if report.notices:
        lines += ["", "Warnings and notes:", ""] + [f"- {line}" for _, line in report.notices]
    return "\n".join(lines) + "\n"


def check_inputs(recordings: list[str], mapping: str, urdf: str, validate: list[str]) -> None:
    """LogError naming the first input file that is not there."""
    for path in (*recordings, mapping, urdf, *validate):
        if not os.path.exists(path):
            raise LogError(f"{path}: no such file")


