"""fricli train-base, fricli adapt."""

from __future__ import annotations

import click

from fricli.fitting import learning, training_data
from fricli.cli import cli
from fricli.cli.options import (check_outputs, common, emit_results, fit_joints, if_changed_option, json_flag,
                                log_reading, output_option, progress_enabled, say, spec_options, warn, wrote)


class _Progress:
    """A tqdm bar over optimiser steps, fed by the trainer's loss records."""

    def __init__(self, quiet: bool, desc: str):
        self.enabled = progress_enabled(quiet)
        self.bar, self.desc, self.done = None, desc, 0

    def __call__(self, step: int, total: int, train_loss: float, val_loss: float | None) -> None:
        if not self.enabled:
            return
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=self.desc, unit="step", leave=False, mininterval=0.25)
        self.bar.update(step - self.done)
        self.done = step
        post = {"train": f"{train_loss:.3g}"}
        if val_loss is not None:
            post["val"] = f"{val_loss:.3g}"
        self.bar.set_postfix(post, refresh=False)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _mae(summary: dict, key: str) -> str:
    return f"{summary[key]['mae']:.3f}" if key in summary else "-"


def _rows_used(summary: dict, tau: str) -> str:
    """How train-base chose its rows, for its message."""
    mode, val = summary["velocity_groups"], summary["val_rows"]
    cv = summary.get("cross_validation")
    rows, why = (("steady rows", "velocity plateaus too close together to group by speed") if summary.get("plateaus")
                 else ("rows in motion", "no steady velocity levels in the log"))
    if mode == "moving" and cv is not None:
        return (f"{rows} (the mean of {cv['folds']} networks, each validated on {summary['groups']} of "
                f"{training_data.PIECES} time blocks, held-out RMS {cv['held_out_rmse']:.3g} {tau}; {why})")
    choice = summary.get("held_out_choice")
    if mode == "moving" and choice is not None:
        return (f"{rows} (one network on all of them, stopped at step {choice['step']:,}: the best on "
                f"the {training_data.PIECES} time blocks held out by halves from {choice['folds']} networks, "
                f"each trained on the other half, held-out RMS {choice['held_out_rmse']:.3g} {tau}; {why})")
    if mode == "moving":
        return (f"{rows} ({val} for validation in {summary['groups']} of "
                f"{training_data.PIECES} time blocks; {why})")
    return f"rows ({val} for validation, {summary['groups']} velocity {'levels' if mode == 'levels' else 'groups'})"


def _memory(memory: dict, tau: str) -> str:
    """train-base's choice of the Maxwell-slip elements, for its message."""
    if not memory["tested"]:
        return f"memory: {memory['why']}"
    figures = (f"held-out MAE [{tau}] over {memory['folds']} blocks of time: network {memory['mae_before']:.4g}, "
               f"with {sum(1 for k in memory['params'] if k.startswith('d'))} Maxwell-slip elements "
               f"{memory['mae_after']:.4g}")
    if memory["chosen"]:
        return (f"memory: {figures}; {memory['why']}; the model is the network with the elements (augmented; "
                f"moving rows MAE {memory['moving']['mae']:.3f})")
    return f"memory: {figures}; {memory['why']}; the model is the network alone"


