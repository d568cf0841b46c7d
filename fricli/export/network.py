"""C code of a dense network (``fricli.numerics.nn.Network``): layers, biases and activations.

``dense(net, name)`` defines ``static inline double <name>(const double *x)``: the network's
single output for the standardised inputs x (n_in inputs, then n_skip inputs that go straight
to the output layer), in double precision. Weights are file-scope const tables (flat), stored
input-major so the compiler can vectorise over a layer's units. Activations are written by
the functions in ``ACTIVATIONS``, one per activation name, mirroring ``fricli.numerics.nn.activations``:
C statements turning ``v`` into the unit's output, or a list of statements run as successive
passes over the layer's units, carrying a scratch value ``t`` per unit from pass to pass; only
the last pass changes ``v``. The network is written twice over the same tables: ``<name>_body``,
portable C99, and ``<name>_fma``, its layers' multiply-adds fused, compiled for AVX2 and FMA;
``<name>`` calls the second when the header's ``FRICLI_AVX2`` says it is built and the CPU has
both (``c.PRELUDE``), else the first.
"""

from __future__ import annotations

import re

import numpy as np

from fricli.core.errors import ModelFileError
from fricli.export.c import AVX2, array, num
from fricli.numerics.nn import activations as acts


EXP_SQUARINGS = 5   # e^-y = R(y / 2^5)^(2^5), R the (4, 4) Pade approximant of e^-x


def _elu(act, unit: str, fused: bool = False) -> list[str]:
    """max(v, 0) + e^min(v, 0) - 1, as acts.ELU computes it, in three passes of operations a
    compiler vectorises at -O2 (no branch, table, library call or comparison, any of which keeps
    it from doing so; short passes keep many units in flight):

    1. z = |v| - v = -2 min(v, 0); w = (z + 80) - |z - 80| = 4 min(-min(v, 0), 40) (below
       e^-40, e^u - 1 rounds to -1 all the same);
    2. R = N(-y) / N(y) = e^-y, the (4, 4) Pade approximant, N(x) = 1 + x/2 + 3x^2/28 + x^3/84
       + x^4/1680, at y = w / 2^7, its powers of two folded into the coefficients;
    3. e^min(v, 0) = R^(2^5) by squaring; max(v, 0) = v + z / 2.

    ``fused``: the polynomials' multiply-adds fused. Absolute error below 1e-14 for finite v,
    and exactly v for v >= 0; NaN stays NaN."""
    k = 4 * 2 ** EXP_SQUARINGS                     # w = k y
    a, b = num(3 / 28 / k ** 2), num(1 / 1680 / k ** 4)
    c, d = num(1 / 84 / k ** 3), num(0.5 / k)
    return ["{ const double z_ = fabs(v) - v; t = (z_ + 80.0) - fabs(z_ - 80.0); }",
            (f"{{ const double s_ = t * t, e_ = fma(fma(s_, {b}, {a}), s_, 1.0), o_ = fma(s_, {c}, {d}) * t; "
             if fused else
             f"{{ const double s_ = t * t, e_ = (s_ * {b} + {a}) * s_ + 1.0, o_ = (s_ * {c} + {d}) * t; ")
            + "t = (e_ - o_) / (e_ + o_); }",
            " ".join(["t *= t;"] * EXP_SQUARINGS) + " v = (v + 0.5 * (fabs(v) - v)) + (t - 1.0);"]


def _sigmoid(act, unit: str, fused: bool = False) -> str:
    clip = num(acts._SIGMOID_CLIP)
    return f"v = v < -{clip} ? -{clip} : (v > {clip} ? {clip} : v); v = 1.0 / (1.0 + exp(-v));"


def _jump(act, unit: str, fused: bool = False) -> str:
    # phi_k = s * s^(k-1), s = 1 - e^-max(v, 0); k per unit from the table K
    return "{ const double s_ = 1.0 - exp(-(v > 0.0 ? v : 0.0)); v = s_ * pow(s_, K[" + unit + "] - 1.0); }"


def _identity(act, unit: str, fused: bool = False) -> str:
    return ""


def _softplus(act, unit: str, fused: bool = False) -> str:
    # log(1 + e^v) without overflow: max(v, 0) + log1p(e^-|v|)
    return "v = (v > 0.0 ? v : 0.0) + log1p(exp(-fabs(v)));"


def _tanh(act, unit: str, fused: bool = False) -> str:
    return "v = tanh(v);"


BLOCK = 16         # most units whose sums a layer accumulates together (8 SSE2 pairs: no spill)
FUSED_BLOCK = 32   # the same in the AVX2 copy (8 of its 16 registers)

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


