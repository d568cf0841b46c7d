"""Held-out scoring of networks: the number of training steps chosen on held-out rows or by
cross-validation over folds of time blocks, trainings run side by side, and adapt's check that
NN_add helps on held-out halves of the log (``cross_validate``)."""

from __future__ import annotations

import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import Callable

import numpy as np

from fricli.core.errors import DataError
from fricli.fitting import training_data
from fricli.models.base import FrictionModel
from fricli.numerics.nn.training import Stopped
from fricli.numerics import forked
from fricli.numerics.threads import single_threaded

# adapt keeps NN_add only when, trained on one half of the log's pieces and scored on the other
# half (both ways round), it lowers the RMS error by MIN_GAIN at least on each half, on the
# held-out rows slower than their median speed and on the faster ones, and the gain per piece is
# positive by SIGNIFICANCE standard errors (about 95 % one-sided over the ten pieces): a network
# fitted to pure noise moves the RMS by a fraction of a per cent, and a gain that only some pieces
# of the log show is not one that another run of the joint will show. The halves put every
# held-out row on the far side in time of all the rows its network was trained on, as another run
# is: a real joint's residual drifts over seconds (the friction level moves as the joint warms
# up), and held-out pieces between training pieces would share their error. A network whose gain
# shows on one side in time only fails on the other half. NN_add sees no velocity: a gain at some
# speeds only is a velocity dependence it turned into a level, which another run moving at other
# speeds does not share.
MIN_GAIN = 0.01
SIGNIFICANCE = 2.0
FOLDS = 2
# chosen_on_held_out's probe stops after this share of its steps without a better held-out loss
PATIENCE_SHARE = 0.25
# while the model waits for the probes it looks at their records every WAIT_POLL seconds; when
# none has recorded for PROBE_SILENCE seconds (a probe's process was killed) it trains on
WAIT_POLL = 0.001
PROBE_SILENCE = 60.0
_SNAPSHOTS = "__snapshots__"
WORKERS = 2   # trainings run side by side (numpy releases the GIL; each trains on one BLAS thread)


def subset(sig: dict[str, np.ndarray], rows: np.ndarray) -> dict[str, np.ndarray]:
    return {k: v[rows] for k, v in sig.items()}