def _decision(summary: dict, tau: str) -> str:
    """adapt's verdict on its held-out rows, for its message."""
    held = summary.get("held_out")
    if held is None:
        return "no rows held out (--val-fraction 0): the residual network is kept unchecked"
    if "base_rmse" not in held:
        return "too few rows to hold out (fewer than two pieces of motion): the base model is kept"
    figures = (f"held out in {held['folds']} folds ({held['rows']:,} rows): RMS [{tau}] base "
               f"{held['base_rmse']:.3f}, adapted {held['adapted_rmse']:.3f} "
               f"(each half x{', x'.join(f'{r:.3f}' for r in held['half_ratios'])}"
               + (f"; slower, faster half x{held['speed_ratios'][0]:.3f}, x{held['speed_ratios'][1]:.3f}"
                  if held.get("speed_ratios") else "") + ")")
    if summary["adapted"]:
        return f"{figures}; the residual network is kept"
    if held["adapted_rmse"] >= held["base_rmse"]:
        verdict = "makes the held-out rows worse"
    else:
        limit = 1.0 - learning.MIN_GAIN
        failed = [f"{name} x{r:.4f}" for name, r in zip(("later half", "earlier half", "slower half", "faster half"),
                                                       held["half_ratios"] + held.get("speed_ratios", []))
                  if r > limit]
        if not held["gain_mean"] > learning.SIGNIFICANCE * held["gain_se"]:
            failed.append(f"gain per piece {held['gain_mean'] / held['gain_se']:.2g} standard errors"
                          if held["gain_se"] > 0 else "no gain per piece")
        verdict = (f"does not help consistently (it must lower the RMS by {100 * learning.MIN_GAIN:g} % on each "
                   f"half in time and in speed, with a gain per piece above {learning.SIGNIFICANCE:g} standard "
                   f"errors; here {', '.join(failed)})")
    return f"{figures}; the residual network {verdict}: the base model is kept"


