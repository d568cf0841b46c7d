"""Dense feed-forward networks in numpy, laid out for speed.

Data are stored features x samples (one column per sample). Every layer folds its bias into
the matrix product: its input buffer carries a constant row of ones, and its weight matrix
W_l of shape (units_out, units_in + 1) holds the bias in its last column.

    a_0 = [x; 1]
    h_l = W_l a_{l-1},   a_l = [f_l(h_l); 1]                 hidden layers l = 1..L
    y   = W_out [a_L; s]                                     linear output

``s`` are optional "skip" inputs that reach the output layer directly (e.g. the NNACM
direction terms). All weight matrices are views into one flat parameter vector ``theta``,
so an optimiser updates them all with a handful of vector operations, and the gradient
has the same layout. All buffers for a given number of samples live in a ``Workspace``,
allocated once and reused with ``out=``.

A workspace for fixed inputs (``Network.workspace_for``, as the trainer uses for a full batch)
computes samples whose layer inputs are bit-for-bit identical once: a log of constant-velocity
sweeps holds thousands of samples but only as many network inputs as speeds. The layers run on
the distinct columns, the outputs are copied out to every sample, and in ``backward`` the
samples' output gradients are summed per distinct column first; the loss and gradient are the
same sums, added in another order.
"""

from __future__ import annotations

import contextlib
import contextvars
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator

import numpy as np

from fricli.numerics.threads import single_threaded
from fricli.numerics.nn import activations as acts
from fricli.numerics.nn.activations import Activation

PREDICT_CHUNK = 16384     # columns per forward pass when predicting (fastest file to file on 2 cores: docs/performance.md)
REPEATS_WORTHWHILE = 0.5  # a fixed-input workspace groups samples when at most this share of columns is distinct
SMALL_PRODUCT = 1_000_000  # m n k of a matrix product up to which OpenBLAS runs its faster small-matrix kernels
_PREDICT_THREADS = contextvars.ContextVar("predict_threads", default=2)


@contextlib.contextmanager
def prediction_threads(n: int) -> Iterator[None]:
    """Within the block, ``predict_in_chunks`` runs on ``n`` threads (2 otherwise)."""
    token = _PREDICT_THREADS.set(int(n))
    try:
        yield
    finally:
        _PREDICT_THREADS.reset(token)


def predict_in_chunks(n: int, run: Callable[[list[tuple[int, int]]], None]) -> None:
    """Call ``run(part)`` over the (start, stop) pieces of PREDICT_CHUNK rows covering ``n`` rows,
    the pieces dealt alternately to ``prediction_threads`` threads (each with one BLAS thread, so
    results do not depend on the machine); ``run`` writes its pieces' results in place."""
    cuts = list(range(0, n, PREDICT_CHUNK)) + [n]
    pieces = list(zip(cuts[:-1], cuts[1:]))
    threads = max(1, _PREDICT_THREADS.get())
    with single_threaded():
        if threads == 1 or len(pieces) < 2 * threads:
            run(pieces)
        else:
            with ThreadPoolExecutor(max_workers=threads) as pool:
                list(pool.map(run, [pieces[i::threads] for i in range(threads)]))


def _check_units(n: int, act: Activation) -> None:
    """ValueError unless ``act`` fits a layer of ``n`` units (mixed parts, jump exponents):
    a damaged model file would otherwise fail later, inside a matrix product."""
    parts = act.parts if isinstance(act, acts.Mixed) else [(n, act)]
    if sum(m for m, _ in parts) != n:
        raise ValueError(f"a layer of {n} units has activations for {sum(m for m, _ in parts)}")
    for m, part in parts:
        if isinstance(part, acts.Jump) and part.ks.size not in (1, m):
            raise ValueError(f"{m} jump units have {part.ks.size} exponents")


