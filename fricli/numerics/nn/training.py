"""Training a ``Network`` on the mean squared error with Adam: full batch or mini-batches.

The loss is L = mean((y - t)^2) over samples and outputs, on standardised data (see
``Standardizer``). ``Trainer.fit`` records the training and validation loss every
``eval_every`` steps and keeps the weights with the lowest validation loss (the training loss
when there is no validation set): full-batch Adam at lr 0.01 shows loss spikes, and the last
step is often not the best one.

Full-batch steps over 8192 samples or more split the columns into two fixed chunks that two
threads work on (numpy releases the GIL); their gradients are added in a fixed order, so the
result does not depend on the machine's core count. Everything is seeded through the
``numpy.random.Generator`` passed in.
"""

from __future__ import annotations

import math
import threading
from typing import Callable

import numpy as np

from fricli.core.errors import FitError
from fricli.numerics.nn.adam import Adam
from fricli.numerics.threads import single_threaded
from fricli.numerics.nn.network import Network

CHUNK_MIN = 8192          # full batches this large are split over two threads
EVAL_POINTS = 2000        # default number of loss records over a run given in steps
EVAL_CHUNK = 4096         # columns per pass of the validation loss (the order of its sum is fixed)
SCHEDULES = ("constant", "cosine")


class Standardizer:
    """Per-feature affine scaling z = (x - mean) / scale, fitted on (features, n) data.

    Features listed in ``keep`` are passed through unchanged (mean 0, scale 1); constant
    features get scale 1.
    """

    def __init__(self, keep: tuple[int, ...] = ()):
        self.keep = tuple(keep)

    def fit(self, x: np.ndarray) -> "Standardizer":
        x = np.asarray(x, dtype=np.float64)
        self.mean_ = x.mean(axis=1)
        scale = x.std(axis=1)
        scale[~(scale > 1e-12 * np.maximum(1.0, np.abs(self.mean_)))] = 1.0
        self.scale_ = scale
        for i in self.keep:
            self.mean_[i], self.scale_[i] = 0.0, 1.0
        return self

    @classmethod
    def from_arrays(cls, mean: np.ndarray, scale: np.ndarray) -> "Standardizer":
        out = cls()
        out.mean_ = np.asarray(mean, dtype=np.float64).reshape(-1)
        out.scale_ = np.asarray(scale, dtype=np.float64).reshape(-1)
        if out.mean_.shape != out.scale_.shape or not (out.scale_ > 0).all() or not np.isfinite(out.mean_).all():
            raise ValueError("standardisation arrays are damaged")
        return out

    def transform(self, x: np.ndarray, out: np.ndarray | None = None, dtype=np.float32) -> np.ndarray:
        """(features, n) -> standardised (features, n) in ``dtype`` (written into ``out`` if given)."""
        if out is None:
            out = np.empty(np.shape(x), dtype=dtype)
        for i in range(out.shape[0]):
            np.subtract(x[i], self.mean_[i], out=out[i], casting="same_kind")
            out[i] *= out.dtype.type(1.0 / self.scale_[i])
        return out

    def inverse(self, z: np.ndarray) -> np.ndarray:
        """Standardised (features, n) -> float64 in original units."""
        return np.asarray(z, dtype=np.float64) * self.scale_[:, None] + self.mean_[:, None]


class _Chunk:
    """One block of columns of a full batch, with its own buffers and gradient."""

    def __init__(self, net: Network, x: np.ndarray, t: np.ndarray):
        self.ws = net.workspace_for(x)
        self.t = np.ascontiguousarray(t, dtype=net.dtype)
        self.grad = np.empty_like(net.theta)


def _sse_and_grad(net: Network, ws, t: np.ndarray, grad: np.ndarray, scale: float) -> float:
    """Sum of squared errors on the samples in ``ws``; writes (scale / 2) * d(sse)/d(theta)
    into ``grad``. With scale = 2 / (n_total * n_out) that is the gradient of the mean squared error."""
    y = net.forward(ws)
    np.subtract(y, t, out=y)
    r = y.reshape(-1)
    sse = float(np.dot(r, r))
    y *= scale
    net.backward(ws, y, grad)
    return sse


