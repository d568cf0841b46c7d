"""fricli train-base, fricli adapt."""

from __future__ import annotations

import time

import click

from fricli import learning, models, training_data
from fricli.cli import cli
from fricli.cli.options import (common, emit_results, fit_joints, if_changed_option, json_flag, log_reading,
                                output_option, progress_enabled, reading_kwargs, say)


def _sizes(_ctx, _param, value: str | None):
    if value is None:
        return None
    try:
        sizes = tuple(int(part) for part in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected layer sizes like 30,30, got {value!r}") from None
    if not sizes or min(sizes) < 1:
        raise click.BadParameter("layer sizes must be positive integers")
    return sizes


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


def _check_outputs(output: str, as_json: bool) -> None:
    if output == "-" and as_json:
        raise click.UsageError("-o - and --json both write to stdout: choose one")


def _rows_used(summary: dict, tau: str) -> str:
    """How train-base chose its rows, for its message."""
    mode, val = summary["velocity_groups"], summary["val_rows"]
    cv = summary.get("cross_validation")
    if mode == "moving" and cv is not None:
        return (f"rows in motion (the mean of {cv['folds']} networks, each validated on {summary['groups']} of "
                f"{training_data.PIECES} time blocks, held-out RMS {cv['held_out_rmse']:.3g} {tau}; "
                "no steady velocity levels in the log)")
    if mode == "moving":
        return (f"rows in motion ({val} for validation in {summary['groups']} of "
                f"{training_data.PIECES} time blocks; no steady velocity levels in the log)")
    return f"rows ({val} for validation, {summary['groups']} velocity {'levels' if mode == 'levels' else 'groups'})"


def _decision(summary: dict, tau: str) -> str:
    """adapt's verdict on its held-out rows, for its message."""
    held = summary.get("held_out")
    if held is None:
        return "no rows held out (--val-fraction 0): the residual network is kept unchecked"
    if "base_rmse" not in held:
        return "too few rows to hold out (fewer than two pieces of motion): the base model is kept"
    figures = (f"held out in {held['folds']} folds ({held['rows']:,} rows): RMS [{tau}] base "
               f"{held['base_rmse']:.3f}, adapted {held['adapted_rmse']:.3f}")
    if summary["adapted"]:
        return f"{figures}; the residual network is kept"
    return (f"{figures}; the residual network does not help consistently (by {100 * learning.MIN_GAIN:g} % "
            f"and in most pieces of the log): the base model is kept")


def _wrote(output: str) -> str:
    return "wrote the model to stdout" if output == "-" else f"wrote {output}"


@cli.command("train-base")
@click.argument("log")
@output_option(help="Model file to write (.npz; - for stdout), or a folder for one model per joint (docs/joints.md).")
@click.option("--arch", type=click.Choice(["dissipative", "mlp", "selmic", "nnacm"]), default="dissipative",
              show_default=True,
              help="dissipative: a non-negative magnitude of (speed, direction) and |tau_g| times a smooth "
                   "sign of qd, never along the motion (docs/neural-models.md); mlp: the paper's NN_base "
                   "NN(tau_g, qd); selmic: Selmic & Lewis (sigmoid and jump units); nnacm: Ciliz & Tomizuka "
                   "(network plus learned Coulomb terms per direction).")
@click.option("--hidden", callback=_sizes, default=None, metavar="N[,N...]",
              help="Hidden layer sizes [default: dissipative and mlp 30,30; selmic 30 (10 of them jump units); "
                   "nnacm 50].")
@click.option("--schedule", type=click.Choice(list(learning.SCHEDULES)), default="cosine", show_default=True,
              help="cosine: Adam's learning rate falls from --lr to 0 along a cosine over the steps; "
                   "paper: the paper's constant learning rate for 50,000 steps.")
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help=f"Adam steps [default: cosine {learning.COSINE_STEPS['dissipative']:,} for dissipative, "
                   f"{learning.SCHEDULES['cosine'][1]:,} for the others; paper {learning.SCHEDULES['paper'][1]:,}].")
@click.option("--patience", type=click.IntRange(min=1), default=None, metavar="STEPS",
              help="Stop early when the validation loss has not improved by 0.1 % for STEPS steps.")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), default=0.01, show_default=True,
              help="Adam learning rate.")
@click.option("--batch-size", type=click.IntRange(min=0), default=0, show_default=True,
              help="Samples per step; 0 = full batch.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed for the row selection, the initial weights and the batches.")
@click.option("--val-fraction", type=click.FloatRange(min=0, max=0.9), default=0.2, show_default=True,
              help="Share of every constant-velocity stretch held out for validation, in whole pieces "
                   "(a log without velocity levels: whole blocks of time).")
@click.option("--no-folds", is_flag=True,
              help="On a log without velocity levels, train one network validated on one fold of time blocks "
                   "instead of the mean of one network per fold (five times faster, more dependent on the seed).")
@click.option("--no-balance", is_flag=True,
              help="Train on every row instead of the same number of rows per velocity level.")
