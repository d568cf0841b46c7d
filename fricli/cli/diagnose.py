"""fricli diagnose: which physical effect is a model missing on a log, and the fixed model."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import (common, emit_json, if_changed_option, json_flag, log_reading, say, spec_option,
                                up_to_date_line, warn)
from fricli.core import errors
from fricli.fitting import optionspec
from fricli.fitting.diagnosis import driver
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.optionspec import OptionError
from fricli.robot import calibration as cb

_SPEC = {o.name: o for o in optionspec.diagnose_options()}


def _effect_names(ctx, param, value):
    if not value:
        return None
    names = [v.strip() for v in value.split(",") if v.strip()]
    known = set(E.NAMES) | {"column"}
    bad = [n for n in names if n not in known and not n.startswith("column:")]
    if bad:
        raise click.BadParameter(f"unknown effect {bad[0]!r} (choose from {', '.join(E.NAMES)}, column, column:NAME)")
    return names


def _gain(g: float, width: int) -> str:
    """A gain as a percentage, or "worse" at the clipped bottom (the effect at least doubles the residual)."""
    return f"{'worse':>{width + 1}}" if g <= driver.WORST_GAIN else f"{100 * g:>{width}.1f}%"


def table(d: driver.Diagnosis, v_unit: str = "rad/s", q_unit: str = "rad", joint=None) -> str:
    """The readable report printed on stdout without --json; ``joint`` (a multi-joint log's
    joint) names the joint on every summary line."""
    u = d.tau_unit
    lines = []
    who = errors.one_line(f"joint {joint}: ") if joint is not None else ""
    level = round(100 * driver.INTERVAL_LEVEL)
    if d.added:
        lo, hi = d.intervals["cut"]
        lines.append(f"held-out MAE {d.mae_before:.4g} {u} -> {d.mae_after:.4g} {u} ({100 * d.cut:.0f} % lower; "
                     f"{level} % interval {100 * lo:.0f} to {100 * hi:.0f} % over the {d.folds} folds) "
                     f"with {', '.join(d.added)}")
    elif d.declined:
        names = d.declined["effects"]
        lines.append(f"nothing added: {', '.join(names)} lower{'s' * (len(names) == 1)} the held-out squared error "
                     f"but not the held-out MAE ({d.mae_before:.4g} {u} -> {d.declined['mae_after']:.4g} {u}): a few "
                     f"large residuals drive {'it' if len(names) == 1 else 'them'}")
    else:
        lo, hi = d.intervals["mae_before"]
        lines.append(f"no missing effect found: nothing added (held-out MAE {d.mae_before:.4g} {u}, {level} % "
                     f"interval {lo:.4g} to {hi:.4g}; no candidate removes {100 * d.min_gain:g} % of the residual "
                     f"significantly)")
    for e in d.effects:
        if e.added and e.part == "model":
            lines.append(f"robot-model error, not friction: {e.name}: {e.summary}")
        if e.added and e.implausible:
            lines.append(f"implausible, applied as asked (--accept-implausible): {e.name}: {e.implausible}")
        if e.name in d.suspected:
            lines.append(f"suspicious, not added: {e.name}: {e.summary}: {e.implausible} "
                         f"(--accept-implausible adds it)")
    lines.extend(f"note: {n}" for n in d.notes)
    if d.unexplained is not None:
        lines.append(d.unexplained.line(u, v_unit, q_unit))
    lines = [who + line for line in lines]
    lines.append("")
    head = (f"{'rank':>4}  {'effect':<18} {'part':<8} {'gain':>7} {'of rest':>8}  {'signif.':<7}  {'added':<5}  "
            f"parameters")
    lines.append(head)
    order = {name: i + 1 for i, name in enumerate(d.added)}
    for rank, e in enumerate(d.effects, 1):
        added = str(order[e.name]) if e.name in order else "-"
        sig = "yes" if e.significant else "no"
        flag = " (implausible)" if e.implausible and e.name not in d.suspected and not e.added else ""
        lines.append(f"{rank:>4}  {e.name:<18} {e.part:<8} {_gain(e.gain, 6)} {_gain(e.step_gain, 7)}  "
                     f"{sig:<7}  {added:<5}  {e.summary}{flag}")
    for name, reason in d.skipped.items():
        lines.append(f"   -  {name:<18} not tested: {reason}")
    lines.append("")
    lines.append(f"gain: share of the model's squared residual an effect explains on held-out data ({d.folds} "
                 f"blocks over time); of rest: share of what the effects added before it left; part: friction, "
                 f"or model (an error of the robot model or the measurement); worse: the effect at least doubles "
                 f"the held-out residual")
    return "\n".join(lines)


@cli.command("diagnose")
@click.argument("model", type=click.Path())
@click.argument("log")
@click.option("--fix", is_flag=True, help="Write the model augmented with the added effects (needs -o).")
@click.option("-o", "--output", default=None,
              help="Augmented model file to write with --fix (.npz), or a folder for one per joint.")
@spec_option(_SPEC["folds"])
@spec_option(_SPEC["min_gain"])
@spec_option(_SPEC["alpha"])
@click.option("--effects", "only", default=None, callback=_effect_names, metavar=_SPEC["effects"].metavar,
              help=_SPEC["effects"].help)
@spec_option(_SPEC["max_effects"])
@spec_option(_SPEC["no_carry"])
@spec_option(_SPEC["accept_implausible"])
@click.option("--urdf", default=None, metavar="ROBOT.urdf",
              help="The URDF LOG's tau_g and tau_dyn came from (default: the one its import recorded), for the "
                   "robot-model check of a whole-arm log and --calibrate.")
@click.option("--calibrate", "calibrated", default=None, metavar="CAL.urdf",
              help="With --fix on a whole-arm log: calibrate the robot model (as fricli calibrate), write CAL.urdf "
                   "and its report, recompute tau_g and tau_dyn from it, refit each joint's friction model and "
                   "diagnose again.")
@click.option("--calibrate-friction", "calibrate_friction", type=click.Choice(["linear", "stribeck"]),
              default=None,
              help=f"The friction fitted with the robot model by --calibrate (as fricli calibrate --friction; "
                   f"default: {cb.LOOP_FRICTION}, so that a rise of the friction at low speed is not taken up by the "
                   "inertial parameters; each joint's friction model is refitted afterwards).")
@log_reading
@if_changed_option
@json_flag
@common
def diagnose_cmd(model, log, fix, output, folds, min_gain, alpha, only, max_effects, no_carry, accept_implausible,
                 urdf, calibrated, calibrate_friction, joint, kt, cutoff, drop_invalid, zero, window, if_changed,
                 as_json, quiet):
    """Find which physical effect MODEL is missing on LOG (- for stdin), and fix it.

    The residual (friction target minus the model's prediction) is tested against a library
    of candidate effects: position (gear ripple), temperature, drift (wear), direction
    (asymmetry), acceleration (inertia), gravity (the logged tau_g off by a factor), load
    (friction growing with |tau_g|), payload (a measured tau_ext loading the gear), quadrant
    (driving vs back-driven), velocity (curve shape), level, offset and column:NAME for any
    other numeric column. Gravity, acceleration and offset are errors of the robot model or
    the measurement, not friction, and are reported as such; on a whole-arm log imported with a
    URDF, gravity or acceleration errors on several joints are reported once as errors of the
    robot model, with the command that calibrates it and what that calibration changes, and
    --fix --calibrate CAL.urdf performs it before fixing the friction. Effects are scored on held-out
    blocks of the log, tested for significance and added one at a time while the next one
    still removes enough of the residual (docs/diagnose.md). An effect the log cannot identify
    (e.g. tau_g nearly constant) is not tested; one chosen with implausible parameters (a gravity
    scale beyond +-30 %, kc or kq beyond 1 Nm/Nm, a negative or huge inertia) is reported as
    suspicious and not added unless --accept-implausible. The ranked effects, their
    physical parameters, the held-out MAE before and after with an interval over the folds,
    and the structure left that no candidate explains go to stdout (a table, or JSON with
    --json). With --fix -o OUT.npz the model plus the added effects is written as one
    self-contained model file. Exit 0 (OK) whether or not something was found. MODEL may be a
    model folder: every joint of the log is diagnosed with its own model (a result per joint)
    and --fix -o DIR writes one fixed model per joint (docs/joints.md); a coupled group's model
    is diagnosed on each joint of its group, and --fix writes a fixed model per joint on top of
    the group's friction (docs/drives.md).

    \b
    Example:
      fricli diagnose lugre.npz warm.parquet
      fricli diagnose lugre.npz warm.parquet --fix -o lugre-fixed.npz --json
      fricli diagnose emps.npz emps.parquet --cutoff 100 --fix -o emps-fixed.npz
    """
    from fricli.arm_diagnosis import diagnose_arm

    if fix and not output:
        raise click.UsageError("--fix needs -o FILE.npz for the augmented model")
    if output and not fix:
        raise click.UsageError("-o is the augmented model written with --fix: add --fix")
    if output == "-":
        raise click.UsageError("--fix writes a model file: give -o FILE.npz, not -")
    if if_changed and not fix:
        raise click.UsageError("--if-changed applies to --fix (the model it writes)")
    if calibrated and not fix:
        raise click.UsageError("--calibrate applies to --fix (it recomputes the log before fixing the friction)")
    if calibrate_friction is not None and not calibrated:
        raise click.UsageError("--calibrate-friction applies to --calibrate")

    def show(item) -> None:
        if item.unchanged:
            say(up_to_date_line(item.output, item.digest, True), quiet)
            return
        if not as_json:
            units = item.data.units
            if item.several:
                click.echo(errors.one_line(f"joint {item.data.joint} ({item.model}"
                                           f"{', refitted on the recomputed log' if item.refitted else ''}):"))
            click.echo(table(item.diagnosis, units["qd"], units["q"], item.data.joint if item.several else None)
                       + ("\n" if item.several else ""))
        if item.made is not None:
            _say_fixed(item.made, quiet, item.refitted)

    try:
        run = diagnose_arm(model, log, output, calibrate=calibrated, urdf=urdf, friction=calibrate_friction,
                         if_changed=if_changed, folds=folds, min_gain=min_gain, alpha=alpha, effects=only,
                         max_effects=max_effects, no_carry=no_carry, accept_implausible=accept_implausible,
                         joint=joint, kt=kt, cutoff=cutoff, drop_invalid=drop_invalid,
                         no_gravity="tau_g" in zero, no_dynamics="tau_dyn" in zero, time_from=window.start,
                         time_until=window.stop, say=lambda line: say(line, quiet), warn=warn, done=show)
    except OptionError as exc:
        if exc.option in _USAGE:
            raise click.UsageError(_USAGE[exc.option]) from None
        raise
    if run.unchanged:
        click.get_current_context().exit(errors.UNCHANGED)
    if as_json:
        printed = run.to_json()
        if printed is not None:
            emit_json(printed)
    elif run.robot_model is not None:
        click.echo(run.robot_model["summary"])


# what diagnose_arm refuses, by the option it names, in the command's words
_USAGE = {"calibrate": "--calibrate needs a whole-arm log and a model folder (one model per joint)",
          "urdf": "--calibrate needs the URDF the log was imported with: give --urdf ROBOT.urdf"}


def _say_fixed(made, quiet: bool, refitted: bool = False) -> None:
    """The stderr line of a model written by --fix."""
    result, fixed, fit = made.diagnosis, made.model, made.summary
    if quiet:
        return
    base_kind = made.base_meta.get("kind")
    if result.added:
        carried = f"; carried by the LuGre parameters: {', '.join(fixed.carried)}" if fixed.carried else ""
        if fixed.errors:
            carried += f"; robot-model error terms, kept apart from friction: {', '.join(fixed.errors)}"
        if fixed.refitted:
            carried += f"; refitted with them: {', '.join(fixed.refitted)}"
        if result.suspected:
            carried += f"; not added, implausible: {', '.join(result.suspected)}"
        say(f"wrote {made.output}: {base_kind} + {', '.join(result.added)}{carried} "
            f"(in-sample MAE {fit['mae']:.4g} {result.tau_unit})")
    else:
        held = f" (not added, implausible: {', '.join(result.suspected)})" if result.suspected else ""
        same = f"{base_kind} refitted on the recomputed log" if refitted else f"same predictions as {made.base}"
        say(f"wrote {made.output}: nothing added{held}, {same}")