class Network:
    """A dense network: ``n_in`` inputs, hidden layers [(units, Activation)], ``n_out`` linear
    outputs and ``n_skip`` inputs that go straight to the output layer."""

    def __init__(self, n_in: int, hidden: list[tuple[int, Activation]], n_out: int = 1, n_skip: int = 0,
                 dtype=np.float32):
        self.n_in, self.n_out, self.n_skip = int(n_in), int(n_out), int(n_skip)
        self.hidden = [(int(n), act) for n, act in hidden]
        for n, act in self.hidden:
            _check_units(n, act)
        self.dtype = np.dtype(dtype)
        sizes = [self.n_in] + [n for n, _ in self.hidden]
        self.shapes = [(sizes[i + 1], sizes[i] + 1) for i in range(len(self.hidden))]
        self.shapes.append((self.n_out, sizes[-1] + 1 + self.n_skip))
        self.n_params = sum(r * c for r, c in self.shapes)
        self.theta = np.zeros(self.n_params, dtype=self.dtype)
        self.weights = self.views(self.theta)

    # ------------------------------------------------------------------ parameters

    def views(self, flat: np.ndarray) -> list[np.ndarray]:
        """Weight-shaped views into a flat vector laid out like ``theta`` (e.g. a gradient)."""
        out, start = [], 0
        for r, c in self.shapes:
            out.append(flat[start:start + r * c].reshape(r, c))
            start += r * c
        return out

    def init(self, rng: np.random.Generator) -> "Network":
        """Weights and biases uniform in +-1/sqrt(fan_in) (the common default for dense layers)."""
        for w, (r, c) in zip(self.weights, self.shapes):
            bound = 1.0 / np.sqrt(c - 1) if c > 1 else 1.0
            w[...] = rng.uniform(-bound, bound, size=(r, c))
        return self

    def spec(self) -> dict:
        return {"n_in": self.n_in, "n_out": self.n_out, "n_skip": self.n_skip,
                "hidden": [[n, act.spec()] for n, act in self.hidden]}

    @classmethod
    def from_spec(cls, spec: dict, weights: list[np.ndarray] | None = None) -> "Network":
        net = cls(spec["n_in"], [(n, acts.from_spec(a)) for n, a in spec["hidden"]],
                  n_out=spec.get("n_out", 1), n_skip=spec.get("n_skip", 0))
        if weights is not None:
            net.set_weights(weights)
        return net

    def set_weights(self, weights: list[np.ndarray]) -> None:
        if len(weights) != len(self.shapes):
            raise ValueError(f"expected {len(self.shapes)} weight matrices, got {len(weights)}")
        for i, (w, shape) in enumerate(zip(weights, self.shapes)):
            w = np.asarray(w)
            if w.shape != shape:
                raise ValueError(f"weight matrix {i} has shape {w.shape}, expected {shape}")
            if not np.isfinite(w).all():
                raise ValueError(f"weight matrix {i} holds non-finite values")
            self.weights[i][...] = w

    def astype(self, dtype) -> "Network":
        """A copy computing in ``dtype`` (float32 weights are exact in float64)."""
        net = Network(self.n_in, self.hidden, n_out=self.n_out, n_skip=self.n_skip, dtype=dtype)
        net.theta[...] = self.theta
        return net

    # ------------------------------------------------------------------ computing

    @property
    def layer_rows(self) -> int:
        """Leading rows of the inputs ``set_inputs`` takes that the layers read (the rest, if any,
        are per-sample values for what follows the layers)."""
        return self.n_in + self.n_skip

    def workspace(self, n: int, backward: bool = True, groups: "Groups | None" = None) -> "Workspace":
        """Buffers for ``n`` samples (``backward``: also for ``backward``; a plain network's
        forward pass needs them all the same); ``groups``: the layers run once per group."""
        return Workspace(self, n, groups, backward)

    def workspace_for(self, x: np.ndarray, backward: bool = True) -> "Workspace":
        """A workspace holding the fixed inputs x (rows as ``set_inputs``, n), its layers run once
        per distinct column of x[:layer_rows] when that spares at least half of the columns."""
        groups = Groups.of(x[:self.layer_rows])
        if not 0 < groups.m <= REPEATS_WORTHWHILE * x.shape[1]:
            groups = None
        ws = self.workspace(x.shape[1], backward, groups)
        ws.set_inputs(x)
        return ws

    def forward(self, ws: "Workspace") -> np.ndarray:
        """Outputs (n_out, n) for the inputs already in ``ws.x`` (and ``ws.s``)."""
        if ws.part is None:
            self._layers(ws)
        else:   # values only: piece by piece through every layer, each piece's buffers in the cache
            for cols in ws.pieces:
                part = ws.part[cols.stop - cols.start]
                part.x[...] = ws.x[:, cols]
                if ws.s.shape[0]:
                    part.s[...] = ws.s[:, cols]
                ws.y_cols[:, cols] = self._layers(part)
        if ws.groups is not None:
            np.take(ws.y_cols, ws.groups.index, axis=1, out=ws.y)
        return ws.y

    def _layers(self, ws: "Workspace") -> np.ndarray:
        """The layers over the columns of ``ws``: ``ws.y_cols`` (n_out, cols)."""
        for (_, act), w, a, h, d, a_next in zip(self.hidden, self.weights, ws.a, ws.h, ws.d, ws.a[1:]):
            _product(w, a, h, ws.pieces)
            if ws.backward:
                act.forward(h, a_next[:h.shape[0]], d)
            else:
                act.value(h, a_next[:h.shape[0]], d)
        np.matmul(self.weights[-1], ws.a[-1], out=ws.y_cols)
        return ws.y_cols

    def backward(self, ws: "Workspace", dy: np.ndarray, grad: np.ndarray) -> None:
        """Write d(loss)/d(theta) into ``grad`` (flat, like theta), given dy = d(loss)/dy
        (n_out, n) after ``forward`` on the same workspace. ``dy`` may be ``ws.y``.

        With one output, the last hidden layer's gradient is w * (dy d) for the output weights
        w: ``g`` holds dy d, and w scales the small products made from it instead of g itself."""
        gw = ws.grad_views(grad)
        if ws.groups is not None:
            np.take(dy, ws.groups.order, axis=1, out=ws.dy_sorted)
            np.add.reduceat(ws.dy_sorted, ws.groups.starts, axis=1, out=ws.dy_cols)
            dy = ws.dy_cols
        upstream, row_scale = dy, None
        for i in range(len(self.weights) - 1, -1, -1):
            _gradient_product(upstream, ws.a[i], gw[i], ws.pieces)
            if row_scale is not None:
                gw[i] *= row_scale[:, None]
            if i == 0:
                break
            units = self.hidden[i - 1][0]
            g = ws.g[i - 1]
            if upstream.shape[0] == 1 and row_scale is None:
                np.multiply(ws.d[i - 1], upstream, out=g)
                row_scale = self.weights[i][0, :units]
            else:
                w = self.weights[i][:, :units]
                if row_scale is not None:
                    w = w * row_scale[:, None]
                    row_scale = None
                _product(w.T, upstream, g, ws.pieces)
                np.multiply(g, ws.d[i - 1], out=g)
            upstream = g

    def layer_inputs(self, x: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """The hidden layers' inputs [(units, m)] and the outputs (n_out, m) for the inputs x
        (n_in, m), in double precision whatever the network's (no skip inputs)."""
        a, pre = np.asarray(x, dtype=np.float64), []
        for (_, act), w in zip(self.hidden, self.weights):
            w = np.asarray(w, dtype=np.float64)
            h = w[:, :-1] @ a + w[:, -1:]
            pre.append(h)
            a = np.empty_like(h)
            act.value(h, a, np.empty_like(h))
        w = np.asarray(self.weights[-1], dtype=np.float64)
        return pre, w[:, :a.shape[0]] @ a + w[:, a.shape[0]:a.shape[0] + 1]

    def predict(self, x: np.ndarray, chunk: int = PREDICT_CHUNK) -> np.ndarray:
        """Outputs (n_out, n) for inputs ``x`` (n_in + n_skip, n), in chunks of ``chunk`` columns."""
        n = x.shape[1]
        out = np.empty((self.predict_rows, n), dtype=self.dtype)
        ws = None
        for start in range(0, n, chunk):
            stop = min(start + chunk, n)
            if ws is None or ws.n != stop - start:
                ws = self.workspace(stop - start, backward=False)
            ws.set_inputs(x[:, start:stop])
            out[:, start:stop] = self.forward(ws)
        return out

    @property
    def predict_rows(self) -> int:
        """Rows of what ``forward`` returns."""
        return self.n_out


def _product(w: np.ndarray, a: np.ndarray, out: np.ndarray, pieces: list[slice] | None) -> None:
    """out = w @ a, over the column ``pieces`` when the whole product is too large for the small-matrix
    kernels (each column of out is the same dot products: the same values to float32 rounding,
    the same bits where the BLAS orders a column's sum alike in both kernels)."""
    if pieces is None or w.shape[0] * w.shape[1] * a.shape[1] <= SMALL_PRODUCT:
        np.matmul(w, a, out=out)
    else:
        for cols in pieces:
            np.matmul(w, a[:, cols], out=out[:, cols])


def _gradient_product(g: np.ndarray, a: np.ndarray, out: np.ndarray, pieces: list[slice] | None) -> None:
    """out = g @ a.T, summed over the column ``pieces`` when the whole product is too large for the
    small-matrix kernels."""
    if pieces is None or g.shape[0] * a.shape[0] * a.shape[1] <= SMALL_PRODUCT:
        np.matmul(g, a.T, out=out)
    else:
        np.matmul(g[:, pieces[0]], a[:, pieces[0]].T, out=out)
        for cols in pieces[1:]:
            out += g[:, cols] @ a[:, cols].T


def column_pieces(net: "Network", cols: int) -> list[slice] | None:
    """Slices of ``cols`` columns, each small enough for the small-matrix kernels in every layer's
    product (in widths of a multiple of 256); None when no useful width exists."""
    width = SMALL_PRODUCT // max(r * c for r, c in net.shapes) // 256 * 256
    if width < 512 or cols <= width:
        return None
    return [slice(start, min(start + width, cols)) for start in range(0, cols, width)]


class Groups:
    """Samples grouped by identical columns of a (k, n) array, bit for bit: ``m`` groups,
    ``index`` (n,) each sample's group, ``first`` (m,) one sample of each group, ``order`` (n,)
    the samples sorted by group and ``starts`` (m,) where each group begins in that order."""

    def __init__(self, index: np.ndarray, first: np.ndarray):
        self.index, self.first, self.m = index, first, first.size
        self.order = np.argsort(index, kind="stable")
        self.starts = np.searchsorted(index[self.order], np.arange(self.m))

    @classmethod
    def of(cls, key: np.ndarray) -> "Groups":
        rows = np.ascontiguousarray(np.asarray(key).T)
        as_bytes = rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).reshape(-1)
        _, first, index = np.unique(as_bytes, return_index=True, return_inverse=True)
        return cls(index.reshape(-1).astype(np.intp), first)


