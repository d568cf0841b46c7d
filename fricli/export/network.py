"""C code of a dense network (``fricli.nn.Network``): layers, biases and activations.

``dense(net, name)`` defines ``static inline double <name>(const double *x)``: the network's
single output for the standardised inputs x (n_in inputs, then n_skip inputs that go straight
to the output layer), in double precision. Weights are function-local const tables (flat), stored
input-major so the compiler can vectorise over a layer's units. Activations are written by
the functions in ``ACTIVATIONS`` (C statements turning ``v`` into the unit's output), one per
activation name, mirroring ``fricli.nn.activations``.
"""

from __future__ import annotations

import numpy as np

from fricli.errors import ModelFileError
from fricli.export.c import array, num
from fricli.nn import activations as acts


def _elu(act, unit: str) -> str:
    # max(e^v - 1, v) as acts.ELU computes it; v > 0 gives v
    return "if (!(v > 0.0)) { const double e = exp(v) - 1.0; v = e > v ? e : v; }"


def _sigmoid(act, unit: str) -> str:
    clip = num(acts._SIGMOID_CLIP)
    return f"v = v < -{clip} ? -{clip} : (v > {clip} ? {clip} : v); v = 1.0 / (1.0 + exp(-v));"


def _jump(act, unit: str) -> str:
    # phi_k = s * s^(k-1), s = 1 - e^-max(v, 0); k per unit from the table K
    return "{ const double s_ = 1.0 - exp(-(v > 0.0 ? v : 0.0)); v = s_ * pow(s_, K[" + unit + "] - 1.0); }"


def _identity(act, unit: str) -> str:
    return ""


def _softplus(act, unit: str) -> str:
    # log(1 + e^v) without overflow: max(v, 0) + log1p(e^-|v|)
    return "v = (v > 0.0 ? v : 0.0) + log1p(exp(-fabs(v)));"


def _tanh(act, unit: str) -> str:
    return "v = tanh(v);"


ACTIVATIONS = {"elu": _elu, "sigmoid": _sigmoid, "jump": _jump, "identity": _identity,
               "softplus": _softplus, "tanh": _tanh}


def _parts(act, units: int) -> list[tuple[int, int, object]]:
    """(first unit, unit count, activation) groups of a layer."""
    groups = act.parts if isinstance(act, acts.Mixed) else [(units, act)]
    out, start = [], 0
    for n, part in groups:
        out.append((start, n, part))
        start += n
    return out


def _layer(i: int, w: np.ndarray, act, src: str, fan_in: int) -> list[str]:
    """C statements of hidden layer i: h<i>[units] from src[fan_in]; w (units, fan_in + 1)."""
    units = w.shape[0]
    table = np.vstack([w[:, :fan_in].T, w[:, fan_in]])   # input-major, bias last
    lines = [f"    static const double W{i}[{(fan_in + 1) * units}] = {array(table, 6)};",
             f"    double h{i}[{units}];",
             f"    for (j = 0; j < {units}; ++j) h{i}[j] = W{i}[{fan_in * units} + j];",
             f"    for (i = 0; i < {fan_in}; ++i)",
             f"        for (j = 0; j < {units}; ++j) h{i}[j] += W{i}[i * {units} + j] * {src}[i];"]
    for start, n, part in _parts(act, units):
        name = part.spec() if isinstance(part.spec(), str) else part.spec()["name"]
        if name not in ACTIVATIONS:
            raise ModelFileError(f"cannot export the activation {name!r} to C")
        code = ACTIVATIONS[name](part, f"j - {start}")
        if not code:
            continue
        if name == "jump":
            ks = np.broadcast_to(part.ks, (n,))
            lines.append(f"    {{ static const double K[{n}] = {array(ks, 10)};")
        else:
            lines.append("    {")
        lines += [f"    for (j = {start}; j < {start + n}; ++j) {{",
                  f"        double v = h{i}[j];", f"        {code}", f"        h{i}[j] = v;", "    } }"]
    return lines


def dense(net, name: str) -> str:
    """C definition of ``static inline double <name>(const double *x)`` for ``net``."""
    if net.n_out != 1:
        raise ModelFileError(f"cannot export a network with {net.n_out} outputs")
    weights = [np.asarray(w, dtype=np.float64) for w in net.weights]
    lines = [f"static inline double {name}(const double *x) {{", "    int i, j;", "    double y;"]
    src, fan_in = "x", net.n_in
    for i, ((units, act), w) in enumerate(zip(net.hidden, weights)):
        lines += _layer(i, w, act, src, fan_in)
        src, fan_in = f"h{i}", units
    last = weights[-1][0]
    lines += [f"    static const double WO[{len(last)}] = {array(last, 6)};",
              f"    y = WO[{fan_in}];",
              f"    for (i = 0; i < {fan_in}; ++i) y += WO[i] * {src}[i];"]
    for k in range(net.n_skip):
        lines.append(f"    y += WO[{fan_in + 1 + k}] * x[{net.n_in + k}];")
    if not net.hidden:
        pass
    lines += ["    (void)i; (void)j;", "    return y;", "}", ""]
    return "\n".join(lines)
