"""C code of a dense network (``fricli.numerics.nn.Network``): layers, biases and activations.

``dense(net, name)`` defines ``static inline double <name>(const double *x)``: the network's
single output for the standardised inputs x (n_in inputs, then n_skip inputs that go straight
to the output layer), in double precision. Weights are function-local const tables (flat), stored
input-major so the compiler can vectorise over a layer's units. Activations are written by
the functions in ``ACTIVATIONS``, one per activation name, mirroring ``fricli.numerics.nn.activations``:
C statements turning ``v`` into the unit's output, or a list of statements run as successive
passes over the layer's units, carrying a scratch value ``t`` per unit from pass to pass; only
the last pass changes ``v``. The body is written once, as ``<name>_body``; ``<name>`` calls its
AVX2 copy when the header's ``FRICLI_AVX2`` says there is one and the CPU has AVX2
(``c.PRELUDE``), else the body itself.
"""

from __future__ import annotations

import re

import numpy as np

from fricli.core.errors import ModelFileError
from fricli.export.c import AVX2, array, num
from fricli.numerics.nn import activations as acts


EXP_SQUARINGS = 5   # e^-y = R(y / 2^5)^(2^5), R the (4, 4) Pade approximant of e^-x


def _elu(act, unit: str) -> list[str]:
    """max(v, 0) + e^min(v, 0) - 1, as acts.ELU computes it, in three passes of operations a
    compiler vectorises at -O2 (no branch, table, library call or comparison, any of which keeps
    it from doing so; short passes keep many units in flight):

    1. z = |v| - v = -2 min(v, 0); w = (z + 80) - |z - 80| = 4 min(-min(v, 0), 40) (below
       e^-40, e^u - 1 rounds to -1 all the same);
    2. R = N(-y) / N(y) = e^-y, the (4, 4) Pade approximant, N(x) = 1 + x/2 + 3x^2/28 + x^3/84
       + x^4/1680, at y = w / 2^7, its powers of two folded into the coefficients;
    3. e^min(v, 0) = R^(2^5) by squaring; max(v, 0) = v + z / 2.

    Absolute error below 1e-14 for finite v, and exactly v for v >= 0; NaN stays NaN."""
    k = 4 * 2 ** EXP_SQUARINGS                     # w = k y
    a, b = num(3 / 28 / k ** 2), num(1 / 1680 / k ** 4)
    c, d = num(1 / 84 / k ** 3), num(0.5 / k)
    return ["{ const double z_ = fabs(v) - v; t = (z_ + 80.0) - fabs(z_ - 80.0); }",
            f"{{ const double s_ = t * t, e_ = (s_ * {b} + {a}) * s_ + 1.0, o_ = (s_ * {c} + {d}) * t; "
            "t = (e_ - o_) / (e_ + o_); }",
            " ".join(["t *= t;"] * EXP_SQUARINGS) + " v = (v + 0.5 * (fabs(v) - v)) + (t - 1.0);"]


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


BLOCK = 16   # most units whose sums a layer accumulates together (8 SSE2 pairs: no spill)

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


def _name(act) -> str:
    spec = act.spec()
    return spec if isinstance(spec, str) else spec["name"]