class _Helper:
    """A thread that runs ``fn(arg)`` each time ``start`` is called; ``result`` waits for it.

    Two plain locks hand the work over and back: far cheaper per step than a thread pool's
    futures, which matters at a few hundred microseconds per step."""

    def __init__(self, fn: Callable, arg):
        self.fn, self.arg = fn, arg
        self._go, self._done = threading.Lock(), threading.Lock()
        self._go.acquire()
        self._done.acquire()
        self._value, self._error, self._closing = 0.0, None, False
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while True:
            self._go.acquire()
            if self._closing:
                return
            try:
                self._value, self._error = self.fn(self.arg), None
            except BaseException as exc:  # handed to the caller of result()
                self._error = exc
            self._done.release()

    def start(self) -> None:
        self._go.release()

    def result(self):
        self._done.acquire()
        if self._error is not None:
            raise self._error
        return self._value

    def close(self) -> None:
        self._closing = True
        self._go.release()
        self._thread.join()


class Evaluator:
    """Sum of squared errors of a network on a fixed data set, with its buffers kept between calls.

    Data sets larger than one chunk share one workspace, refilled chunk by chunk.
    """

    def __init__(self, net: Network, x: np.ndarray, t: np.ndarray, chunk: int = EVAL_CHUNK):
        self.net, self.x, self.t = net, x, t
        n = x.shape[1]
        self.cuts = list(range(0, n, chunk)) + [n]
        self.filled = len(self.cuts) == 2
        # the training pass's arithmetic (backward workspaces), not prediction's: which step
        # training keeps rests on these sums
        if self.filled:
            self.ws = {n: net.workspace_for(x, backward=True)}
        else:
            self.ws = {size: net.workspace(size, backward=True)
                       for size in {b - a for a, b in zip(self.cuts[:-1], self.cuts[1:])}}

    def sse(self) -> float:
        total = 0.0
        for a, b in zip(self.cuts[:-1], self.cuts[1:]):
            ws = self.ws[b - a]
            if not self.filled:
                ws.set_inputs(self.x[:, a:b])
            y = self.net.forward(ws)
            np.subtract(y, self.t[:, a:b], out=y)
            r = y.reshape(-1)
            total += float(np.dot(r, r))
        return total


def sse(net: Network, x: np.ndarray, t: np.ndarray) -> float:
    """Sum of squared errors of ``net`` on standardised inputs x (f, n) and targets t (n_out, n)."""
    return Evaluator(net, x, t).sse()


class Stopped(Exception):
    """A training stopped from outside (``Trainer``'s ``stop``)."""


