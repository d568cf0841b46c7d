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
    if value is None:
        return None
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
        Option("edge", "float", 0.5, "Seconds left out at each end of every stretch of the log [s].", unit="s", low=0),
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

    def fit(self, log):
        """Calibrate on the whole-arm log ``log`` (a path); returns self."""
        from fricli.robot import calibration as cb
        from fricli.robot.dynamics import load_model as load_robot
        from fricli.robot.mapping import Mapping

        urdf = os.fspath(self.urdf)
        name = os.fspath(log)
        table, _ = logs.read_table(name)
        table = timewindow.slice_table(table, timewindow.Window(_bound(self.time_from), _bound(self.time_until)), name)
        gravity = _gravity(self.gravity)
        robot = load_robot(urdf, Mapping(time=None, joints=[], gravity=logs.gravity_of(table.schema, gravity),
                                         held=logs.held_of(table.schema)))
        names = {str(k): v for k, v in self.urdf_joints.items()} if self.urdf_joints else None
        motion = cb.read_motion(table, name, robot, match=self.match or ("name" if names else None), urdf_names=names,
                                cutoff_hz=logs.DEFAULT_CUTOFF_HZ if self.cutoff is None else float(self.cutoff))
        cal = cb.calibrate(robot, motion, prior=self.prior if self.prior == "auto" else float(self.prior),
                           edge_s=float(self.edge), enforce=self.consistency == "enforce", friction=self.friction)
        cb.refuse_inconsistent(cal)
        with open(urdf, encoding="utf-8") as fh:
            self.urdf_text_ = cb.calibrated_urdf(fh.read(), urdf, cal)
        self.calibration_, self.report_ = cal, cal.report
        self.friction_ = cal.report["friction"]["joints"]
        return self

    def save(self, path) -> None:
        """Write the calibrated URDF (the file ``fricli calibrate -o`` writes)."""
        from fricli.core.atomic import atomic_write_bytes

        self._check_fitted()
        atomic_write_bytes(os.fspath(path), self.urdf_text_.encode())
