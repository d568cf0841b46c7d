"""fricli calibrate: a whole-arm log + URDF -> a calibrated URDF (inertial parameters, armature, or
each motor's rotor inertia through the log's transmission) and each joint's (motor's) linear
friction, identified together."""

from __future__ import annotations

import math

import click

from fricli.cli.options import Number, common, emit_json, output_option, say, warn, window_options


class PriorStrength(click.ParamType):
    """--prior: "auto" or a positive number."""

    name = "auto|P"

    def convert(self, value, param, ctx):
        if isinstance(value, float) or str(value).strip().lower() == "auto":
            return value if isinstance(value, float) else "auto"
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not number > 0 or not math.isfinite(number):
            self.fail(f"{value!r} is neither auto nor a positive number", param, ctx)
        return number


@click.command("calibrate")
@click.argument("log")
@click.option("--urdf", required=True, metavar="ROBOT.urdf",
              help="The robot description whose CAD values are the starting point (needs Pinocchio).")
@click.option("--match", type=click.Choice(["name", "order"]), default=None,
              help="How log joints match URDF joints (default: as recorded by fricli import/dynamics).")
@click.option("--urdf-joint", "urdf_pairs", multiple=True, metavar="JOINT=NAME",
              help="The URDF joint of a log joint, with --match name. Repeatable.")
@click.option("--gravity", nargs=3, type=Number(), default=None, metavar="X Y Z",
              help="Gravity in the URDF's base frame [m/s^2] (default: as recorded by fricli import/dynamics, "
                   "else 0 0 -9.81).")
@click.option("--friction", type=click.Choice(["linear", "stribeck"]), default="linear", show_default=True,
              help="Friction identified with the rigid body: linear = Fv*qd + Fc*sign(qd) + offset per joint "
                   "(IDIM-LS); stribeck adds the LuGre static curve's bump (Fs - Fc) exp(-(qd/vs)^2).")
@click.option("--prior", type=PriorStrength(), default="auto", show_default=True, metavar="auto|P",
              help="Prior standard deviation of each inertial parameter and armature around its CAD/prior value, "
                   "relative to its scale; auto: the strength whose fits best predict held-out blocks of time "
                   "of the log (cross-validation).")
@click.option("--consistency", type=click.Choice(["enforce", "check"]), default="enforce", show_default=True,
              help="enforce: fit again over physically consistent parameters when the linear estimate is not; "
                   "check: refuse (FIT, exit 5) an inconsistent estimate.")
@click.option("--edge", type=Number(min=0), default=0.5, show_default=True,
              help="Seconds dropped at each end of the log (filter and difference transients in qdd).")
@click.option("--cutoff", type=Number(min=0, min_open=True), default=None,
              help="Low-pass cut-off [Hz] when qd/qdd are derived from the log (default: the log contract's 50); "
                   "no effect on a log that holds both.")
@click.option("--report", "report_file", default=None, metavar="REPORT.json",
              help="Where to write the report (default: OUT.calibration.json beside the URDF; none with -o -).")
@window_options
@click.option("--json", "as_json", is_flag=True, help="Print the report as JSON on stdout.")
@output_option(help="The calibrated URDF (- for stdout).")
@common
def calibrate_cmd(log, urdf, match, urdf_pairs, gravity, friction, prior, consistency, edge, cutoff, report_file, as_json,
                  output, quiet, window):
    """Identify the arm's rigid-body model and each joint's friction from one whole-arm log.

    LOG is a long-format log of every moving joint of the URDF (as fricli import writes it) with
    q, qd, qdd (or derivable) and tau_m. The URDF's masses, centres of mass and inertias, a reflected
    rotor inertia per joint and Fv, Fc, offset per joint are fitted together by weighted least
    squares with a prior at the CAD values: what the run does not excite stays at CAD and is
    reported. When the log records a transmission (a motor-side import), the rotor inertia and the
    friction are each motor's, through the transmission. Writes the calibrated URDF and a JSON
    report (friction, fit, excitation, checks). See docs/calibration.md.

    \b
    Example:
      fricli calibrate run.parquet --urdf ur10e.urdf -o ur10e-cal.urdf
      fricli import other.csv --mapping docs/ur10e-mapping.toml --urdf ur10e-cal.urdf -o other.parquet
    """
    from fricli.cli.robot import urdf_joint_names
    from fricli.estimators import Calibration

    if output == "-" and (as_json or report_file == "-"):
        raise click.UsageError("-o - writes the URDF to stdout: give the report a file (--report REPORT.json)")
    est = Calibration(urdf, match=match, urdf_joints=urdf_joint_names(urdf_pairs) or None, gravity=gravity,
                      friction=friction, prior=prior, consistency=consistency, edge=edge, cutoff=cutoff,
                      time_from=window.start, time_until=window.stop)
    est.fit(log, say=lambda line: say(line, quiet), warn=warn)
    report = est.save(output, report_file)
    say(f"calibrated {len(est.calibration_.joints)} joints of {urdf} on {report['rows']:,} rows of {report['log']} -> "
        f"{output} (report: {report['report'] or 'none'})", quiet)
    if as_json:
        emit_json(report)
