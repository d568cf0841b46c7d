"""fricli payload: the mass and centre of mass a whole-arm log's joints carry at a frame."""

from __future__ import annotations

import click

from fricli.cli.options import Number, common, emit_json, say, warn, window_options


@click.command("payload")
@click.argument("log")
@click.option("--frame", required=True, help="The URDF frame (link) that carries the payload, e.g. tool0.")
@click.option("--urdf", default=None, metavar="ROBOT.urdf",
              help="The robot description (default: the one the log was imported with).")
@click.option("--cutoff", type=Number(min=0, min_open=True), default=None,
              help="Low-pass cut-off [Hz] when qd/qdd are derived from the log (default: the log contract's 50).")
@click.option("--edge", type=Number(min=0), default=0.5, show_default=True,
              help="Seconds dropped at each end of the log (filter and difference transients in qdd).")
@click.option("--friction", type=click.Choice(["linear", "stribeck"]), default="linear", show_default=True,
              help="Each joint's friction fitted alongside: linear (Fv, Fc, offset) or stribeck (and the bump of "
                   "the LuGre static curve, as fricli calibrate --friction stribeck).")
@click.option("--json", "as_json", is_flag=True, help="Print the result as JSON on stdout.")
@window_options
@common
def payload_cmd(log, frame, urdf, cutoff, edge, friction, as_json, quiet, window):
    """Identify the payload at FRAME from a whole-arm log imported with a URDF.

    A point mass and its centre of mass in FRAME's coordinates are fitted to what the robot model
    leaves of tau_m, with each joint's friction alongside (rows in motion). A payload the
    import declared is left out of the model, so the whole payload is identified. Prints the
    import options that declare it. See docs/payload.md.

    \b
    Example:
      fricli payload loaded.parquet --frame tool0
      fricli import loaded.csv --mapping map.toml --urdf arm.urdf --payload-mass 2.47 --payload-com 0.03 0.17 0.05 --payload-frame tool0
    """
    from fricli.estimators import identify_payload

    found = identify_payload(log, frame, urdf=urdf, cutoff=cutoff, edge=edge, friction=friction,
                             time_from=window.start, time_until=window.stop, warn=warn)
    name = "stdin" if log == "-" else log
    for line in summary(found):
        say(line, quiet)
    if as_json:
        emit_json({"log": name, **found.report()})


def summary(found) -> list[str]:
    """The console lines of an identified payload."""
    from fricli.robot.payload import DETERMINED_COM, DETERMINED_MASS

    m, (sm, *sc) = found.mass, found.stderr
    verdict = found.verdict
    if verdict in ("payload", "undetermined"):
        com = ", ".join(f"{c:.4f}" for c in found.com)
        err = ", ".join(f"{s:.2g}" for s in sc)
        lines = [f"payload at {found.frame} on {found.rows:,} rows: mass {m:.4g} kg (standard error {sm:.2g}), "
                 f"centre of mass ({com}) m in {found.frame}'s frame (standard errors {err})"]
        if verdict == "undetermined":
            lines.append(f"not determined: the mass is not known to {100 * DETERMINED_MASS:g} % or the centre of mass "
                         f"to {DETERMINED_COM:g} m (one standard error): the log turns the payload through too little, "
                         "or the load is not a constant mass (a push, a cable); nothing to declare")
    elif verdict == "negative":
        lines = [f"no payload at {found.frame} on {found.rows:,} rows: mass {m:.3g} kg, {abs(m) / sm:.0f} standard "
                 f"errors ({sm:.2g}) below zero: a negative mass is no payload but a robot-model error the size of "
                 f"that mass at {found.frame} (link masses, drive gains): calibrate the robot model (fricli calibrate) "
                 "and look again"]
    else:
        lines = [f"no payload at {found.frame} on {found.rows:,} rows: mass {m:.3g} kg, within "
                 f"{payload_significance()} standard errors ({sm:.2g}) of zero"]
    lines.append(f"RMS of tau_m minus the robot model and {'linear' if found.vs is None else 'Stribeck'} friction [Nm], "
                 "without -> with the payload:")
    lines += [f"  joint {j}: held still, not used" if j in found.held else f"  joint {j}: {a:.4g} -> {b:.4g}"
              for j, a, b in zip(found.joints, found.rms_without, found.rms_with)]
    if verdict == "payload":
        lines.append(f"declare it: fricli import ... --payload-mass {m:.4g} --payload-com "
                     + " ".join(f"{c:.4g}" for c in found.com) + f" --payload-frame {found.frame}")
    return lines


def payload_significance() -> str:
    from fricli.robot.payload import SIGNIFICANCE

    return f"{SIGNIFICANCE:g}"