class Workspace:
    """Every buffer a forward and backward pass over ``n`` samples needs; the layers work on
    ``cols`` columns: n, or one per group with ``groups``.

    a[l]  (units_l + 1 [+ n_skip], cols)  layer inputs, with the row of ones (skip rows last)
    h[l]  (units, cols)                   pre-activations of hidden layer l (one buffer for all l)
    d[l]  (units, cols)                   activation derivatives of hidden layer l (without
                                          ``backward``, scratch: forward computes values only)
    g[l]  (units, cols)                   back-propagated gradients of hidden layer l (g[l] shares
                                          h's buffer or a second one, alternately)
    y     (n_out, n)                      outputs (``y_cols`` (n_out, cols) before the copy-out)
    x, s  views of a[0] and of the skip rows, where inputs are written
    pieces  column slices the layers' large products run over (``column_pieces``), or None
    part  without ``backward``, when there are pieces: a workspace for each width of piece, that
          ``forward`` runs every layer on, piece by piece (else None)
    """

    def __init__(self, net: Network, n: int, groups: Groups | None = None, backward: bool = True):
        self.n, self.groups, self.backward = int(n), groups, backward
        cols = self.n if groups is None else groups.m
        dt = net.dtype
        rows = [net.n_in] + [units for units, _ in net.hidden]
        self.a = []
        for i, r in enumerate(rows):
            extra = net.n_skip if i == len(rows) - 1 else 0
            a = np.empty((r + 1 + extra, cols), dtype=dt)
            a[r] = 1
            self.a.append(a)
        # h and g of every layer in two buffers, so that a step's arrays stay in the cache: h is not
        # needed after the forward pass, and g[l] only until g[l - 1] is made from it
        units = [n for n, _ in net.hidden]
        first, second = (np.empty((max(units, default=0), cols), dtype=dt) for _ in range(2))
        self.h = [first[:n] for n in units]
        self.d = [np.empty((n, cols), dtype=dt) for n in units]
        self.g = [(second if (len(units) - 1 - l) % 2 == 0 else first)[:n] for l, n in enumerate(units)]
        self.y = np.empty((net.n_out, n), dtype=dt)
        self.y_cols = self.y
        if groups is not None:
            self.y_cols = np.empty((net.n_out, cols), dtype=dt)
            self.dy_cols = np.empty((net.n_out, cols), dtype=dt)
            self.dy_sorted = np.empty((net.n_out, n), dtype=dt)
        self.pieces = column_pieces(net, cols)
        # without backward the layers' buffers are needed one piece at a time: workspaces of a piece
        self.part = None if backward or self.pieces is None else {
            width: Workspace(net, width, backward=False) for width in {p.stop - p.start for p in self.pieces}}
        self.x = self.a[0][:net.n_in]
        self.s = self.a[-1][rows[-1] + 1:]
        self.n_in = net.n_in
        self._net, self._grad, self._grad_views = net, None, None

    def grad_views(self, grad: np.ndarray) -> list[np.ndarray]:
        """``net.views(grad)``, kept while the same gradient vector comes back."""
        if grad is not self._grad:
            self._grad, self._grad_views = grad, self._net.views(grad)
        return self._grad_views

    def _check_ungrouped(self) -> None:
        if self.groups is not None:
            raise ValueError("a workspace of grouped inputs holds fixed inputs: use a plain workspace")

    def layer_columns(self, x: np.ndarray) -> np.ndarray:
        """The columns of x (rows, n) the layers see: all, or one per group."""
        return x if self.groups is None else x[:, self.groups.first]

    def set_inputs(self, x: np.ndarray) -> None:
        """Copy inputs (n_in + n_skip, n) into place."""
        cols = self.layer_columns(x)
        self.x[...] = cols[:self.n_in]
        if self.s.shape[0]:
            self.s[...] = cols[self.n_in:]

    def take_inputs(self, x: np.ndarray, idx: np.ndarray) -> None:
        """Gather the columns ``idx`` (length n) of ``x`` (n_in + n_skip, N) into place (not for a
        workspace of fixed, grouped inputs)."""
        self._check_ungrouped()
        np.take(x[:self.n_in], idx, axis=1, out=self.x, mode="clip")
        if self.s.shape[0]:
            np.take(x[self.n_in:], idx, axis=1, out=self.s, mode="clip")