def chosen_on_held_out(new_model: Callable[[int], FrictionModel], steps: int, sig: dict[str, np.ndarray],
                       target: np.ndarray, splits: list[tuple[np.ndarray, np.ndarray]], rng: np.random.Generator,
                       on_eval: Callable | None = None, meanwhile: Callable[[], None] | None = None
                       ) -> tuple[FrictionModel, list[FrictionModel], dict]:
    """One network on every row of ``splits`` (pairs (train, val) of indices into ``sig`` and
    ``target`` (n,) [Nm]) stopped at the step that probe networks, one per pair trained on its
    ``train`` rows, show best on their held-out rows ``val``, pooled.

    The probes (each in a child process of its own where ``forked`` can fork, else one after
    the other on a second of ``WORKERS`` threads) and the model train at once, with the same
    scales (those of every row), the same learning-rate schedule over ``steps`` and the same
    initial weights (generators of one seed drawn from ``rng``): the model is a probe's network
    trained on more rows, so the probes' best step carries over to it, early steps included.
    Their held-out losses are pooled as ``cross_validated_steps`` pools its folds' (weighted by
    the held-out rows, over the records every probe reached). A probe stops once its held-out
    loss has not improved by 0.1 % for its patience (the model's, else PATIENCE_SHARE of
    ``steps``); the model records its weights at every loss record, trains on until it has
    passed the pooled curve's best record and keeps the weights of that record. While the probes
    train it runs at most one record past the best they have shown so far and waits there for
    them (the cores go to the probes where their best comes early). Which weights
    are kept depends on the probes' losses alone, not on which training runs ahead; so do the
    model's recorded steps and training losses (up to the record kept).
    ``meanwhile`` (e.g. loading what the steps after training need) runs in this process after the
    model's training, while the probes train on (the model is the one that trains on the most
    rows; the probes train on for their patience).
    Returns (model, probes, summary): the probes stay fitted for the choices made on their
    held-out rows (the prior's share, the pre-sliding state); summary holds "step" (the step
    chosen), "held_out_rmse" [Nm] (the pooled curve's at that step) and "folds" (the probes).
    """
    rows = np.union1d(np.concatenate([train for train, _ in splits]), np.concatenate([val for _, val in splits]))
    model, probes = new_model(steps), [new_model(steps) for _ in splits]
    for probe in probes:
        probe.patience = probe.patience or max(1, round(PATIENCE_SHARE * steps))
    model.patience = None
    model.set_scales(subset(sig, rows), target[rows])
    seed = int(rng.integers(2 ** 63))
    stop = threading.Event()
    apart = forked.AVAILABLE
    progress = shared_progress(on_eval, steps if apart else (len(splits) + 1) * steps, 1 if apart else len(splits) + 1, stop)
    # the probes' held-out losses as they are recorded, in memory their processes share with this one
    k_probes, weights = len(splits), [val.size for _, val in splits]
    curves = forked.shared_zeros(k_probes * (steps + 1), np.float64).reshape(k_probes, steps + 1)
    counts, done = forked.shared_zeros(k_probes), forked.shared_zeros(k_probes)

    def pooled(length: int) -> np.ndarray:
        """The probes' held-out losses averaged, weighted by their held-out rows, over ``length`` records."""
        return np.average(curves[:, :length], axis=0, weights=weights)

    def fit_probe(k: int, report: Callable | None, halt) -> FrictionModel:
        def noted(step, total, train_loss, val_loss):
            curves[k, counts[k]] = val_loss
            counts[k] += 1
            if report is not None:
                report(step, total, train_loss, val_loss)
            # the pooled curve ends with the probe that ends first: no record beyond it is used
            ended = [int(counts[j]) for j in range(k_probes) if j != k and done[j]]
            return bool(ended and counts[k] >= min(ended))

        train, val = splits[k]
        try:
            probes[k].fit(subset(sig, train), target[train], subset(sig, val), target[val],
                          rng=np.random.default_rng(seed), scales_from=model, on_eval=noted, stop=halt,
                          snapshots=True)
        finally:   # a probe that failed no longer holds the model up (its error is raised after)
            done[k] = 1
        return probes[k]

    pooled_best = {"upto": 0, "record": -1, "loss": math.inf}

    def best_record(length: int) -> int:
        """The record of least pooled loss over the first ``length`` records (-1 for none): the
        records not looked at before are pooled and compared (the first least one, as argmin)."""
        upto = pooled_best["upto"]
        if length > upto:
            part = np.average(curves[:, upto:length], axis=0, weights=weights)
            k = int(np.argmin(part))
            if part[k] < pooled_best["loss"]:
                pooled_best.update(record=upto + k, loss=float(part[k]))
            pooled_best["upto"] = length
        return pooled_best["record"]

    def verdict() -> str:
        """"stop", "go" or "wait": what the model does after its latest record."""
        # the pooled curve ends with the shortest probe: once one has finished and the others
        # have recorded as many losses, its best record is known (the others train on for the
        # choices made on their own best weights)
        reached = int(counts.min())
        finished = done.astype(bool)
        if finished.any() and int(counts[finished].min()) == reached:
            return "stop" if len(model.snapshots_) > best_record(reached) else "go"
        # until then the model trains while it may be needed: up to one record past the best the
        # probes have shown so far; beyond, it waits for them to show a later best or to end
        # (on threads the probes train one after the other: before the last starts, the model goes on)
        if stop.is_set() or (reached == 0 and not apart):
            return "go"
        return "go" if len(model.snapshots_) <= best_record(reached) + 1 else "wait"

    heard = {"records": -1, "at": time.monotonic(), "silent": False, "shown": 0}

    def show(step: int, *rest) -> None:
        """Report progress: in processes the model's bar is the only one, and while the model waits
        it follows the probes (never back: the model's later steps may lie behind them)."""
        if apart:
            if step <= heard["shown"]:
                return
            heard["shown"] = step
        progress[-1](step, *rest)

    def model_report(step, total, *losses) -> bool:
        show(step, total, *losses)
        every = step // max(len(model.snapshots_), 1)   # steps per loss record
        while (now := verdict()) == "wait" and not heard["silent"]:
            if int(counts.sum()) != heard["records"]:
                heard.update(records=int(counts.sum()), at=time.monotonic())
                show(min(int(counts.min()) * every, total), total, *losses)
            elif time.monotonic() - heard["at"] > PROBE_SILENCE:   # a probe's process is gone: train on
                heard["silent"] = True
            time.sleep(WAIT_POLL)
        return now == "stop"

    fit_rows = partial(model.fit, subset(sig, rows), target[rows], rng=np.random.default_rng(seed),
                       scales_from=model, on_eval=model_report, snapshots=True, stop=stop)

    def fit_model():
        fitted = fit_rows()
        if meanwhile is not None:
            meanwhile()
        return fitted

    if apart:
        # each probe in a child process (see fricli.numerics.forked: threads would share one lock)
        parent = os.getpid()

        def beside_the_rest(k: int) -> list:
            if k == k_probes:
                fit_model()
                return []
            parcel, rest = forked.beside(lambda: _packed(fit_probe(k, None, forked.Orphaned(parent))),
                                         partial(beside_the_rest, k + 1))
            return [parcel, *rest]

        with single_threaded():
            probes = [_unpacked(type(model), parcel) for parcel in beside_the_rest(0)]
    else:
        run_parallel([lambda: [fit_probe(k, progress[k], stop) for k in range(k_probes)], fit_model], stop)
    curve = pooled(int(counts.min()))   # every probe has ended: the records all of them reached
    record = min(int(np.argmin(curve)), len(model.snapshots_) - 1)
    # every network at that record: the model, and the probes for the choices made on their rows
    for net, net_rows in ((model, rows), *((probe, train) for probe, (train, _) in zip(probes, splits))):
        net.net_.theta[...] = net.snapshots_[record]
        net.snapshots_ = None
        net.set_members([net.net_], sig["qd"][net_rows])   # the extrapolation from the weights kept
    model.best_step_ = min((record + 1) * model.eval_every_, steps)
    # how far the model and the probes ran past the records used depends on which process ran
    # ahead: what is kept depends on the probes' curves alone (the same bytes every run)
    model.history_train_ = np.asarray(model.history_train_)[:record + 1]
    model.steps_ = min(curve.size * model.eval_every_, steps)
    model.history_val_ = curve
    model.n_val_ = 0
    return model, probes, {"step": int(model.best_step_), "folds": len(probes),
                           "held_out_rmse": float(np.sqrt(curve[record])) * model.y_scale_}


