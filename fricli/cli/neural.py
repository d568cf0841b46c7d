"""fricli train-base, fricli adapt."""

from __future__ import annotations

import time

import click

from fricli import learning, logs, models
from fricli.cli import cli
from fricli.cli.options import (common, emit_json, if_changed_option, json_flag, log_reading, model_job,
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


def _wrote(output: str) -> str:
    return "wrote the model to stdout" if output == "-" else f"wrote {output}"


@cli.command("train-base")
@click.argument("log")
@output_option()
@click.option("--arch", type=click.Choice(["mlp", "selmic", "nnacm"]), default="mlp", show_default=True,
              help="mlp: the paper's NN_base; selmic: Selmic & Lewis (sigmoid and jump units); "
                   "nnacm: Ciliz & Tomizuka (network plus learned Coulomb terms per direction).")
@click.option("--hidden", callback=_sizes, default=None, metavar="N[,N...]",
              help="Hidden layer sizes [default: mlp 30,30; selmic 30 (10 of them jump units); nnacm 50].")
@click.option("--schedule", type=click.Choice(list(learning.SCHEDULES)), default="cosine", show_default=True,
              help="cosine: Adam's learning rate falls from --lr to 0 along a cosine over 30,000 steps; "
                   "paper: the paper's constant learning rate for 50,000 steps.")
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Adam steps [default: 30,000 with --schedule cosine, 50,000 with paper].")
@click.option("--patience", type=click.IntRange(min=1), default=None, metavar="STEPS",
              help="Stop early when the validation loss has not improved by 0.1 % for STEPS steps.")
@click.option("--lr", type=click.FloatRange(min=0, min_open=True), default=0.01, show_default=True,
              help="Adam learning rate.")
@click.option("--batch-size", type=click.IntRange(min=0), default=0, show_default=True,
              help="Samples per step; 0 = full batch.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed for the row selection, the initial weights and the batches.")
@click.option("--val-fraction", type=click.FloatRange(min=0, max=0.9), default=0.2, show_default=True,
              help="Share of every constant-velocity stretch held out for validation, in whole pieces.")
@click.option("--no-balance", is_flag=True,
              help="Train on every row instead of the same number of rows per velocity level.")
@click.option("--max-samples", type=click.IntRange(min=10), default=learning.DEFAULT_MAX_SAMPLES, show_default=True,
              help="Rows kept after velocity balancing (training plus validation).")
@click.option("--velocity-input", type=click.Choice(learning.VELOCITY_INPUTS), default="asinh", show_default=True,
              help="asinh: the network sees asinh(qd / v0), which spreads the slow speeds apart; "
                   "linear: qd itself (the paper's input).")
@click.option("--velocity-scale", type=click.FloatRange(min=0, min_open=True), default=None, metavar="V0",
              help="v0 of --velocity-input asinh [rad/s or m/s]; default the 5 % quantile of the training "
                   "rows' speeds.")
@log_reading
@if_changed_option
@json_flag
@common
def train_base(log, output, arch, hidden, schedule, steps, patience, lr, batch_size, seed, val_fraction, no_balance, max_samples,
               velocity_input, velocity_scale, joint, kt, cutoff, drop_invalid, if_changed, as_json, quiet):
    """Train a neural friction model on LOG (tau_f = NN(tau_g, qd)) and write it to MODEL.npz.

    The target is the friction torque tau_m + tau_ext - tau_g - tau_dyn. By default the rows are
    balanced over the velocity levels of the log (a few thousand rows), whole stretches of every
    level are held out for validation, and the weights with the lowest validation loss are kept.
    The velocity enters the network as asinh(qd / v0) (v0 a low speed of the log, stored in the
    model), so slow speeds are resolved; --velocity-input linear gives the network qd itself.
    Adam's learning rate falls from --lr to 0 along a cosine over the steps (--schedule paper: the
    paper's constant rate for 50,000 steps). Training and validation MAE are printed at the end.
    The same seed gives the same file.

    \b
    Example:
      fricli train-base sample_data/joint2_base.parquet -o nn_base.npz
      fricli train-base sample_data/joint2_base.parquet --arch selmic -o selmic.npz
      fricli train-base sample_data/joint2_base.parquet --schedule paper -o nn_paper.npz
      fricli train-base base.parquet --steps 5000 --batch-size 256 --seed 3 -o quick.npz --json
    """
    _check_outputs(output, as_json)
    try:  # e.g. selmic needs one layer of more than 10 units (its jump units)
        learning.ARCHS[arch](hidden_sizes=tuple(hidden or learning.DEFAULT_HIDDEN[arch]))
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--hidden") from None
    the_log = logs.load_log(log, **reading_kwargs(joint, kt, cutoff, drop_invalid))
    options = {"arch": arch, "hidden": list(hidden or learning.DEFAULT_HIDDEN[arch]), "schedule": schedule,
               "steps": steps or learning.SCHEDULES[schedule][1], "patience": patience, "lr": lr,
               "batch_size": batch_size, "val_fraction": val_fraction, "balance": not no_balance,
               "max_samples": max_samples, "velocity_input": velocity_input}
    if velocity_scale is not None:
        options["velocity_scale"] = velocity_scale
    with model_job(output, the_log, if_changed=if_changed, quiet=quiet) as job:
        progress = _Progress(quiet, f"train-base {arch}")
        start = time.perf_counter()
        try:
            model, summary = learning.train_base(
                the_log, arch=arch, hidden=hidden, steps=steps, schedule=schedule, patience=patience, lr=lr, batch_size=batch_size, seed=seed,
                val_fraction=val_fraction, balance=not no_balance, max_samples=max_samples,
                velocity_input=velocity_input, velocity_scale=velocity_scale, on_eval=progress)
        finally:
            progress.close()
        seconds = time.perf_counter() - start
        rows = summary["train_rows"] + summary["val_rows"]
        models.save_for_log(output, model, the_log, rows_used=rows, seed=seed, fit=summary, options=options,
                            job=job)
    say(f"trained {arch} on {summary['train_rows']} rows ({summary['val_rows']} for validation, "
        f"{summary['groups']} velocity {'levels' if summary['velocity_groups'] == 'levels' else 'groups'}) "
        f"of {the_log.name} in {seconds:.1f} s; weights from step {summary['best_step']} of {summary['steps']}"
        f"{'' if summary['steps'] == summary['max_steps'] else ' (stopped early)'}", quiet)
    tau = the_log.units["tau"]
    say(f"friction MAE [{tau}]: training {_mae(summary, 'train')}, validation {_mae(summary, 'val')}; "
        f"moving rows of the log {_mae(summary, 'moving')}, all rows {_mae(summary, 'log')}", quiet)
    say(_wrote(output), quiet)
    if as_json:
        emit_json({"model": output, "kind": arch, "seconds": round(seconds, 3), **summary})


@cli.command("adapt")
@click.argument("base", type=click.Path(dir_okay=False))
@click.argument("log")
@output_option()
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
              help="Share of every stretch of motion held out for validation, in whole pieces.")