@cli.command("train-base")
@click.argument("log")
@output_option(help="Model file to write (.npz; - for stdout), or a folder for one model per joint (docs/joints.md).")
@spec_options("train-base")
@log_reading
@if_changed_option
@json_flag
@common
def train_base(log, output, arch, coupling, if_changed, as_json, quiet, window, **_options):
    """Train a neural friction model on LOG and write it to MODEL.npz.

    The default network (--arch dissipative) predicts tau_f = tanh(qd / v_ps) * m with a
    magnitude m >= 0 from the speed, the direction and |tau_g|, so it never predicts friction
    along the motion; --arch mlp is the paper's NN_base, tau_f = NN(tau_g, qd). By default
    (--bristles on) the dissipative network carries the LuGre model's bristle state with m as
    its steady state, so friction passes through zero over a small displacement at a reversal
    and holds at rest; --bristles off gives the static network. The magnitude is blended with the
    LuGre model's static curve (Stribeck, viscous and load terms) fitted on the same rows, the
    network's share chosen on the held-out rows, so the network corrects that curve only as far
    as rows it did not train on show it helps; --no-prior gives the network alone.

    The target is the friction torque tau_m + tau_ext - tau_g - tau_dyn. By default the rows are
    balanced over the velocity levels of the log (a few thousand rows), whole stretches of every
    level are held out for validation, and the weights with the lowest validation loss are kept.
    A log without velocity levels (continuous excitation, e.g. sums of harmonics) trains on its
    rows in motion instead and holds out whole blocks of time; stderr says which. There the
    dissipative network is one network on every row, stopped at the step that two probe networks,
    each trained on half of the time blocks, show best on the other half; their held-out rows
    also set the prior's share and the pre-sliding state (--ensemble N: the mean of N networks,
    one per fold of blocks).
    On such a log the network's residual is then tested for friction with memory: Maxwell-slip
    elements (fricli diagnose's hysteresis effect) are added on top of the network, as an
    augmented model, when on held-out blocks of time they lower the error significantly more than
    a change of level or a smooth correction in speed (--memory auto; on: always, where they stay
    physical; off: never); stderr and --json ("memory") say what was chosen and why.
    The velocity enters the network as asinh(qd / v0) (v0 a low speed of the log, stored in the
    model), so slow speeds are resolved; --velocity-input linear gives the network qd itself.
    Adam's learning rate falls from --lr to 0 along a cosine over the steps (--schedule paper: the
    paper's constant rate for 50,000 steps). Training and validation MAE are printed at the end.
    The same seed gives the same file. A log of several joints without --joint gives one model
    per joint in the folder -o DIR. With --coupling, each group of joints that share motors (the
    log's transmission) gets one model, DIR/joints_<a>_<b>.npz: a dissipative network per motor,
    of the motor's velocity, its friction mapped to the joints by R^T (docs/drives.md).

    \b
    Example:
      fricli train-base sample_data/joint2_base.parquet -o nn_base.npz
      fricli train-base sample_data/joint2_base.parquet --arch mlp -o paper_nn_base.npz
      fricli train-base sample_data/joint2_base.parquet --schedule paper -o nn_paper.npz
      fricli train-base base.parquet --steps 5000 --batch-size 256 --seed 3 -o quick.npz --json
      fricli train-base arm.parquet --coupling -o nn-arm/          # a network per motor of the wrist
    """
    check_outputs(output, as_json)

    def report(made):
        the_log, summary, out, seconds = made.data, made.summary, made.output, made.seconds
        where = f" (joint {the_log.joint})" if the_log.joint is not None else ""
        rows_used = _rows_used(summary, the_log.units["tau"])
        say(f"trained {arch} on {summary['train_rows']} {rows_used} of {the_log.name}{where} in "
            f"{seconds:.1f} s; weights from step {summary['best_step']} of "
            f"{summary['steps']}{'' if summary['steps'] == summary['max_steps'] else ' (stopped early)'}", quiet)
        tau = the_log.units["tau"]
        say(f"friction MAE [{tau}]: training {_mae(summary, 'train')}, validation {_mae(summary, 'val')}; "
            f"moving rows of the log {_mae(summary, 'moving')}, all rows {_mae(summary, 'log')}", quiet)
        if "memory" in summary:
            say(_memory(summary["memory"], tau), quiet)
        if summary["velocity_groups"] == "levels" and summary["groups"] < learning.MIN_VELOCITY_LEVELS:
            warn(f"warning: {the_log.name}{where}: the training rows hold {summary['groups']} velocity "
                 f"level{'s' if summary['groups'] != 1 else ''} (both directions counted): the model knows the "
                 "friction at those speeds only (below the slowest a dissipative network holds its level, above the "
                 "fastest it grows by its slope: fricli inspect); log constant-velocity motion at "
                 f"{learning.MIN_VELOCITY_LEVELS // 2} speeds or more each way for its velocity dependence")
        if summary["max_steps"] >= 100 and summary["best_step"] <= summary["max_steps"] // 100:
            warn(f"warning: {the_log.name}{where}: the validation error was least at step {summary['best_step']} "
                 f"of {summary['max_steps']}: training learned nothing the held-out rows confirm; the target may hold "
                 "what no friction of velocity and load gives (fricli diagnose says what)")
        say(wrote(out), quiet)
        return {"model": out, "kind": made.model.kind, "seconds": round(seconds, 3), **summary}

    def progress(data, motor=None):
        where = f" motor {motor + 1}" if motor is not None else (
            f" joint {data.joint}" if data.joint is not None else "")
        return _Progress(quiet, f"train-base {arch}{where}")

    def report_group(made, label):
        summary, model, tau = made.summary, made.model, made.data.units["tau"]
        say(f"trained a dissipative network per motor of joints {label} on {made.data.name} "
            f"({len(made.data):,} rows per joint) in {made.seconds:.1f} s", quiet)
        for i, motor in enumerate(summary["motors"]):
            say(f"  motor {i + 1}: {motor['train_rows']} {_rows_used(motor, tau)}; weights from step "
                f"{motor['best_step']} of {motor['steps']}; friction MAE [{tau}] training {_mae(motor, 'train')}, "
                f"validation {_mae(motor, 'val')}", quiet)
        for joint, errs in summary["moving"].items():
            say(f"friction MAE [{tau}], joint {joint}: moving rows {errs['mae']:.3f}, "
                f"all rows {summary['joints'][joint]['mae']:.3f}", quiet)
        say(wrote(made.output), quiet)
        return {"model": made.output, "log": made.data.name, "joints": list(model.joints), "kind": "coupled",
                "ratio": model.ratio.tolist(), "seconds": round(made.seconds, 3), **summary}

    results, folder_run = fit_joints("train-base", log, output, report, report_group=report_group, window=window,
                                     if_changed=if_changed, quiet=quiet, progress=progress)
    if as_json:
        emit_results(results, folder_run)