def _packed(model: FrictionModel) -> tuple[dict, dict[str, np.ndarray]]:
    """A fitted model as (params, arrays) for ``forked.beside``, its weight snapshots included."""
    arrays = dict(model.get_arrays())
    if getattr(model, "snapshots_", None):
        arrays[_SNAPSHOTS] = np.stack(model.snapshots_)
    return model.get_params(), arrays


def _unpacked(cls, parcel: tuple[dict, dict[str, np.ndarray]]) -> FrictionModel:
    params, arrays = parcel
    snapshots = arrays.pop(_SNAPSHOTS, None)
    model = cls.from_parts(params, arrays, {})
    model.snapshots_ = [] if snapshots is None else list(snapshots)
    return model


def fitted_side_by_side(fits: list[Callable[[bool], FrictionModel]], stop: threading.Event) -> list[FrictionModel]:
    """Run the calls ``fits`` (``fit(here)`` fits a model and returns it; ``here`` False: in a
    forked child, which has no progress display and stops once its parent is gone: see
    ``apart``), two at a time: the first of each pair in a child process and the second in this
    one where ``forked`` can fork, else all on ``run_parallel``'s threads. The models, in order
    (those fitted in a child rebuilt from their parameters)."""
    if not forked.AVAILABLE:
        return run_parallel([partial(fit, True) for fit in fits], stop)
    done = []
    with single_threaded():
        for k, fit in enumerate(fits):
            if apart(k, len(fits)):   # with the next one, which runs here
                parcel, here = forked.beside(lambda f=fit: _packed(f(False)), partial(fits[k + 1], True))
                done += [_unpacked(type(here), parcel), here]
            elif not (k and apart(k - 1, len(fits))):
                done.append(fit(True))
    return done