@click.option("--max-samples", type=click.IntRange(min=10), default=learning.DEFAULT_MAX_SAMPLES, show_default=True,
              help="Rows kept after velocity balancing (training plus validation).")
@click.option("--velocity-input", type=click.Choice(learning.VELOCITY_INPUTS), default="asinh", show_default=True,
              help="asinh: the network sees asinh(qd / v0), which spreads the slow speeds apart; "
                   "linear: qd itself (the paper's input; not for --arch dissipative).")
@click.option("--velocity-scale", type=click.FloatRange(min=0, min_open=True), default=None, metavar="V0",
              help="v0 of --velocity-input asinh [rad/s or m/s]; default the 5 % quantile of the training "
                   "rows' speeds.")
@log_reading
@if_changed_option
@json_flag
@common
def train_base(log, output, arch, hidden, schedule, steps, patience, lr, batch_size, seed, val_fraction, no_folds,
               no_balance, max_samples,
               velocity_input, velocity_scale, joint, kt, cutoff, drop_invalid, if_changed, as_json, quiet):
    """Train a neural friction model on LOG and write it to MODEL.npz.

    The default network (--arch dissipative) predicts tau_f = tanh(qd / v_ps) * m with a
    magnitude m >= 0 from the speed, the direction and |tau_g|, so it never predicts friction
    along the motion; --arch mlp is the paper's NN_base, tau_f = NN(tau_g, qd).

    The target is the friction torque tau_m + tau_ext - tau_g - tau_dyn. By default the rows are
    balanced over the velocity levels of the log (a few thousand rows), whole stretches of every
    level are held out for validation, and the weights with the lowest validation loss are kept.
    A log without velocity levels (continuous excitation, e.g. sums of harmonics) trains on its
    rows in motion instead and holds out whole blocks of time; stderr says which. There the
    dissipative network is the mean of five networks, each validated on other blocks, all
    stopped at the step of the least validation loss over every block.
    The velocity enters the network as asinh(qd / v0) (v0 a low speed of the log, stored in the
    model), so slow speeds are resolved; --velocity-input linear gives the network qd itself.
    Adam's learning rate falls from --lr to 0 along a cosine over the steps (--schedule paper: the
    paper's constant rate for 50,000 steps). Training and validation MAE are printed at the end.
    The same seed gives the same file. A log of several joints without --joint gives one model
    per joint in the folder -o DIR.

    \b
    Example:
      fricli train-base sample_data/joint2_base.parquet -o nn_base.npz
      fricli train-base sample_data/joint2_base.parquet --arch mlp -o paper_nn_base.npz
      fricli train-base sample_data/joint2_base.parquet --schedule paper -o nn_paper.npz
      fricli train-base base.parquet --steps 5000 --batch-size 256 --seed 3 -o quick.npz --json
    """
    _check_outputs(output, as_json)
    try:  # e.g. selmic needs one layer of more than 10 units (its jump units)
        learning.ARCHS[arch](hidden_sizes=tuple(hidden or learning.DEFAULT_HIDDEN[arch]))
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--hidden") from None
    if arch == "dissipative" and velocity_input != "asinh":
        raise click.BadParameter("the dissipative network always sees asinh(|qd| / v0); use --arch mlp",
                                 param_hint="--velocity-input")

    def fit_one(the_log, out, job, _model):
        progress = _Progress(quiet, f"train-base {arch}" + (f" joint {the_log.joint}" if the_log.joint is not None else ""))
        start = time.perf_counter()
        try:
            model, summary = learning.train_base(
                the_log, arch=arch, hidden=hidden, steps=steps, schedule=schedule, patience=patience, lr=lr, batch_size=batch_size, seed=seed,
                val_fraction=val_fraction, folds=not no_folds, balance=not no_balance, max_samples=max_samples,
                velocity_input=velocity_input, velocity_scale=velocity_scale, on_eval=progress)
        finally:
            progress.close()
        seconds = time.perf_counter() - start
        rows = summary["train_rows"] + summary["val_rows"]
        models.save_for_log(out, model, the_log, rows_used=rows, seed=seed, fit=summary, job=job)
        where = f" (joint {the_log.joint})" if the_log.joint is not None else ""
        rows_used = _rows_used(summary, the_log.units["tau"])
        say(f"trained {arch} on {summary['train_rows']} {rows_used} of {the_log.name}{where} in "
            f"{seconds:.1f} s; weights from step {summary['best_step']} of "
            f"{summary['steps']}{'' if summary['steps'] == summary['max_steps'] else ' (stopped early)'}", quiet)
        tau = the_log.units["tau"]
        say(f"friction MAE [{tau}]: training {_mae(summary, 'train')}, validation {_mae(summary, 'val')}; "
            f"moving rows of the log {_mae(summary, 'moving')}, all rows {_mae(summary, 'log')}", quiet)
        say(_wrote(out), quiet)
        return {"model": out, "kind": arch, "seconds": round(seconds, 3), **summary}

    results, folder_run = fit_joints(log, output, joint, reading_kwargs(joint, kt, cutoff, drop_invalid), fit_one,
                                     if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


@cli.command("adapt")
@click.argument("base", type=click.Path())
@click.argument("log")
@output_option(help="Model file to write (.npz; - for stdout), or a folder for one model per joint (docs/joints.md).")
@click.option("--hidden", type=click.IntRange(min=1), default=30, show_default=True,
              help="Units in NN_add's hidden layer (ELU).")
@click.option("--epochs", type=click.IntRange(min=1), default=200, show_default=True,
              help="Passes over the training rows, in random mini-batches.")
@click.option("--batch-size", type=click.IntRange(min=1), default=64, show_default=True,
              help="Rows per mini-batch (an epoch is floor(rows / batch size) steps).")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), default=0.01, show_default=True,
              help="Adam learning rate.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for the split, weights and batches.")
