"""A network whose linear outputs pass through a fixed, differentiable head before the loss.

    raw = Network(x)                      (k, n)  the dense layers of ``fricli.numerics.nn.network``
    y   = head(raw, aux)                  (1, n)  elementwise, no trainable parameters

``aux`` are per-sample values the head needs besides the network's outputs (a smooth sign of
the velocity, the load); they ride along as extra input rows after the network's inputs, so
the trainer of ``fricli.numerics.nn.training`` batches them with the inputs and trains a
``HeadedNetwork`` like any ``Network``: ``forward`` returns y, ``backward`` takes dL/dy.

    dissipative  aux = (c, g), raw = (r0, r1):
                 y = c * (softplus(r0) + softplus(r1) g)
                 with c = tanh(qd / v_ps) in [-1, 1] and g = |tau_g| / g_scale >= 0, so
                 y qd >= 0 for every input and every weight.
"""

from __future__ import annotations

import numpy as np

from fricli.numerics.nn.network import Groups, Network, Workspace

_CLIP = 60.0


def _softplus(r: np.ndarray, sp: np.ndarray) -> None:
    """sp[:] = softplus(r) = max(r, 0) + log(1 + e^-|r|), no overflow for any r; in float32 with
    log(1 + x) for log1p(x) (several times faster, the same to float32 rounding of 1)."""
    np.abs(r, out=sp)
    np.negative(sp, out=sp)
    np.exp(sp, out=sp)                   # e^-|r|
    if sp.dtype == np.float64:
        np.log1p(sp, out=sp)
    else:
        sp += 1
        np.log(sp, out=sp)
    sp += np.maximum(r, 0)


def _sigmoid(r: np.ndarray, sig: np.ndarray) -> None:
    """sig[:] = sigmoid(r) = (1 + tanh(r / 2)) / 2, no overflow for any r."""
    np.multiply(r, 0.5, out=sig)
    np.tanh(sig, out=sig)
    sig += 1
    sig *= 0.5


class DissipativeHead:
    """y = c (softplus(r0) + softplus(r1) g); aux rows (c, g)."""

    name = "dissipative"
    n_raw, n_aux = 2, 2

    def forward(self, raw: np.ndarray, aux: np.ndarray, y: np.ndarray, fac: np.ndarray | None,
                tmp: np.ndarray) -> None:
        """y (1, n) from raw (2, n), aux (2, n); fac (2, n) gets dy/draw (None: values only);
        tmp (2, n) scratch."""
        _softplus(raw, tmp)
        c = aux[0]
        tmp[1:] *= aux[1:]                   # softplus(r1) g
        np.add(tmp[0], tmp[1], out=y[0])     # the magnitude, >= 0
        y[0] *= c
        if fac is not None:
            _sigmoid(raw, fac)
            fac[1:] *= aux[1:]
            fac *= c

    def spec(self) -> str:
        return self.name


HEADS = {DissipativeHead.name: DissipativeHead}


class HeadedWorkspace(Workspace):
    """A ``Workspace`` plus the head's buffers: aux (n_aux, n), out (1, n), fac, draw, tmp (n_raw, n);
    without ``backward`` (prediction) no fac: the head computes values only."""

    def __init__(self, net: "HeadedNetwork", n: int, backward: bool = True, groups: Groups | None = None):
        super().__init__(net, n, groups, backward)
        dt = net.dtype
        self.aux = np.empty((net.head.n_aux, n), dtype=dt)
        self.out = np.empty((1, n), dtype=dt)
        self.fac = np.empty((net.n_out, n), dtype=dt) if backward else None
        self.draw = np.empty((net.n_out, n), dtype=dt)
        self.tmp = np.empty((net.n_out, n), dtype=dt)

    def set_inputs(self, x: np.ndarray) -> None:
        """Copy inputs and aux rows (n_in + n_aux, n) into place."""
        self.x[...] = self.layer_columns(x[:self.n_in])
        self.aux[...] = x[self.n_in:]

    def take_inputs(self, x: np.ndarray, idx: np.ndarray) -> None:
        self._check_ungrouped()
        np.take(x[:self.n_in], idx, axis=1, out=self.x, mode="clip")
        np.take(x[self.n_in:], idx, axis=1, out=self.aux, mode="clip")


class HeadedNetwork(Network):
    """A dense ``Network`` with ``head.n_raw`` linear outputs followed by ``head``; one output.

    ``constant_outputs``: raw outputs that do not depend on the inputs, only on their bias (the
    weights from the last hidden layer to them start at 0 and get no gradient)."""

    def __init__(self, n_in: int, hidden, head, dtype=np.float32, constant_outputs=()):
        super().__init__(n_in, hidden, n_out=head.n_raw, n_skip=0, dtype=dtype)
        self.head = head
        self.constant_outputs = tuple(int(k) for k in constant_outputs)
        self.frozen = np.zeros(self.n_params, dtype=bool)
        for k in self.constant_outputs:
            self.views(self.frozen)[-1][k, :-1] = True
        self._frozen_at = np.flatnonzero(self.frozen)

    def init(self, rng: np.random.Generator) -> "HeadedNetwork":
        super().init(rng)
        self.theta[self.frozen] = 0
        return self

    def astype(self, dtype) -> "HeadedNetwork":
        """A copy computing in ``dtype`` (float32 weights are exact in float64)."""
        net = HeadedNetwork(self.n_in, self.hidden, self.head, dtype=dtype, constant_outputs=self.constant_outputs)
        net.theta[...] = self.theta
        return net

    @property
    def layer_rows(self) -> int:
        """The layers read the inputs; the aux rows after them go to the head, sample by sample."""
        return self.n_in

    def workspace(self, n: int, backward: bool = True, groups: Groups | None = None) -> HeadedWorkspace:
        return HeadedWorkspace(self, n, backward, groups)

    def forward(self, ws: HeadedWorkspace) -> np.ndarray:
        """y (1, n) for the inputs and aux rows already in ``ws``."""
        raw = super().forward(ws)
        self.head.forward(raw, ws.aux, ws.out, ws.fac, ws.tmp)
        return ws.out

    def backward(self, ws: HeadedWorkspace, dy: np.ndarray, grad: np.ndarray) -> None:
        np.multiply(ws.fac, dy, out=ws.draw)
        super().backward(ws, ws.draw, grad)
        if self.constant_outputs:
            grad[self._frozen_at] = 0

    @property
    def predict_rows(self) -> int:
        """The head returns one row, y (1, n); inputs and aux rows are (n_in + n_aux, n)."""
        return 1

    def spec(self) -> dict:
        return {**super().spec(), "head": self.head.spec(), "constant_outputs": list(self.constant_outputs)}
