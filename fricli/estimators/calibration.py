"""``Calibration``: the robot model and each joint's friction from a whole-arm log (``fricli calibrate``)."""

from __future__ import annotations

import os

import numpy as np

from fricli.core import logs, timewindow
from fricli.estimators.base import NotFittedError, _Custom, _Params
from fricli.fitting.optionspec import Option


def _prior(value):
    if value == "auto" or (isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value)
                           and value > 0):
        return value
    raise ValueError(f"prior = {value!r}: expected auto or a number > 0")


def _gravity(value):
    try:
        if value is None:
            return None
        g = tuple(float(x) for x in value)
        if len(g) == 3 and np.all(np.isfinite(g)):
            return g
    except (TypeError, ValueError):
        pass
    raise ValueError(f"gravity = {value!r}: expected three numbers [m/s^2]")


def _urdf_joints(value):
    if value is None or (isinstance(value, dict) and all(isinstance(v, str) for v in value.values())):
        return value
    raise ValueError(f"urdf_joints = {value!r}: expected {{log joint: URDF joint name}}")


def _bound(value):
    if value is None or isinstance(value, timewindow.Bound):
        return value
    try:
        return timewindow.Bound.parse(str(value))
    except ValueError as exc:
        raise ValueError(f"time window bound {value!r}: {exc}") from None


def _calibrate_spec() -> dict:
    return {o.name: o for o in (
        Option("friction", "choice", "linear", "Each joint's friction fitted with the robot model.",
               choices=("linear", "stribeck")),
        _Custom("prior", "text", "auto", "auto, or the prior's strength (a number > 0).", validate=_prior),
        Option("consistency", "choice", "enforce", "enforce: fit again over physically consistent parameters; "
                                                   "check: refuse an inconsistent estimate.",
               choices=("enforce", "check")),
        Option("edge", "float", 0.5, "Seconds dropped at each end of the log (filter and difference transients in qdd) [s].", unit="s", low=0),
        Option("cutoff", "float", None, "Low-pass cut-off [Hz] when qd/qdd are derived from q.", unit="Hz",
               low=0, low_open=True),
        Option("match", "choice", None, "How the log's joints are matched to the URDF's: name or order.",
               choices=("name", "order")),
        _Custom("urdf_joints", "text", None, "{log joint: URDF joint name}.", validate=_urdf_joints),
        _Custom("gravity", "text", None, "Gravity (x, y, z) [m/s^2] in the URDF's base frame (default: the log's, "
                                         "else 0 0 -9.81).", validate=_gravity),
        _Custom("time_from", "text", None, "Calibrate on the rows from this time: seconds of t, or a share of its "
                                           "span (\"60%\").", validate=_bound),
        _Custom("time_until", "text", None, "... and before this time.", validate=_bound),
    )}


class Calibration(_Params):
    """The arm's inertial parameters, rotor inertias and each joint's friction from a whole-arm log
    and ``urdf`` (``fricli calibrate``; needs pinocchio): ``report_`` (the figures of the command's
    report),
    ``urdf_text_`` the calibrated URDF (``save``), ``friction_`` {joint: {Fv, Fc, offset, ...}}."""

    _positional = "urdf"
    _spec = _calibrate_spec()

    def _check_fitted(self) -> None:
        if not hasattr(self, "urdf_text_"):
            raise NotFittedError("this Calibration is not fitted yet: call fit(log) first")

    def fit(self, log, say=None, warn=None):
        """Calibrate on the whole-arm log ``log`` (a path; "-": stdin); returns self. ``say(line)``
        gets the lines the command prints on stderr, ``warn(line)`` its notes and warnings; an
        inconsistent estimate with ``consistency="check"`` raises FitError after them."""
        from fricli.robot import calibration as cb
        from fricli.robot.dynamics import load_model as load_robot
        from fricli.robot.mapping import Mapping

        say, warn = say or (lambda line: None), warn or (lambda line: None)
        urdf = os.fspath(self.urdf)
        name = "stdin" if log == "-" else os.fspath(log)
        table, _ = logs.read_table("-" if log == "-" else name)
        window = timewindow.Window(_bound(self.time_from), _bound(self.time_until))
        table = timewindow.slice_table(table, window, name, warn=warn)
        gravity = _gravity(self.gravity)
        robot = load_robot(urdf, Mapping(time=None, joints=[], gravity=logs.gravity_of(table.schema, gravity),
                                         held=logs.held_of(table.schema)))
        if self.cutoff is not None and {"qd", "qdd"} <= set(table.column_names):
            warn(f"note: --cutoff has no effect: {name} holds qd and qdd (derive them again with fricli import "
                 "--cutoff, or leave qdd out of the log)")
        names = {str(k): v for k, v in self.urdf_joints.items()} if self.urdf_joints else None
        motion = cb.read_motion(table, name, robot, match=self.match or ("name" if names else None), urdf_names=names,
                                cutoff_hz=logs.DEFAULT_CUTOFF_HZ if self.cutoff is None else float(self.cutoff))
        say(f"calibrating {len(robot.joints)} joints on {len(motion.t):,} samples of {name} ...")
        cal = cb.calibrate(robot, motion, prior=self.prior if self.prior == "auto" else float(self.prior),
                           edge_s=float(self.edge), enforce=self.consistency == "enforce", friction=self.friction)
        report = {"log": name, "urdf": urdf, **cal.report}
        for line in summary_lines(report):
            say(line)
        enforced = report["consistency_enforced"]
        if enforced:
            before = "; ".join(enforced["inconsistent_before"])
            warn(f"warning: the linear estimate was physically inconsistent ({before}): fitted again over consistent "
                 "parameters only")
        for line in cb.warnings(report):
            warn(f"warning: {line}")
        cb.refuse_inconsistent(cal)
        with open(urdf, encoding="utf-8") as fh:
            self.urdf_text_ = cb.calibrated_urdf(fh.read(), urdf, cal)
        self.calibration_, self.report_ = cal, report
        self.friction_ = cal.report["friction"]["joints"]
        return self

    def save(self, path, report=None) -> dict:
        """Write the calibrated URDF to ``path`` ("-": stdout) and the report to ``report`` (default
        PATH.calibration.json beside it, none for "-"): the files ``fricli calibrate -o PATH
        [--report REPORT]`` writes. Returns the report as written (its path as "report")."""
        from fricli.robot import calibration as cb

        self._check_fitted()
        out = os.fspath(path)
        written = {"log": self.report_["log"], "urdf": self.report_["urdf"], "output": out,
                   **self.calibration_.report}
        cb.write(self.urdf_text_, written, out, None if report is None else os.fspath(report))
        return written


