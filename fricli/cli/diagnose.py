"""fricli diagnose: which physical effect is a model missing on a log, and the fixed model."""

from __future__ import annotations

import os

import click

from fricli import models
from fricli.core import logs, modelset
from fricli.cli import cli
from fricli.cli.options import (common, emit_results, fit_joints, if_changed_option, json_flag, log_reading,
                                read_log, reading_kwargs, say)
from fricli.fitting.diagnosis import driver
from fricli.fitting.diagnosis import effects as E
from fricli.core.errors import OutputError


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
    who = f"joint {joint}: " if joint is not None else ""
    level = round(100 * driver.INTERVAL_LEVEL)
    if d.added:
        lo, hi = d.intervals["cut"]
        lines.append(f"held-out MAE {d.mae_before:.4g} {u} -> {d.mae_after:.4g} {u} ({100 * d.cut:.0f} % lower; "
                     f"{level} % interval {100 * lo:.0f} to {100 * hi:.0f} % over the {d.folds} folds) "
                     f"with {', '.join(d.added)}")
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
@click.option("--folds", type=click.IntRange(min=3, max=100), default=driver.DEFAULT_FOLDS, show_default=True,
              help="Contiguous folds over time for the held-out scores.")
@click.option("--min-gain", type=click.FloatRange(min=0, max=1, min_open=True), default=driver.DEFAULT_MIN_GAIN,
              show_default=True, help="Share of the remaining held-out squared residual an effect must remove.")
@click.option("--alpha", type=click.FloatRange(min=0, max=0.5, min_open=True), default=driver.DEFAULT_ALPHA,
              show_default=True, help="Significance level of the held-out improvement.")
@click.option("--effects", "only", default=None, callback=_effect_names, metavar="NAMES",
              help="Comma-separated candidate effects to test (default: all).")
@click.option("--max-effects", type=click.IntRange(min=0), default=None, help="Add at most this many effects.")
@click.option("--no-carry", is_flag=True,
              help="With --fix, keep every effect as an added term even when a LuGre base could carry it.")
@click.option("--accept-implausible", is_flag=True,
              help="Add effects whose fitted parameters are out of plausible range (e.g. a gravity scale "
                   "beyond +-30 %) instead of reporting them as suspicious.")
@log_reading
@if_changed_option
@json_flag
@common
def diagnose_cmd(model, log, fix, output, folds, min_gain, alpha, only, max_effects, no_carry, accept_implausible,
                 joint, kt, cutoff, drop_invalid, if_changed, as_json, quiet):
    """Find which physical effect MODEL is missing on LOG (- for stdin), and fix it.

    The residual (friction target minus the model's prediction) is tested against a library
    of candidate effects: position (gear ripple), temperature, drift (wear), direction
    (asymmetry), acceleration (inertia), gravity (the logged tau_g off by a factor), load
    (friction growing with |tau_g|), payload (a measured tau_ext loading the gear), quadrant
    (driving vs back-driven), velocity (curve shape), level, offset and column:NAME for any
    other numeric column. Gravity, acceleration and offset are errors of the robot model or
    the measurement, not friction, and are reported as such. Effects are scored on held-out
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
    and --fix -o DIR writes one fixed model per joint (docs/joints.md).

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
    if output:
        folder = os.path.dirname(os.path.abspath(output))
        if not os.path.isdir(folder):
            raise OutputError(f"cannot write {output}: folder {folder} does not exist")
    source = modelset.source(model)
    reading = reading_kwargs(None, kt, cutoff, drop_invalid)
    del reading["joint"]
    table_, digest = read_log(log)
    name = "stdin" if log == "-" else log
    pairs = modelset.paired(source, table_, name, joint)
    several = len(pairs) > 1

    def show(result, data, model_path) -> None:
        if not as_json:
            if several:
                click.echo(f"joint {data.joint} ({model_path}):")
            click.echo(table(result, data.units["qd"], data.units["q"], data.joint if several else None)
                       + ("\n" if several else ""))

    if fix:
        def report(made):
            show(made.diagnosis, made.data, made.base)
            _say_fixed(made, quiet)
            return made.diagnosis.to_json()

        results, folder_run = fit_joints("diagnose", log, output, report, if_changed=if_changed, quiet=quiet,
                                         source=source, read=(table_, digest))
    else:
        results, folder_run = {}, several

        from fricli.models import coupled

        def work(j):
            data = logs.from_table(table_, name=name, sha256=digest, joint=j, **reading)
            data.signals.update(coupled.partner_signals(table_, j, name, **reading))   # the coupling effect's
            base, meta = models.load(pairs[j])
            models.check_log(meta, data, pairs[j])
            results[j] = driver.diagnose(base, data, folds=folds, min_gain=min_gain, alpha=alpha, only=only,
                                         max_effects=max_effects, accept_implausible=accept_implausible)
            show(results[j], data, pairs[j])
            results[j] = results[j].to_json()

        modelset.each_joint(list(pairs), work, what="results")
    if as_json:
        emit_results(results, folder_run)


def _say_fixed(made, quiet: bool) -> None:
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
        say(f"wrote {made.output}: nothing added{held}, same predictions as {made.base}")
