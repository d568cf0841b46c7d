"""fricli calibrate: a whole-arm log + URDF -> a calibrated URDF (inertial parameters, armature, or
each motor's rotor inertia through the log's transmission) and each joint's (motor's) linear
friction, identified together."""

from __future__ import annotations

import math

import click

from fricli.cli.options import Number, common, emit_json, output_option, read_log, say, warn, window_options


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
              help="Low-pass cut-off [Hz] when qd/qdd are derived from the log (default: the log contract's); "
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
    from fricli.core.logs import DEFAULT_CUTOFF_HZ, gravity_of, held_of
    from fricli.robot import calibration as cb
    from fricli.robot.dynamics import load_model
    from fricli.robot.mapping import Mapping

    if output == "-" and (as_json or report_file == "-"):
        raise click.UsageError("-o - writes the URDF to stdout: give the report a file (--report REPORT.json)")
    names = urdf_joint_names(urdf_pairs)
    if names and match is None:
        match = "name"
    table, _ = read_log(log, window)
    name = "stdin" if log == "-" else log
    robot = load_model(urdf, Mapping(time=None, joints=[], gravity=gravity_of(table.schema, gravity),
                                     held=held_of(table.schema)))
    if cutoff is not None and {"qd", "qdd"} <= set(table.column_names):
        warn(f"note: --cutoff has no effect: {name} holds qd and qdd (derive them again with fricli import "
             "--cutoff, or leave qdd out of the log)")
    motion = cb.read_motion(table, name, robot, match=match, urdf_names=names,
                            cutoff_hz=DEFAULT_CUTOFF_HZ if cutoff is None else cutoff)
    say(f"calibrating {len(robot.joints)} joints on {len(motion.t):,} samples of {name} ...", quiet)
    cal = cb.calibrate(robot, motion, prior=prior, edge_s=edge, enforce=consistency == "enforce", friction=friction)
    report = {"log": name, "urdf": urdf, "output": output, **cal.report}
    for line in _summary(report):
        say(line, quiet)
    enforced = report["consistency_enforced"]
    if enforced:
        warn(f"warning: the linear estimate was physically inconsistent ({'; '.join(enforced['inconsistent_before'])}): "
             "fitted again over consistent parameters only")
    for line in cb.warnings(report):
        warn(f"warning: {line}")
    cb.refuse_inconsistent(cal)
    with open(urdf, encoding="utf-8") as fh:
        text = cb.calibrated_urdf(fh.read(), urdf, cal)
    where = cb.write(text, report, output, report_file)
    say(f"calibrated {len(cal.joints)} joints of {urdf} on {report['rows']:,} rows of {name} -> {output} "
        f"(report: {where or 'none'})", quiet)
    if as_json:
        emit_json(report)


def _summary(report: dict) -> list[str]:
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
