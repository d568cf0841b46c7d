"""fricli diagnose: which physical effect is a model missing on a log, and the fixed model."""

from __future__ import annotations

import os

import click

from fricli import models
from fricli.core import errors, logs, modelset
from fricli.cli import cli
from fricli.cli.options import (common, emit_json, emit_results, fit_joints, if_changed_option, json_flag,
                                log_reading, read_log, reading_kwargs, say, spec_option, warn)
from fricli.fitting.diagnosis import driver
from fricli.robot import calibration as cb
from fricli.fitting.diagnosis import effects as E
from fricli.core.errors import FricliError, ModelFileError, OutputError
from fricli.fitting import optionspec

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
    if output:
        folder = os.path.dirname(os.path.abspath(output))
        if not os.path.isdir(folder):
            raise OutputError(f"cannot write {output}: folder {folder} does not exist")
    source = modelset.source(model)
    reading = reading_kwargs(None, kt, cutoff, drop_invalid, zero)
    del reading["joint"]
    table_, digest = read_log(log, window)
    name = "stdin" if log == "-" else log
    pairs = modelset.paired(source, table_, name, joint)
    several = len(pairs) > 1

    if calibrated and not several:
        raise click.UsageError("--calibrate needs a whole-arm log and a model folder (one model per joint)")
    shared = [j for j, path in pairs.items() if list(pairs.values()).count(path) > 1]
    if calibrated and shared:
        raise ModelFileError(f"{model}: --calibrate refits each joint's model on the recomputed log, but joints "
                             f"{', '.join(map(str, shared))} share the model of their coupled group, which it does not "
                             "refit: leave --calibrate out, or give models of one joint each")

    def show(result, data, model_path) -> None:
        if not as_json:
            if several:
                click.echo(errors.one_line(f"joint {data.joint} ({model_path}):"))
            click.echo(table(result, data.units["qd"], data.units["q"], data.joint if several else None)
                       + ("\n" if several else ""))

    def report(made, refitted: bool = False):
        show(made.diagnosis, made.data, made.base + (", refitted on the recomputed log" if refitted else ""))
        _say_fixed(made, quiet, refitted)
        return made.diagnosis.to_json()

    def diagnose_all(table, echo: bool = True) -> dict:
        from fricli.models import coupled

        found = {}

        def work(j):
            data = logs.from_table(table, name=name, sha256=digest, joint=j, **reading)
            base, meta = models.load(pairs[j])
            base = coupled.view(base, j)
            coupled.add_partners(base, data, table, **reading)   # what the model reads (a group's member)
            data.signals.update(coupled.partner_signals(table, j, name, **reading))   # the coupling effect's
            models.check_log(meta, data, pairs[j])
            note = models.robot_model_note(meta, data, pairs[j])
            if note and echo:
                warn(note)
            result = driver.diagnose(base, data, folds=folds, min_gain=min_gain, alpha=alpha, only=only,
                                     max_effects=max_effects, accept_implausible=accept_implausible)
            if echo:
                show(result, data, pairs[j])
            found[j] = result.to_json()

        modelset.each_joint(list(pairs), work, what="results")
        return found

    robot = None
    if calibrated:
        opts = _calibrate_options(table_, urdf)
        if if_changed:
            _exit_if_up_to_date(log, output, opts, (table_, digest), source, window, quiet)
        before = diagnose_all(table_, echo=False)   # the tables printed are those after the calibration
        cal, table_ = _calibrate(table_, name, urdf, calibrated, cutoff, quiet,
                                 calibrate_friction or cb.LOOP_FRICTION)
        results, folder_run = fit_joints("diagnose", log, output, lambda made: report(made, refitted=True),
                                         window=window, if_changed=if_changed, quiet=quiet, source=source,
                                         read=(table_, digest), refit=True, opts=opts)
        robot = _calibrated_record(before, results, cal, calibrated)
    elif fix:
        results, folder_run = fit_joints("diagnose", log, output, report, window=window, if_changed=if_changed,
                                         quiet=quiet, source=source, read=(table_, digest))
    else:
        results, folder_run = diagnose_all(table_), several
    if several and robot is None:
        robot = _robot_model_check(results, table_, name, log, urdf, cutoff, quiet)
    if robot is not None and not as_json:
        click.echo(robot["summary"])
    if as_json:
        if robot is not None and folder_run:
            emit_json({"joints": {str(j): r for j, r in results.items()}, "robot_model": robot})
        else:
            emit_results(results, folder_run)