def _blocks(units: int, block: int) -> list[tuple[int, int]]:
    """(first unit, count) blocks of at most ``block`` units, of even sizes where possible."""
    n = -(-units // block)
    size = min(block, -(-units // n) + (-(-units // n) % 2))
    return [(b, min(size, units - b)) for b in range(0, units, size)]


LANES = 4   # doubles in an AVX2 register: gcc -O2 vectorises a loop whose count is a multiple of it


def _madd(acc: str, w: str, x: str, fused: bool) -> str:
    """acc += w x, as one fused multiply-add (one rounding) when ``fused``."""
    return f"{acc} = fma({w}, {x}, {acc});" if fused else f"{acc} += {w} * {x};"


def _table(i: int, w: np.ndarray, name: str) -> str:
    """The file-scope table of hidden layer i's weights, w (units, fan_in + 1): input-major,
    biases last."""
    fan_in = w.shape[1] - 1
    table = np.vstack([w[:, :fan_in].T, w[:, fan_in]])
    return f"static const double {name}_W{i}[{table.size}] = {array(table, 6)};"


def _layer(i: int, w: np.ndarray, act, src: str, fan_in: int, name: str, fused: bool) -> list[str]:
    """C statements of hidden layer i: h<i>[units] from src[fan_in], w (units, fan_in + 1) read
    from the table ``<name>_W<i>``. An activation in passes runs over the units padded to a
    multiple of LANES with zeros (its value at 0 is 0; nothing reads the padding)."""
    units = w.shape[0]
    parts = _parts(act, units)
    only = parts[0][2] if len(parts) == 1 else None
    in_passes = only is not None and isinstance(ACTIVATIONS.get(_name(only), _identity)(only, "j"), list)
    padded = units + (-units) % LANES if in_passes else units
    lines = [f"    double h{i}[{padded}];"]
    # a block of units at a time, their sums in registers
    for b, m in _blocks(units, FUSED_BLOCK if fused else BLOCK):
        acc = [f"a{k}" for k in range(m)]
        lines += ["    {",
                  "        double " + ", ".join(f"{a} = {name}_W{i}[{fan_in * units + b + k}]"
                                                 for k, a in enumerate(acc)) + ";",
                  f"        for (i = 0; i < {fan_in}; ++i) {{",
                  f"            const double xi = {src}[i];",
                  f"            const double *w = {name}_W{i} + i * {units} + {b};",
                  *[f"            {_madd(a, f'w[{k}]', 'xi', fused)}" for k, a in enumerate(acc)],
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
        code = ACTIVATIONS[name](part, f"j - {start}", fused)
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


def _dot(w: str, x: str, n: int, fused: bool) -> list[str]:
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
            *[f"            {_madd(a, f'{w}[i + {j}]', f'{x}[i + {j}]', fused)}" for j, a in enumerate(acc)],
            "        }",
            f"        y += {total[0]};",
            *[f"        {_madd('y', f'{w}[{i}]', f'{x}[{i}]', fused)}" for i in range(full, n)],
            "    }"]


def _body(net, weights: list[np.ndarray], name: str, output: int, fused: bool) -> list[str]:
    """C definition of ``<name>_body`` (``<name>_fma`` when ``fused``): the network's output
    number ``output`` for the standardised inputs x."""
    head = (f"__attribute__((target(\"avx2,fma\"))) static double {name}_fma" if fused
            else f"static inline double {name}_body")
    lines = [head + "(const double *x) {", "    int i, j;", "    double y;"]
    src, fan_in = "x", net.n_in
    for i, ((units, act), w) in enumerate(zip(net.hidden, weights)):
        lines += _layer(i, w, act, src, fan_in, name, fused)
        src, fan_in = f"h{i}", units
    lines += [f"    y = {name}_WO[{fan_in}];", *_dot(f"{name}_WO", src, fan_in, fused)]
    for k in range(net.n_skip):
        lines.append(f"    {_madd('y', f'{name}_WO[{fan_in + 1 + k}]', f'x[{net.n_in + k}]', fused)}")
    return lines + ["    (void)i; (void)j;", "    return y;", "}"]


def dense(net, name: str, output: int | None = None) -> str:
    """C definition of ``static inline double <name>(const double *x)`` for ``net``: its single
    output, or output number ``output`` of several. The header puts ``c.PRELUDE`` before it.

    Two bodies share the weight tables: ``<name>_body``, the portable C99 one, and
    ``<name>_fma``, the same operations with the layers' multiply-adds fused, compiled for AVX2
    and FMA (a GNU target attribute) and run when the CPU has both (``c.PRELUDE``)."""
    if output is None and net.n_out != 1:
        raise ModelFileError(f"cannot export a network with {net.n_out} outputs")
    weights = [np.asarray(w, dtype=np.float64) for w in net.weights]
    last = weights[-1][output or 0]
    lines = [*(_table(i, w, name) for i, w in enumerate(weights[:-1])),
             f"static const double {name}_WO[{len(last)}] = {array(last, 6)};",
             *_body(net, weights, name, output or 0, fused=False),
             f"#if {AVX2}",
             *_body(net, weights, name, output or 0, fused=True),
             "#endif",
             f"static inline double {name}(const double *x) {{",
             f"#if {AVX2}",
             f"    if (__builtin_cpu_supports(\"avx2\") && __builtin_cpu_supports(\"fma\")) return {name}_fma(x);",
             "#endif",
             f"    return {name}_body(x);", "}", ""]
    return "\n".join(lines)