def apart(k: int, n: int) -> bool:
    """Whether ``fitted_side_by_side`` runs the k-th of n fits in a child process."""
    return forked.AVAILABLE and k % 2 == 0 and k < n - 1


def run_parallel(tasks: list[Callable[[], object]], stop: threading.Event | None = None) -> list:
    """Run the calls ``tasks`` on ``WORKERS`` threads (BLAS pinned to one thread each, set from
    this thread); their results in order. numpy releases the GIL in its array work, so two
    trainings take about the time of one on two cores. When this thread is interrupted (Ctrl-C,
    SIGTERM) or a task fails, ``stop`` is set, which the tasks' progress callbacks
    (``shared_progress``) and trainers (``Trainer``'s ``stop``) turn into an exception, and the interruption
    is raised once every task has ended."""
    if len(tasks) <= 1:
        return [task() for task in tasks]
    with single_threaded(), ThreadPoolExecutor(max_workers=WORKERS) as pool:
        futures = [pool.submit(task) for task in tasks]
        try:
            return [f.result() for f in futures]
        except BaseException:
            if stop is not None:
                stop.set()
            for f in futures:
                f.cancel()
            raise


def shared_progress(on_eval: Callable | None, total: int, parts: int = 2,
                    stop: threading.Event | None = None) -> list[Callable]:
    """``parts`` progress callbacks for trainings that run at once: each reports the sum of the
    steps all of them have done, out of ``total``, through ``on_eval`` (None: no report; one call
    at a time), and raises ``Stopped`` once ``stop`` is set."""
    done, lock = [0] * parts, threading.Lock()

    def part(k: int) -> Callable:
        def report(step, _total, train_loss, val_loss):
            if stop is not None and stop.is_set():
                raise Stopped("stopped")
            if on_eval is not None:
                with lock:
                    done[k] = step
                    on_eval(sum(done), total, train_loss, val_loss)
        return report
    return [part(k) for k in range(parts)]


def cross_validated_steps(new_model: Callable[[int], FrictionModel], steps: int, sig: dict[str, np.ndarray],
                          target: np.ndarray, rows: np.ndarray, blocks: np.ndarray, folds: list[np.ndarray],
                          rng: np.random.Generator, on_eval: Callable | None = None, **fit_kwargs) -> dict:
    """The number of training steps, chosen on the mean validation curve of K networks.

    ``rows`` (sorted indices) are the rows to use, ``blocks`` (n,) the time block of every row
    and ``folds`` the blocks each fold holds out. Fold k fits ``new_model(steps)`` (with
    ``fit_kwargs``; a model whose validation loss is that of target / ``y_scale_``) on the rows
    outside its blocks, recording its validation loss; the curves, in Nm^2 and weighted by their
    validation rows, are pooled into the mean squared error over
    every held-out row, and the step of its least value is chosen. Returns "folds" (K), "step"
    (the step chosen), "record" (its index in the loss records), "held_out_rmse" [Nm] (the
    pooled curve's least value, rooted), "fold_best_steps" (each fold's own best step),
    "curve" (the pooled curve [Nm^2]), "models" (the K fitted models) and "held" (the blocks each
    of them held out).
    """
    splits = []
    for held in folds:
        is_val = np.isin(blocks[rows], held)
        train, val = rows[~is_val], rows[is_val]
        if train.size and val.size:
            splits.append((held, train, val))
    seeds = rng.spawn(len(splits))
    stop = threading.Event()
    n, parent = len(splits), os.getpid()
    here = sum(not apart(k, n) for k in range(n))
    progress = iter(shared_progress(on_eval, here * steps, here, stop))

    def fit(k: int, in_this_process: bool) -> FrictionModel:
        _, train, val = splits[k]
        return new_model(steps).fit(subset(sig, train), target[train], subset(sig, val), target[val], rng=seeds[k],
                                    on_eval=next(progress) if in_this_process else None,
                                    stop=stop if in_this_process else forked.Orphaned(parent), **fit_kwargs)

    fitted = fitted_side_by_side([partial(fit, k) for k in range(n)], stop)
    curves = [np.asarray(model.history_val_) * model.y_scale_ ** 2 for model in fitted]
    weights = [val.size for _, _, val in splits]
    held_out = [held for held, _, _ in splits]
    if not curves:
        raise DataError("no fold of time blocks holds both training and validation rows")
    length = min(c.size for c in curves)
    pooled = np.average([c[:length] for c in curves], axis=0, weights=weights)
    best = int(np.argmin(pooled))
    step = min((best + 1) * fitted[0].eval_every_, steps)
    return {"folds": len(fitted), "step": int(step), "record": best, "held_out_rmse": float(np.sqrt(pooled[best])),
            "fold_best_steps": [int(m.best_step_) for m in fitted], "curve": pooled, "models": fitted, "held": held_out}