def summary_lines(report: dict) -> list[str]:
    """The lines ``fricli calibrate`` prints on stderr for a calibration's ``report``."""
    ex = report["excitation"]
    lines = [f"excitation: {ex['base_parameters']} base parameters of {ex['parameters']} "
             f"({ex['structurally_unidentifiable']} combinations no joint-torque data can separate stay at CAD); "
             f"condition number {ex['condition_number']:.3g} ({ex['condition_number_scaled']:.3g} with scaled columns)"]
    if ex["undetermined"]:
        lines.append(f"excitation: this run leaves {len(ex['undetermined'])} direction"
                     f"{'s' if len(ex['undetermined']) != 1 else ''} undetermined (kept near CAD):")
        for d in ex["undetermined"][:8]:
            combo = " ".join(f"{p['weight']:+.2g} {p['parameter']}" for p in d["combination"])
            lines.append(f"  {combo} (information {d['information']:.2g} x the prior's)")
        if len(ex["undetermined"]) > 8:
            lines.append(f"  ... and {len(ex['undetermined']) - 8} more (see the report)")
    tied = ex.get("masses_not_determined_alone") or {}
    if tied:
        lines.append(f"excitation: the masses of {', '.join(m.removesuffix('.m') for m in tied)} are not determined "
                     "alone (each trades with other parameters, see the report): the calibrated torques are what to "
                     "trust, not each link's mass")
    choice = report.get("prior_choice")
    if choice:
        held, weakest = choice["held_out_rms"], max(choice["grid"])
        line = (f"prior: {report['prior']:g} x each parameter's scale (held-out weighted RMS "
                f"{held[format(report['prior'], 'g')]:.4g}; {held[format(weakest, 'g')]:.4g} at the weakest, {weakest:g})")
        if choice.get("per_group"):
            per = choice["per_group"].values()
            line += (f", then per body and armature {min(per):g} to {max(per):g} "
                     f"(held-out {choice['held_out_rms_per_group']:.4g})")
        lines.append(line + f"; chosen by {choice['folds']}-fold cross-validation over time (see the report)")
    else:
        lines.append(f"prior: {report['prior']:g} x each parameter's scale (--prior)")
    lines.append("fit: RMS of tau_m minus the model over each joint's rows in motion [Nm], CAD + friction -> calibrated:")
    for joint, f in report["fit"].items():
        fr = report["friction"]["joints"][joint]
        extra = f", Fs {fr['Fs']:.4g}, vs {fr['vs']:.3g}" if "Fs" in fr else ""
        lines.append(f"  joint {joint}: {f['rms_before']:.4g} -> {f['rms_after']:.4g} on {f['rows_in_motion']:,} rows "
                     f"({'motor: ' if fr.get('motor') else ''}Fv {fr['Fv']:.4g}, Fc {fr['Fc']:.4g}{extra}, "
                     f"offset {fr['offset']:.4g})")
    if report.get("motors"):
        lines.append("motors (through the log's transmission): rotor inertia [kg m^2], prior -> identified:")
        lines += [f"  motor of joint {joint}: {m['prior']:.4g} -> {m['identified']:.4g}"
                  for joint, m in report["motors"].items()]
    return lines


def identify_payload(log, frame: str, *, urdf=None, cutoff=None, edge: float = 0.5, friction: str = "linear",
                     time_from=None, time_until=None, warn=None):
    """``fricli payload LOG --frame FRAME``: the point mass [kg] and centre of mass [m, in FRAME's
    coordinates] a whole-arm log's joints carry at ``frame``, with each joint's friction alongside
    (``friction``: "linear" or "stribeck"); ``urdf`` (default: the one the log's import recorded), ``cutoff`` [Hz], ``edge`` [s],
    ``time_from``/``time_until`` as the command's options. Returns the command's result
    (``fricli.robot.payload.IdentifiedPayload``: ``mass``, ``com``, ``stderr``, ``verdict``,
    ``report()`` as ``--json`` prints it without ``log``); ``warn(line)`` gets the command's notes."""
    from fricli.fitting.optionspec import check_values
    from fricli.robot import payload

    spec = _calibrate_spec()
    opts = check_values({"cutoff": cutoff, "edge": edge, "friction": friction, "time_from": time_from,
                         "time_until": time_until},
                        {name: spec[name] for name in ("cutoff", "edge", "friction", "time_from", "time_until")},
                        "identify_payload")
    bounds = [_bound(opts["time_from"]), _bound(opts["time_until"])]
    name = "stdin" if log == "-" else os.fspath(log)
    table, _ = logs.read_table("-" if log == "-" else name)
    table = timewindow.slice_table(table, timewindow.Window(*bounds), name, warn=warn)
    return payload.identify_log(table, name, frame, urdf=None if urdf is None else os.fspath(urdf),
                                cutoff_hz=opts["cutoff"], edge_s=opts["edge"], friction=opts["friction"])