class Trainer:
    """Adam on the mean squared error.

    steps       optimiser steps (full batch: passes over the data; mini-batch: batches)
    epochs      mini-batch only, instead of ``steps``: an epoch is one pass over a fresh random
                permutation of the training samples in floor(n / batch_size) batches of
                ``batch_size`` (the few samples left over wait for the next permutation)
    batch_size  0 = full batch
    eval_every  steps between loss records and best-weight checks (default: once per epoch,
                or so that a run has about 2000 records)
    on_eval     called as on_eval(step, total_steps, train_loss, val_loss) at every record;
                when it returns True, training ends there
    keep_best   False: without a validation set, the loss is not evaluated at records and the
                last weights stay (for a caller that keeps weights of its own choosing)
    patience    early stopping: after this many steps without the monitored loss (validation,
                else training) falling below (1 - min_delta) times its best, the learning rate
                is multiplied by ``lr_factor``, from the best weights so far, up to ``lr_drops``
                times; after one more such stretch training stops. None = run every step.
    stop        an event (``threading.Event``) checked at every step: once set, ``fit`` raises
                ``Stopped`` (a training run beside others that are being stopped)
    schedule    "constant": Adam at ``lr`` throughout; "cosine": the learning rate falls from
                ``lr`` to ``lr_final`` over the steps as lr_final + (lr - lr_final) (1 + cos(pi s / S)) / 2
    """

    def __init__(self, *, steps: int | None = None, epochs: int | None = None, lr: float = 0.01,
                 batch_size: int = 0, eval_every: int | None = None,
                 on_eval: Callable[[int, int, float, float | None], None] | None = None,
                 patience: int | None = None, min_delta: float = 1e-3, lr_drops: int = 0, lr_factor: float = 0.3,
                 schedule: str = "constant", lr_final: float = 0.0, stop=None, keep_best: bool = True):
        if steps is None and epochs is None:
            raise ValueError("give steps or epochs")
        if epochs is not None and batch_size <= 0:
            raise ValueError("epochs need a batch size")
        if schedule not in SCHEDULES:
            raise ValueError(f"unknown learning-rate schedule {schedule!r}")
        self.steps, self.epochs, self.lr = steps, epochs, lr
        self.batch_size, self.eval_every, self.on_eval = int(batch_size), eval_every, on_eval
        self.patience, self.min_delta, self.lr_drops, self.lr_factor = patience, min_delta, lr_drops, lr_factor
        self.schedule, self.lr_final = schedule, lr_final
        self.stop, self.keep_best = stop, keep_best

    def fit(self, net: Network, x: np.ndarray, t: np.ndarray, x_val: np.ndarray | None = None,
            t_val: np.ndarray | None = None, rng: np.random.Generator | None = None) -> "Trainer":
        """Train ``net`` in place on standardised float32 inputs x (f, n), targets t (n_out, n).

        Sets ``history_train_``, ``history_val_`` (loss records), ``best_step_``, ``best_loss_``,
        ``steps_`` and leaves the best weights in ``net``.
        """
        x = np.ascontiguousarray(x, dtype=net.dtype)
        t = np.ascontiguousarray(np.atleast_2d(t), dtype=net.dtype)
        n = x.shape[1]
        if n == 0:
            raise FitError("no training samples")
        has_val = x_val is not None and x_val.shape[1] > 0
        if has_val:
            x_val = np.ascontiguousarray(x_val, dtype=net.dtype)
            t_val = np.ascontiguousarray(np.atleast_2d(t_val), dtype=net.dtype)
        rng = rng if rng is not None else np.random.default_rng(0)
        mini = 0 < self.batch_size < n
        batch = self.batch_size if mini else n
        per_epoch = max(1, n // batch)
        total = self.steps if self.steps is not None else self.epochs * per_epoch
        every = self.eval_every or (per_epoch if self.epochs is not None else max(1, math.ceil(total / EVAL_POINTS)))
        opt = Adam(net.n_params, lr=self.lr, dtype=net.dtype)
        n_out = t.shape[0]
        best = net.theta.copy()
        best_loss, best_step = math.inf, 0
        hist_train, hist_val = [], []
        plateau = {"since": 0, "level": math.inf, "drops": 0, "stop": False}

        checking = has_val or self.keep_best
        checker = Evaluator(net, x_val, t_val) if has_val else Evaluator(net, x, t) if checking else None
        n_check = (x_val.shape[1] if has_val else n) * n_out

        def record(step: int, train_loss: float) -> None:
            nonlocal best_loss, best_step
            pick = checker.sse() / n_check if checking else train_loss
            val_loss = pick if has_val else None
            if not math.isfinite(pick):
                raise FitError(f"training diverged at step {step}: the loss is not finite (try a smaller --lr)")
            hist_train.append(train_loss)
            if has_val:
                hist_val.append(val_loss)
            if pick < best_loss:
                best_loss, best_step = pick, step
                if checking:
                    np.copyto(best, net.theta)
            if self.on_eval and self.on_eval(step, total, train_loss, val_loss) is True:
                plateau["stop"] = True
            if self.patience is not None:
                watch(step, pick)

        def watch(step: int, pick: float) -> None:
            if pick < plateau["level"] * (1.0 - self.min_delta):
                plateau["level"], plateau["since"] = pick, step
            elif step - plateau["since"] >= self.patience:
                if plateau["drops"] >= self.lr_drops:
                    plateau["stop"] = True
                    return
                plateau["drops"] += 1
                plateau["since"] = step
                opt.lr *= self.lr_factor
                if checking:
                    np.copyto(net.theta, best)

        acc = [0.0, 0]  # training loss summed since the last record, steps

        def step_done(step: int, loss: float, grad: np.ndarray) -> bool:
            """Apply the step; True when training should stop early."""
            self._check(loss, step)
            if self.stop is not None and self.stop.is_set():
                raise Stopped(f"stopped at step {step}")
            if cosine:
                opt.lr = self.lr_final + 0.5 * (self.lr - self.lr_final) * (1.0 + math.cos(math.pi * (step - 1) / total))
            opt.step(net.theta, grad)
            acc[0] += loss
            acc[1] += 1
            if step % every == 0 or step == total:
                record(step, acc[0] / acc[1])
                acc[0], acc[1] = 0.0, 0
                if plateau["stop"]:
                    ran[0] = step
                    return True
            return False

        ran = [total]
        cosine = self.schedule == "cosine"

        # overflow shows up as a non-finite loss, which stops training with a FitError
        with single_threaded(), np.errstate(over="ignore", invalid="ignore"):
            if mini:
                self._mini_batch(net, x, t, batch, per_epoch, total, rng, step_done)
            else:
                self._full_batch(net, x, t, total, step_done)
        if checking:
            np.copyto(net.theta, best)
        self.history_train_ = np.asarray(hist_train, dtype=np.float64)
        self.history_val_ = np.asarray(hist_val, dtype=np.float64)
        self.best_step_, self.best_loss_, self.steps_, self.eval_every_ = best_step, best_loss, ran[0], every
        self.lr_drops_ = plateau["drops"]
        return self

    @staticmethod
    def _check(loss: float, step: int) -> None:
        if not math.isfinite(loss):
            raise FitError(f"training diverged at step {step}: the loss is not finite (try a smaller --lr)")

    def _full_batch(self, net, x, t, total, step_done) -> None:
        n, n_out = x.shape[1], t.shape[0]
        scale = 2.0 / (n * n_out)
        n_chunks = 2 if n >= CHUNK_MIN else 1
        cuts = np.linspace(0, n, n_chunks + 1).astype(int)
        chunks = [_Chunk(net, x[:, a:b], t[:, a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
        grad = chunks[0].grad if n_chunks == 1 else np.empty_like(net.theta)

        def work(c: _Chunk) -> float:
            return _sse_and_grad(net, c.ws, c.t, c.grad, scale)

        helper = _Helper(work, chunks[1]) if n_chunks > 1 else None
        try:
            for step in range(1, total + 1):
                if helper is None:
                    loss = work(chunks[0])
                else:
                    helper.start()
                    loss = work(chunks[0])
                    loss += helper.result()
                    np.add(chunks[0].grad, chunks[1].grad, out=grad)
                if step_done(step, loss / (n * n_out), grad):
                    break
        finally:
            if helper is not None:
                helper.close()

    def _mini_batch(self, net, x, t, batch, per_epoch, total, rng, step_done) -> None:
        n, n_out = x.shape[1], t.shape[0]
        scale = 2.0 / (batch * n_out)
        ws = net.workspace(batch)
        tb = np.empty((n_out, batch), dtype=net.dtype)
        grad = np.empty_like(net.theta)
        perm = rng.permutation(n)
        for step in range(1, total + 1):
            j = (step - 1) % per_epoch
            if j == 0 and step > 1:
                perm = rng.permutation(n)
            idx = perm[j * batch:(j + 1) * batch]
            ws.take_inputs(x, idx)
            np.take(t, idx, axis=1, out=tb, mode="clip")
            if step_done(step, _sse_and_grad(net, ws, tb, grad, scale) / (batch * n_out), grad):
                break