def _calibrate_options(table, urdf: str | None) -> dict:
    """diagnose's options for --fix --calibrate, with the sha256 of the URDF the robot model is
    calibrated from (an input of the models written, for --if-changed) when it is there."""
    from fricli.core import jobs
    from fricli.cli.options import command_options

    opts = command_options("diagnose")
    path = _urdf_of(table, urdf)
    if path is not None and os.path.isfile(path):
        opts["urdf_sha256"] = jobs.file_sha256(path)
    return opts


def _exit_if_up_to_date(log: str, output: str, opts: dict, read: tuple, source, window, quiet: bool) -> None:
    """--calibrate --if-changed: exit UNCHANGED before calibrating when every fixed model is up to date."""
    from fricli.cli.options import up_to_date_line
    from fricli.fitting import plan

    fresh = plan.up_to_date("diagnose", log, output, opts, read=read, inputs=source, window=window)
    if fresh is not None:
        for outcome in fresh.outcomes:
            say(up_to_date_line(outcome.output, outcome.digest, True), quiet)
        click.get_current_context().exit(errors.UNCHANGED)


def _urdf_of(table, urdf: str | None) -> str | None:
    """The URDF given, or the one the log's import recorded when it is still there."""
    if urdf:
        return urdf
    recorded = cb.recorded_urdf(table)
    return recorded if recorded and os.path.isfile(recorded) else None


def _calibrate(table, name: str, urdf: str | None, output: str, cutoff, quiet: bool, friction: str):
    """Calibrate the log's robot model, write OUTPUT and its report; the table recomputed from it."""
    path = _urdf_of(table, urdf)
    if path is None:
        raise click.UsageError("--calibrate needs the URDF the log was imported with: give --urdf ROBOT.urdf")
    say(f"calibrating the robot model of {path} on {name} ...", quiet)
    cal, text, new = cb.recalibrate(table, name, path, friction=friction,
                                    cutoff_hz=logs.DEFAULT_CUTOFF_HZ if cutoff is None else cutoff)
    cb.write(text, {"log": name, "urdf": path, "output": output, **cal.report}, output)
    for line in cb.warnings(cal.report):
        warn(f"warning: {line}")
    say(f"calibrated the robot model of {name} ({path}) -> {output}; tau_g and tau_dyn recomputed from it", quiet)
    return cal, new


def _fit_lines(cal, joints_: list) -> str:
    fit = cal.report["fit"]
    return ", ".join(f"joint {j} {fit[str(j)]['rms_before']:.3g} -> {fit[str(j)]['rms_after']:.3g} Nm"
                     for j in joints_ if str(j) in fit)


def _robot_model_check(results: dict, table, name: str, log: str, urdf: str | None, cutoff,
                       quiet: bool = False) -> dict | None:
    """Once per whole-arm log imported with a URDF: gravity or acceleration errors on several joints are the
    robot model's; the calibration that fixes them and, when the URDF is at hand, what it changes."""
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
    say(f"robot-model errors on joints {who}: calibrating the robot model on {name} to show what it changes ...",
        quiet)
    try:
        cal, _, _ = cb.recalibrate(table, name, path, friction=cb.LOOP_FRICTION,
                                   cutoff_hz=logs.DEFAULT_CUTOFF_HZ if cutoff is None else cutoff)
    except FricliError as exc:       # the check is advice: the diagnosis stands without it
        out["summary"] = f"{summary} (the calibration on this log fails: {exc})"
        return out
    out["fit"] = {j: cal.report["fit"][j] for j in out["joints"] if j in cal.report["fit"]}
    out["suspicious"] = cal.report["suspicious"]
    out["summary"] = (f"{summary}; RMS in motion of tau_m minus the robot model and {cb.LOOP_FRICTION} friction on this "
                      "log, CAD -> "
                      f"calibrated: {_fit_lines(cal, flagged)}; then --fix --calibrate CAL.urdf refits the friction "
                      "on it")
    return out


def _calibrated_record(before: dict, after: dict, cal, output: str) -> dict:
    """What --calibrate changed: per joint the held-out MAE with the CAD robot model and the friction model
    given -> with the calibrated robot model, its refitted friction and the added effects."""
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
