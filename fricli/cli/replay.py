"""fricli replay and fricli thresholds."""

from __future__ import annotations

import click

from fricli.applying import observer
from fricli.cli import cli
from fricli.cli.options import Number, common, emit_json, json_flag, robot_model_flags, say, zero_keywords


def urdf_option(f):
    return click.option("--urdf", type=click.Path(), default=None,
                        help="URDF of the arm: the observer's rigid-body terms (M(q) qd, C(q, qd)^T qd, g(q)) through "
                             "Pinocchio, with the gravity, payload, rotor inertias and joint names the log's import "
                             "recorded. Without it: the per-joint form on the log's tau_g and tau_dyn.")(f)


GAIN_HELP = (f"Observer gain K [1/s] (time constant 1/K). Default: the thresholds file's, else "
             f"{observer.DEFAULT_GAIN:g}.")
TIME_CONSTANT_HELP = "Memory of the adaptation [s]: forgetting factor exp(-dt / T)."


def label(joint) -> str:
    """How a joint is named on stderr: a log without a joint column has one joint, without a name."""
    return "the joint" if joint in (None, "None") else f"joint {joint}"


def gain_option(f):
    return click.option("--gain", type=Number(min=0, min_open=True), default=None, help=GAIN_HELP)(f)


@cli.command("replay")
@click.argument("model", type=click.Path())
@click.argument("log", type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(), help="Output log (Parquet).")
@urdf_option
@click.option("--adapt", is_flag=True,
              help="Adapt each joint's friction level (the scale of its friction) online; needs --thresholds (no "
                   "update while a contact is suspected).")
@click.option("--adapt-offset", is_flag=True, help="With --adapt: adapt an offset too, besides the scale.")
@click.option("--thresholds", "thresholds_path", type=click.Path(), default=None,
              help="Contact thresholds of fricli thresholds: adds the flags and the events.")
@click.option("--time-constant", type=Number(min=0, min_open=True), default=observer.Adaptation().time_constant,
              show_default=True, help=TIME_CONSTANT_HELP)
@gain_option
@robot_model_flags
@json_flag
@common
def replay_cmd(model, log, output, urdf, adapt, adapt_offset, thresholds_path, time_constant, gain, zero, as_json,
               quiet):
    """Run LOG row by row through what the controller runs: MODEL's friction, the momentum observer
    of the external torque, with --adapt the online friction level, with --thresholds contact
    detection. Writes the log with tau_f_pred, tau_ext_pred and contact (0/1) added.

    Causal: row k uses rows up to k only. The exported arm header (fricli export --observer)
    gives the same numbers. Contact events (joint, start, end, peak torque) and each joint's
    friction error in motion go to stderr (and stdout with --json). See docs/contact-detection.md.

    \b
    Example:
      fricli thresholds models/ fit.parquet --urdf arm.urdf -o thresholds.json
      fricli replay models/ run.parquet --urdf arm.urdf --adapt --thresholds thresholds.json -o out.parquet
    """
    from fricli.robot import replay

    done = replay.replay_log(model, log, output, urdf=urdf, thresholds=thresholds_path, adapt=adapt,
                             adapt_offset=adapt_offset, time_constant=time_constant, gain=gain,
                             **zero_keywords(zero))
    arm, k, figures = done.arm, done.gain, done.figures
    if not quiet:
        which = "the log's joint" if arm.joints == [None] else f"joints {', '.join(map(str, arm.joints))}"
        say(f"{figures['rows']:,} rows of {which} ({arm.form} observer, gain {k:g} "
            f"1/s{', adapted' if adapt else ''}) -> {output}")
        for j, f in figures["joints"].items():
            level = f"; level: scale {f['scale']:.4g}, offset {f['offset']:.4g} {arm.unit}" if adapt else ""
            moving = f"{f['friction_rms_moving']:.4g}" if f["friction_rms_moving"] is not None else "-"
            say(f"  {label(j)}: friction RMS error in motion {moving} {arm.unit}, contact rows {f['contact_rows']}"
                + level)
        for e in figures["events"]:
            end = f"{e['end']:.3f}" if e["end"] is not None else "end of log"
            say(f"  contact: {label(e['joint'])} from t = {e['start']:.3f} s to {end}, peak {e['peak']:.4g} "
                f"{arm.unit} at t = {e['peak_time']:.3f} s")
    if as_json:
        emit_json(figures | {"model": model, "log": log, "output": output, "gain": k, "adapt": adapt})


