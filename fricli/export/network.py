"""C code of a dense network (``fricli.nn.Network``): layers, biases and activations.

``dense(net, name)`` defines ``static inline double <name>(const double *x)``: the network's
single output for the standardised inputs x (n_in inputs, then n_skip inputs that go straight
to the output layer), in double precision. Weights are function-local const tables (flat), stored
input-major so the compiler can vectorise over a layer's units. Activations are written by
the functions in ``ACTIVATIONS`` (C statements turning ``v`` into the unit's output), one per
activation name, mirroring ``fricli.nn.activations``.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.errors import ModelFileError
from fricli.export.c import array, num
from fricli.nn import activations as acts


EXP_TABLE = 256    # e^u = 2^(-m/256) e^r: table of 2^(-j/256) and of 2^-q
EXP_DEGREE = 4     # Taylor polynomial of e^r, |r| <= ln2/512: error below 4e-17


def _exp_tables() -> list[str]:
    """Tables for ``_elu``: 2^(-j/256) for j < 256, and 2^-q for q up to 40 / ln2."""
    top = int(40.0 / math.log(2.0)) + 2
    fractions = [2.0 ** (-j / EXP_TABLE) for j in range(EXP_TABLE)]
    return [f"    static const double EXP_T[{EXP_TABLE}] = {array(fractions, 4)};",
            f"    static const double EXP_P[{top}] = {array([2.0 ** -q for q in range(top)], 4)};"]


def _elu(act, unit: str) -> str:
    """max(e^u - 1, v) with u = min(v, 0), as acts.ELU computes it, without a branch (the sign of
    a unit's input is unpredictable) or a library call: u clamped at -40 (below, e^u - 1 rounds
    to -1 all the same), u = -(m/256) ln2 + r with |r| <= ln2/512, e^u = 2^-(m/256) (tables) times
    the Taylor polynomial of e^r of degree 4: relative error about 1e-16."""
    shift = EXP_TABLE.bit_length() - 1
    return ("{ double u_ = v < 0.0 ? v : 0.0; u_ = u_ > -40.0 ? u_ : -40.0; "
            f"const int m_ = (int)(-u_ * {num(EXP_TABLE / math.log(2.0))} + 0.5); "
            f"const double r_ = (u_ + m_ * {num(_LN2_HI)}) + m_ * {num(_LN2_LO)}; "
            f"const double e = EXP_P[m_ >> {shift}] * (EXP_T[m_ & {EXP_TABLE - 1}] * {_taylor('r_', EXP_DEGREE)}) - 1.0; "
            "v = e > v ? e : v; }")


def _taylor(r: str, degree: int = 6) -> str:
    poly = num(1.0 / math.factorial(degree))
    for k in range(degree - 1, -1, -1):
        poly = f"({poly} * {r} + {num(1.0 / math.factorial(k))})"
    return poly


def _split(x: float, zero_bits: int = 16) -> tuple[float, float]:
    """x = hi + lo with the low ``zero_bits`` bits of hi's significand zero (m * hi is exact)."""
    bits = np.array(x, dtype=np.float64).view(np.int64) & ~np.int64((1 << zero_bits) - 1)
    hi = float(bits.view(np.float64))
    return hi, x - hi


_LN2_HI, _LN2_LO = _split(math.log(2.0) / EXP_TABLE)


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


BLOCK = 30   # units whose sums a layer accumulates together (in registers: 15 SSE2 pairs)

ACTIVATIONS = {"elu": _elu, "sigmoid": _sigmoid, "jump": _jump, "identity": _identity,
               "softplus": _softplus, "tanh": _tanh}


def _uses(act, name: str) -> bool:
    parts = act.parts if isinstance(act, acts.Mixed) else [(0, act)]
    return any((p.spec() if isinstance(p.spec(), str) else p.spec()["name"]) == name for _, p in parts)


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
             f"    double h{i}[{units}];"]
    for b in range(0, units, BLOCK):          # BLOCK units at a time, their sums in registers
        m = min(BLOCK, units - b)
        acc = [f"a{k}" for k in range(m)]
        lines += ["    {",
                  "        double " + ", ".join(f"{a} = W{i}[{fan_in * units + b + k}]"
                                                 for k, a in enumerate(acc)) + ";",
                  f"        for (i = 0; i < {fan_in}; ++i) {{",
                  f"            const double xi = {src}[i];",
                  f"            const double *w = W{i} + i * {units} + {b};",
                  *[f"            {a} += w[{k}] * xi;" for k, a in enumerate(acc)],
                  "        }",
                  *[f"        h{i}[{b + k}] = {a};" for k, a in enumerate(acc)],
                  "    }"]
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


def dense(net, name: str, output: int | None = None) -> str:
    """C definition of ``static inline double <name>(const double *x)`` for ``net``: its single
    output, or output number ``output`` of several."""
    if output is None and net.n_out != 1:
        raise ModelFileError(f"cannot export a network with {net.n_out} outputs")
    weights = [np.asarray(w, dtype=np.float64) for w in net.weights]
    lines = [f"static inline double {name}(const double *x) {{", "    int i, j;", "    double y;"]
    if any(_uses(act, "elu") for _, act in net.hidden):
        lines += _exp_tables()
    src, fan_in = "x", net.n_in
    for i, ((units, act), w) in enumerate(zip(net.hidden, weights)):
        lines += _layer(i, w, act, src, fan_in)
        src, fan_in = f"h{i}", units
    last = weights[-1][output or 0]
    lines += [f"    static const double WO[{len(last)}] = {array(last, 6)};",
              f"    y = WO[{fan_in}];",
              f"    for (i = 0; i < {fan_in}; ++i) y += WO[i] * {src}[i];"]
    for k in range(net.n_skip):
        lines.append(f"    y += WO[{fan_in + 1 + k}] * x[{net.n_in + k}];")
    lines += ["    (void)i; (void)j;", "    return y;", "}", ""]
    return "\n".join(lines)