def cross_validate(fit_predict: Callable, blocks: np.ndarray, target: np.ndarray, base_pred: np.ndarray,
                   speed: np.ndarray | None = None) -> dict:
    """Whether a residual model beats its base on rows it was not trained on.

    ``blocks`` (n,) int gives the piece 0..PIECES-1 of every usable row (-1: not used); the
    pieces fall into FOLDS = 2 folds, the first half of the pieces and the second, and
    ``fit_predict(train_rows)`` trains on the rows of one fold and returns the prediction (n,)
    [Nm] for every row, kept for the other fold. Returns the RMS [Nm] of base and adapted model
    over the held-out rows and the ratio of the two on each half ("half_ratios": the second
    half's, trained on the first, then the first half's); with ``speed`` (n,) [|qd|], the same
    ratio on the held-out rows slower than their median speed and on the others
    ("speed_ratios", slow then fast; none when all rows move at one speed); the mean and
    standard error of the per-piece gain in mean squared error [Nm^2], and "helps": the RMS
    falls by MIN_GAIN on each half and each speed half, and the mean gain exceeds SIGNIFICANCE
    standard errors (False when fewer than two pieces hold rows).
    """
    first = (blocks >= 0) & (blocks < training_data.PIECES // 2)
    second = blocks >= training_data.PIECES // 2
    pred = np.array(base_pred, dtype=np.float64)
    half_ratios = []
    for train, held in ((first, second), (second, first)):
        if train.any() and held.any():
            pred[held] = fit_predict(np.flatnonzero(train))[held]
            half_ratios.append(rms_ratio(target, pred, base_pred, held))
    rows = blocks >= 0
    speed_ratios = []
    if speed is not None and len(half_ratios) == FOLDS:
        slow = speed < np.median(speed[rows])
        if (rows & slow).any():
            speed_ratios = [rms_ratio(target, pred, base_pred, rows & part) for part in (slow, ~slow)]
    e_base, e_new = (target - base_pred)[rows], (target - pred)[rows]
    gains = np.array([np.mean(e_base[b] ** 2 - e_new[b] ** 2) for b in
                      (blocks[rows] == k for k in range(training_data.PIECES)) if b.any()])
    out = {"rows": int(rows.sum()), "pieces": int(gains.size), "folds": FOLDS, "helps": False}
    if gains.size < 2:
        return out
    base_rms, new_rms = float(np.sqrt(np.mean(e_base ** 2))), float(np.sqrt(np.mean(e_new ** 2)))
    mean, se = float(gains.mean()), float(gains.std(ddof=1) / np.sqrt(gains.size))
    return {**out, "base_rmse": base_rms, "adapted_rmse": new_rms, "half_ratios": half_ratios,
            "speed_ratios": speed_ratios, "gain_mean": mean, "gain_se": se,
            "helps": bool(len(half_ratios) == FOLDS and max(half_ratios + speed_ratios) <= 1.0 - MIN_GAIN
                          and mean > SIGNIFICANCE * se)}


def rms_ratio(target: np.ndarray, pred: np.ndarray, base_pred: np.ndarray, rows: np.ndarray) -> float:
    """RMS error of ``pred`` over that of ``base_pred`` on ``rows`` (bool (n,))."""
    new, old = np.mean((target - pred)[rows] ** 2), np.mean((target - base_pred)[rows] ** 2)
    return float(np.sqrt(new / old)) if old > 0 else (1.0 if new == 0 else np.inf)