@cli.command("adapt")
@click.argument("base", type=click.Path())
@click.argument("log")
@output_option(help="Model file to write (.npz; - for stdout), or a folder for one model per joint (docs/joints.md).")
@spec_options("adapt")
@log_reading
@if_changed_option
@json_flag
@common
def adapt_cmd(base, log, output, if_changed, as_json, quiet, window, **_options):
    """Adapt BASE (any fricli model) to LOG by learning its residual: tau_f = base + NN_add(tau_g, sign(qd)).

    NN_add (ELU layers, --hidden; one of 30 units by default) is trained on the friction target minus BASE's
    prediction over LOG, typically one short movement out and back at one velocity without
    external load in the new conditions. The output holds BASE and NN_add together and works
    with every command that takes a model. Held-out rows decide (NN_add trained on the first half
    of every stretch of motion, scored on the second, and the other way round; for a log without
    velocity levels, the halves of its time): when NN_add does not lower the RMS error there
    consistently (by 1 % on each half, on the slower and the faster half of those rows, and in
    most pieces of the log), the output is BASE
    unchanged (said on stderr, recorded in the file's fit as "adapted": false). BASE may be a model folder (one model per joint):
    on a log of several joints every joint is adapted into the folder -o DIR (docs/joints.md). BASE
    may be a coupled group's model: each joint of its group (or --joint) gets NN_add on top of the
    group's friction, added to it (docs/drives.md).

    \b
    Example:
      fricli adapt nn_base.npz sample_data/joint2_adapt.parquet -o adapted.npz
      fricli adapt lugre.npz sample_data/joint2_adapt.parquet --max-seconds 40 -o lugre_adapted.npz
    """
    check_outputs(output, as_json)
    from fricli.core import modelset

    def report(made):
        the_log, summary, out, base_path = made.data, made.summary, made.output, made.base
        tau = the_log.units["tau"]
        where = f"joint {the_log.joint}; " if the_log.joint is not None else ""
        say(f"adapted {made.base_meta.get('kind')} model {base_path} on {summary['seconds_used']:.1f} s of "
            f"{the_log.name} ({where}{summary['train_rows']} training rows, {summary['val_rows']} validation) "
            f"in {made.seconds:.1f} s", quiet)
        say(f"friction MAE [{tau}] on the moving rows: base {summary['base_moving']['mae']:.3f} -> adapted "
            f"{summary['moving']['mae']:.3f}; validation {_mae(summary, 'base_val')} -> {_mae(summary, 'val')}",
            quiet)
        outside = summary.get("outside_base_envelope")
        if outside is not None:
            say(f"{100 * outside['share']:.1f} % of the rows used ({outside['rows']:,} of {outside['of']:,}) lie "
                "outside the base model's training envelope", quiet)
        say(_decision(summary, tau), quiet)
        if summary["seconds_used"] > learning.LONG_ADAPT_S:
            say(f"note: NN_add is made for under a minute of data and trains on every row of what it is given; "
                f"--max-seconds 60 adapts on the first minute of the {summary['seconds_used']:.0f} s, in a fraction "
                "of the time", quiet)
        say(wrote(out) + ("" if summary["adapted"] else " (the base model unchanged)"), quiet)
        return {"model": out, "kind": made.model.kind, "base": base_path, "seconds": round(made.seconds, 3),
                **summary}

    def progress(data):
        return _Progress(quiet, "adapt" + (f" joint {data.joint}" if data.joint is not None else ""))

    results, folder_run = fit_joints("adapt", log, output, report, window=window, if_changed=if_changed, quiet=quiet,
                                     source=modelset.source(base), progress=progress)
    if as_json:
        emit_results(results, folder_run)