@cli.command("thresholds")
@click.argument("model", type=click.Path())
@click.argument("logs", nargs=-1, required=True, type=click.Path())
@click.option("-o", "--output", required=True, type=click.Path(), help="Output thresholds file (JSON).")
@urdf_option
@click.option("--gain", type=Number(min=0, min_open=True), default=None,
              help="Observer gain K [1/s] (time constant 1/K) of the replay the thresholds are calibrated on; "
                   "written into the file, where replay and export --observer take it from. Default: "
                   f"{observer.FAST_GAIN:g} for logs sampled every {1000 * observer.FAST_STEP:g} ms or faster, "
                   f"else {observer.DEFAULT_GAIN:g}.")
@click.option("--quantile", type=Number(min=0, max=1, min_open=True), default=observer.DEFAULT_QUANTILE,
              show_default=True, help="Quantile of |tau_ext_pred| over the logs' rows, per joint.")
@click.option("--margin", type=Number(min=0, min_open=True), default=observer.DEFAULT_MARGIN, show_default=True,
              help="Threshold = margin x that quantile.")
@click.option("--release", type=Number(min=0, max=1, min_open=True, max_open=True), default=observer.DEFAULT_RELEASE,
              show_default=True, help="A contact flag is released below this share of the threshold (hysteresis).")
@click.option("--moving-speed", type=Number(min=0, min_open=True), default=observer.DEFAULT_MOVING_SPEED, show_default=True,
              help="|qd| above which a joint moves [rad/s or m/s]: its threshold in motion applies, and the "
                   "adaptation may update.")
@click.option("--persistence", type=click.IntRange(min=1, max=observer.MAX_PERSISTENCE), default=observer.DEFAULT_PERSISTENCE, show_default=True,
              help="Samples in a row beyond the threshold, with one sign, before a contact is flagged (1: at once).")
@click.option("--no-level-share", "no_level", is_flag=True,
              help="A constant threshold in motion: leave out the share of the friction (the drift of its level).")
@robot_model_flags
@json_flag
@common
def thresholds_cmd(model, logs, output, urdf, gain, quantile, margin, release, moving_speed, persistence, no_level,
                   zero, as_json, quiet):
    """Calibrate per-joint contact thresholds from collision-free LOGS replayed with MODEL (the
    static observer, as fricli replay without --adapt): margin x quantile of |tau_ext_pred| per
    joint; in motion plus a share of the predicted friction, margin x quantile of how far the online
    adaptation moves the friction's scale on the LOGS (the drift of the friction level); the static friction band (the largest friction the model gives moving just above
    --moving-speed, up to 5 times it: at rest the estimate is the torque outside that band); and
    each joint's friction scale (the RMS of the model's friction in motion).

    \b
    Example:
      fricli thresholds models/ fit.parquet --urdf arm.urdf -o thresholds.json
    """
    from fricli.robot import replay

    thr = replay.calibrate_thresholds(model, list(logs), output, urdf=urdf, gain=gain, quantile=quantile,
                                      margin=margin, release=release, moving_speed=moving_speed,
                                      persistence=persistence, level_share=not no_level,
                                      **zero_keywords(zero))
    if not quiet:
        say(f"observer gain {thr.gain:g} 1/s (time constant {1000 / thr.gain:.3g} ms)")
        for j, value, share, band in zip(thr.joints, thr.threshold, thr.shares, thr.static_friction):
            say(f"  {label(j)}: threshold {value:.4g} + {share:.3g} x |tau_f_pred| in motion, static friction band "
                f"{band:.4g}")
        say(f"wrote {output}")
    if as_json:
        emit_json(thr.as_json())