@click.option("--val-fraction", type=click.FloatRange(min=0, max=0.9), default=0.2, show_default=True,
              help="Share of every stretch of motion (a log without velocity levels: of the log's time) held "
                   "out for validation, in whole pieces; 0 also skips the held-out decision (NN_add kept unchecked).")
@click.option("--max-seconds", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Use only the first S seconds of LOG.")
@click.option("--min-speed", type=click.FloatRange(min=0), default=None,
              help="Leave out rows slower than this [rad/s or m/s]; default: the rows not in motion (slower "
                   "than 2 % of the log's top speed).")
@log_reading
@if_changed_option
@json_flag
@common
def adapt_cmd(base, log, output, hidden, epochs, batch_size, lr, seed, val_fraction, max_seconds, min_speed,
              joint, kt, cutoff, drop_invalid, if_changed, as_json, quiet):
    """Adapt BASE (any fricli model) to LOG by learning its residual: tau_f = base + NN_add(tau_g, sign(qd)).

    NN_add (one hidden layer of ELU units) is trained on the friction target minus BASE's
    prediction over LOG, typically one short movement out and back at one velocity without
    external load in the new conditions. The output holds BASE and NN_add together and works
    with every command that takes a model. Held-out rows decide (cross-validated over whole
    pieces of every stretch of motion; for a log without velocity levels, whole blocks of
    time): when NN_add does not lower the RMS error there consistently, the output is BASE
    unchanged (said on stderr, recorded in the file's fit as "adapted": false). BASE may be a model folder (one model per joint):
    on a log of several joints every joint is adapted into the folder -o DIR (docs/joints.md).

    \b
    Example:
      fricli adapt nn_base.npz sample_data/joint2_adapt.parquet -o adapted.npz
      fricli adapt lugre.npz sample_data/joint2_adapt.parquet --max-seconds 40 -o lugre_adapted.npz
    """
    _check_outputs(output, as_json)
    from fricli import modelset

    def fit_one(the_log, out, job, base_path):
        base_model, base_meta = models.load(base_path)
        models.check_log(base_meta, the_log, base_path)
        progress = _Progress(quiet, "adapt" + (f" joint {the_log.joint}" if the_log.joint is not None else ""))
        start = time.perf_counter()
        try:
            model, summary = learning.adapt(
                base_model, the_log, hidden=hidden, epochs=epochs, batch_size=batch_size, lr=lr, seed=seed,
                val_fraction=val_fraction, max_seconds=max_seconds, min_speed=min_speed, on_eval=progress,
                base_envelope=models.envelope(base_meta, base_path))
        finally:
            progress.close()
        seconds = time.perf_counter() - start
        models.save_for_log(out, model, the_log, rows_used=summary["rows_used"], seed=seed, fit=summary, job=job,
                            envelope=base_meta.get("envelope"),
                            base={"path": base_path, "kind": base_meta.get("kind"),
                                  "provenance": base_meta.get("provenance", {})})
        tau = the_log.units["tau"]
        where = f"joint {the_log.joint}; " if the_log.joint is not None else ""
        say(f"adapted {base_meta.get('kind')} model {base_path} on {summary['seconds_used']:.1f} s of "
            f"{the_log.name} ({where}{summary['train_rows']} training rows, {summary['val_rows']} validation) "
            f"in {seconds:.1f} s", quiet)
        say(f"friction MAE [{tau}] on the moving rows: base {summary['base_moving']['mae']:.3f} -> adapted "
            f"{summary['moving']['mae']:.3f}; validation {_mae(summary, 'base_val')} -> {_mae(summary, 'val')}",
            quiet)
        outside = summary.get("outside_base_envelope")
        if outside is not None:
            say(f"{100 * outside['share']:.1f} % of the rows used ({outside['rows']:,} of {outside['of']:,}) lie "
                "outside the base model's training envelope", quiet)
        say(_decision(summary, tau), quiet)
        say(_wrote(out) + ("" if summary["adapted"] else " (the base model unchanged)"), quiet)
        return {"model": out, "kind": model.kind, "base": base_path, "seconds": round(seconds, 3), **summary}

    results, folder_run = fit_joints(log, output, joint, reading_kwargs(joint, kt, cutoff, drop_invalid), fit_one,
                                     if_changed=if_changed, quiet=quiet, source=modelset.source(base),
                                     input_name="base")
    if as_json:
        emit_results(results, folder_run)