def _blocks(units: int) -> list[tuple[int, int]]:
    """(first unit, count) blocks of at most BLOCK units, of even sizes where possible."""
    n = -(-units // BLOCK)
    size = min(BLOCK, -(-units // n) + (-(-units // n) % 2))
    return [(b, min(size, units - b)) for b in range(0, units, size)]


LANES = 4   # doubles in an AVX2 register: gcc -O2 vectorises a loop whose count is a multiple of it


def _layer(i: int, w: np.ndarray, act, src: str, fan_in: int) -> list[str]:
    """C statements of hidden layer i: h<i>[units] from src[fan_in]; w (units, fan_in + 1). An
    activation in passes runs over the units padded to a multiple of LANES with zeros (its
    value at 0 is 0; nothing reads the padding)."""
    units = w.shape[0]
    parts = _parts(act, units)
    only = parts[0][2] if len(parts) == 1 else None
    in_passes = only is not None and isinstance(ACTIVATIONS.get(_name(only), _identity)(only, "j"), list)
    padded = units + (-units) % LANES if in_passes else units
    table = np.vstack([w[:, :fan_in].T, w[:, fan_in]])   # input-major, bias last
    lines = [f"    static const double W{i}[{(fan_in + 1) * units}] = {array(table, 6)};",
             f"    double h{i}[{padded}];"]
    for b, m in _blocks(units):               # a block of units at a time, their sums in registers
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
    if padded > units:
        lines.append("    " + " ".join(f"h{i}[{k}] = 0.0;" for k in range(units, padded)))
    for start, n, part in parts:
        n = padded if padded > units else n
        name = _name(part)
        if name not in ACTIVATIONS:
            raise ModelFileError(f"cannot export the activation {name!r} to C")
        code = ACTIVATIONS[name](part, f"j - {start}")
        if not code:
            continue
        lines.append("    {")
        if name == "jump":
            lines.append(f"    static const double K[{n}] = {array(np.broadcast_to(part.ks, (n,)), 10)};")
        if isinstance(code, str):
            lines += [f"    for (j = {start}; j < {start + n}; ++j) {{",
                      f"        double v = h{i}[j];", f"        {code}", f"        h{i}[j] = v;", "    }"]
        else:                                 # passes over the units, with a scratch value t per unit
            lines.append(f"    double t_[{n}];")
            for k, step in enumerate(code):
                last = k == len(code) - 1
                lines += [f"    for (j = {start}; j < {start + n}; ++j) {{",
                          *([f"        {'double' if last else 'const double'} v = h{i}[j];"]
                            if re.search(r"\bv\b", step) else []),
                          f"        double t{'' if k == 0 else f' = t_[j - {start}]'};",
                          f"        {step}", f"        h{i}[j] = v;" if last else f"        t_[j - {start}] = t;", "    }"]
        lines.append("    }")
    return lines


SUMS = 6   # partial sums of the output layer's dot product (a short chain of additions)


def _dot(w: str, x: str, n: int) -> list[str]:
    """C statements adding the dot product of w[:n] and x[:n] to y, in SUMS partial sums."""
    k = min(SUMS, n)
    full = n - n % k
    acc = [f"s{j}" for j in range(k)]
    total = acc
    while len(total) > 1:
        total = [f"({a} + {b})" for a, b in zip(total[::2], total[1::2])] + total[len(total) - len(total) % 2:]
    return ["    {",
            "        double " + ", ".join(f"{a} = 0.0" for a in acc) + ";",
            f"        for (i = 0; i < {full}; i += {k}) {{",
            *[f"            {a} += {w}[i + {j}] * {x}[i + {j}];" for j, a in enumerate(acc)],
            "        }",
            f"        y += {total[0]};",
            *[f"        y += {w}[{i}] * {x}[{i}];" for i in range(full, n)],
            "    }"]


def dense(net, name: str, output: int | None = None) -> str:
    """C definition of ``static inline double <name>(const double *x)`` for ``net``: its single
    output, or output number ``output`` of several. The header puts ``c.PRELUDE`` before it."""
    if output is None and net.n_out != 1:
        raise ModelFileError(f"cannot export a network with {net.n_out} outputs")
    weights = [np.asarray(w, dtype=np.float64) for w in net.weights]
    lines = [f"FRICLI_NET_INLINE double {name}_body(const double *x) {{", "    int i, j;", "    double y;"]
    src, fan_in = "x", net.n_in
    for i, ((units, act), w) in enumerate(zip(net.hidden, weights)):
        lines += _layer(i, w, act, src, fan_in)
        src, fan_in = f"h{i}", units
    last = weights[-1][output or 0]
    lines += [f"    static const double WO[{len(last)}] = {array(last, 6)};",
              f"    y = WO[{fan_in}];", *_dot("WO", src, fan_in)]
    for k in range(net.n_skip):
        lines.append(f"    y += WO[{fan_in + 1 + k}] * x[{net.n_in + k}];")
    lines += ["    (void)i; (void)j;", "    return y;", "}",
              f"#if {AVX2}",
              f"__attribute__((target(\"avx2\"))) static double {name}_avx2(const double *x) {{ return {name}_body(x); }}",
              "#endif",
              f"static inline double {name}(const double *x) {{",
              f"#if {AVX2}",
              f"    if (__builtin_cpu_supports(\"avx2\")) return {name}_avx2(x);",
              "#endif",
              f"    return {name}_body(x);", "}", ""]
    return "\n".join(lines)