@click.option("--max-seconds", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Use only the first S seconds of LOG.")
@click.option("--min-speed", type=click.FloatRange(min=0), default=None,
              help="Leave out rows slower than this [rad/s or m/s]; default 2 % of the log's top speed.")
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
    with every command that takes a model.

    \b
    Example:
      fricli adapt nn_base.npz sample_data/joint2_adapt.parquet -o adapted.npz
      fricli adapt lugre.npz sample_data/joint2_adapt.parquet --max-seconds 40 -o lugre_adapted.npz
    """
    _check_outputs(output, as_json)
    kwargs = reading_kwargs(joint, kt, cutoff, drop_invalid)
    base_model, base_meta = models.load(base)
    table, digest = logs.read_table(log)
    if kwargs["joint"] is None and "joint" in table.column_names:
        kwargs["joint"] = base_meta.get("joint")
    the_log = logs.from_table(table, name="stdin" if log == "-" else log, sha256=digest, **kwargs)
    models.check_log(base_meta, the_log, base)
    options = {"hidden": hidden, "epochs": epochs, "batch_size": batch_size, "lr": lr, "val_fraction": val_fraction,
               "max_seconds": max_seconds, "min_speed": min_speed}
    with model_job(output, the_log, if_changed=if_changed, quiet=quiet, inputs={"base": base}) as job:
        progress = _Progress(quiet, "adapt")
        start = time.perf_counter()
        try:
            model, summary = learning.adapt(
                base_model, the_log, hidden=hidden, epochs=epochs, batch_size=batch_size, lr=lr, seed=seed,
                val_fraction=val_fraction, max_seconds=max_seconds, min_speed=min_speed, on_eval=progress)
        finally:
            progress.close()
        seconds = time.perf_counter() - start
        models.save_for_log(output, model, the_log, rows_used=summary["rows_used"], seed=seed, fit=summary,
                            options=options, job=job, base={"path": base, "kind": base_meta.get("kind"),
                                                   "provenance": base_meta.get("provenance", {})})
    tau = the_log.units["tau"]
    say(f"adapted {base_meta.get('kind')} model {base} on {summary['seconds_used']:.1f} s of {the_log.name} "
        f"({summary['train_rows']} training rows, {summary['val_rows']} validation) in {seconds:.1f} s", quiet)
    say(f"friction MAE [{tau}] on the moving rows: base {summary['base_moving']['mae']:.3f} -> adapted "
        f"{summary['moving']['mae']:.3f}; validation {_mae(summary, 'base_val')} -> {_mae(summary, 'val')}", quiet)
    say(_wrote(output), quiet)
    if as_json:
        emit_json({"model": output, "kind": "residual", "base": base, "seconds": round(seconds, 3), **summary})
