"""C code of the neural kinds (``fricli.models.neural``): input features, standardisation,
the dense network, and the output scaling

    tau_f = y_mean + y_scale * net((features - x_mean) / x_scale)     [Nm]

with the velocity input asinh(qd / v0) when the model has a velocity scale; and of the
dissipative network (``fricli.models.dissipative``), its first output through the head of
``fricli.numerics.nn.heads``; stateless, except a dissipative network with the pre-sliding
state (``sigma0_``): its magnitude g drives the bristle update of the LuGre export
(``fricli.export.lugre``), z = z_ss + (z_prev - z_ss) exp(-sigma0 |qd| / g dt), tau_f = sigma0 z.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.core.errors import ModelFileError
from fricli.export import network, piecewise
from fricli.export.c import Context, Part, emitter, num
from fricli.models.dissipative import G_MIN
from fricli.numerics.nn import activations as acts
from fricli.numerics.piecewise import CHECKS, DEGREE


def feature(model, name: str, ctx: Context) -> str:
    """C expression of the network input ``name`` before standardisation (as ``NeuralFriction._input``)."""
    if name in ("sign(qd)", "pos(qd)", "neg(qd)"):
        s = f"{ctx.sgn}({ctx.signal('qd')})"
        return {"sign(qd)": s, "pos(qd)": f"0.5 * (1.0 + {s})", "neg(qd)": f"0.5 * (1.0 - {s})"}[name]
    if name == "qd" and model.v0_ is not None:
        return f"asinh({ctx.signal('qd')} / {num(model.v0_)})"
    return ctx.signal(name)


@emitter("mlp", "selmic", "nnacm")
def neural(model, name: str, ctx: Context) -> Part:
    if model.net_ is None:
        raise ModelFileError("cannot export a network that is not fitted")
    names = model.inputs + model.skip
    mean, scale = model.x_std_.mean_, model.x_std_.scale_
    lines = [network.dense(model.net_, f"{name}_net"),
             f"static inline double {name}_step(const {ctx.in_type} *in) {{",
             f"    double x[{len(names)}];"]
    for i, feat in enumerate(names):
        lines.append(f"    x[{i}] = ({feature(model, feat, ctx)} - {num(mean[i])}) * {num(1.0 / scale[i])};")
    lines += [f"    return {name}_net(x) * {num(model.y_std_.scale_[0])} + {num(model.y_std_.mean_[0])};", "}", ""]
    return Part(name, "\n".join(lines), stateful=False)


@emitter("dissipative")
def dissipative(model, name: str, ctx: Context) -> Part:
    """tau_f = y_scale tanh(qd / v_ps) (softplus(r0) + softplus(b1) |tau_g| / g_scale), r0 the
    network's first output for (u, sign(qd)); b1, the bias of its second, is a constant. An
    ensemble of K networks: the mean of the K magnitudes (K network evaluations). What is constant
    per model is folded into the written numbers, and a term whose coefficients are 0 is not
    written: the prior at blend 1, the networks at blend 0, a zero extrapolation slope or load term."""
    if model.net_ is None:
        raise ModelFileError("cannot export a network that is not fitted")
    nets = model.nets_
    uses_net, uses_prior = _uses(model)
    names = [f"{name}_net" if k == 0 else f"{name}_net{k}" for k in range(len(nets))]
    qd = ctx.signal("qd")
    ctx.signal("tau_g")   # a step of (t,) qd, tau_g for every dissipative model, whether it reads tau_g or not
    pieces = model.magnitude_pieces() if uses_net else None
    if pieces is not None:
        code = [_pieces_code(model, pieces, name)]
    else:
        code = [network.dense(net, net_name, output=0) for net, net_name in zip(nets, names) if uses_net]
    lines = [*code,
             f"static inline double {name}_step(const {ctx.in_type} *in) {{",
             f"    const double qd = {qd};",
             "    const int pos_ = qd > 0.0; (void)pos_;",
             "    double m;",
             *(_net_magnitude(model, name, names, ctx, pieces) if uses_net else ["    m = 0.0;"]),
             *(_prior(model, ctx) if uses_prior else []),
             *([f"    return m * tanh(qd * {num(1.0 / model.v_ps_)}) * {num(model.y_scale_)};", "}", ""]
               if model.sigma0_ is None else _bristles(model, ctx))]
    if model.sigma0_ is None:
        return Part(name, "\n".join(lines), stateful=False)
    k = len(code)
    lines[k:k] = [
        "typedef struct {", "    double z;       /* bristle deflection [rad] */",
        "    double t_prev;  /* time of the previous sample [s] */",
        "    int started;    /* 0 until the first sample */", f"}} {name}_state;", "",
        f"static inline void {name}_init({name}_state *s) {{ s->z = 0.0; s->t_prev = 0.0; s->started = 0; }}", ""]
    lines[lines.index(f"static inline double {name}_step(const {ctx.in_type} *in) {{")] = (
        f"static inline double {name}_step({name}_state *s, const {ctx.in_type} *in) {{")
    return Part(name, "\n".join(lines), stateful=True)


# an exponent beyond which exp(-x) < 4.3e-18 is taken as 0 (the Stribeck shape, the bristle decay):
# a change below 4.3e-18 of the torque it multiplies, within the rounding of the terms it is added to
SETTLED = 40.0


def _uses(model) -> tuple[bool, bool]:
    """Whether the magnitude needs the networks and the prior (as ``DissipativeFriction._run``)."""
    if model.prior_ is None:
        return True, False
    return model.blend_ != 0.0, model.blend_ != 1.0


def _pieces_code(model, pieces, name: str) -> str:
    """The tables and the evaluation function of ``model.magnitude_pieces()``, with a comment saying what they are."""
    pos, neg = pieces.pos, pieces.neg
    note = (f"/* The networks' magnitude{' (the mean of the members)' if len(model.nets_) > 1 else ''} "
            f"softplus(r0) of the speed input x[0], as polynomials of degree {DEGREE} "
            f"in {len(pos.table)} pieces for qd > 0 and {len(neg.table)} for qd < 0, each between the inputs where "
            f"a hidden unit's input crosses 0 (halved where needed); largest difference from the networks at "
            f"{CHECKS} points a piece: {pieces.error:.1e} (relative to max(1, m)). */")
    return "\n".join([note, piecewise.c_tables(f"{name}_mag_pos", pos), piecewise.c_tables(f"{name}_mag_neg", neg),
                      piecewise.c_function(f"{name}_mag"), ""])


def _net_magnitude(model, name: str, names: list[str], ctx: Context, pieces=None) -> list[str]:
    """m = the networks' magnitude softplus(r0) + k |tau_g| (+ the slope beyond v_max), / y_scale;
    with ``pieces`` (``model.magnitude_pieces()``), softplus(r0) from its polynomials."""
    nets = model.nets_
    b1 = float(np.mean(acts.softplus(np.array([float(net.weights[-1][1, -1]) for net in nets]))))
    inv_v0 = 1.0 / model.v0_
    by_dir = lambda pair: f"(pos_ ? {num(pair[0])} : {num(pair[1])})"  # noqa: E731
    # limits as comparisons, not fmin and fmax (library calls at -O2); the same for every input
    lines = [f"    double {'x[2], r_' if pieces is None else 'x[1]'}, s_ = fabs(qd);"]
    if model.v_max_ is not None:
        lines.append(f"    {{ const double top_ = {by_dir(model.v_max_)}; s_ = s_ < top_ ? s_ : top_; }}")
    if model.v_min_ is not None:   # held at the slowest training speeds below them
        lines.append(f"    {{ const double low_ = {by_dir(model.v_min_)}; s_ = s_ > low_ ? s_ : low_; }}")
    lines.append(f"    s_ = s_ * {num(inv_v0)};")
    lines += ["    /* asinh(s_) for s_ >= 0, to a few 1e-16 (as a library asinh, faster) */",
              "    s_ = s_ < 1e8 ? log(s_ + sqrt(s_ * s_ + 1.0)) : log(s_) + 0.69314718055994531;",
              f"    x[0] = (s_ - {num(model.u_mean_)}) * {num(1.0 / model.u_scale_)};"]
    if pieces is not None:
        pos, neg, at_rest = pieces.pos, pieces.neg, pieces.at_rest
        lines.append(f"    m = pos_ ? {piecewise.c_call(f'{name}_mag', f'{name}_mag_pos', pos, 'x[0]')}"
                     f" : (qd < 0.0 ? {piecewise.c_call(f'{name}_mag', f'{name}_mag_neg', neg, 'x[0]')} : {num(at_rest)});")
    else:
        lines += ["    x[1] = pos_ ? 1.0 : (qd < 0.0 ? -1.0 : 0.0);", "    m = 0.0;"]
        softplus = "log(1.0 + exp(-fabs(r_))) + (r_ > 0.0 ? r_ : 0.0)"   # softplus(r_), to 1e-16 absolute
        lines += [f"    r_ = {net_name}(x); m += {softplus};" for net_name in names]
        if len(nets) > 1:
            lines.append(f"    m = m * {num(1.0 / len(nets))};")
    if model.load_ and b1 != 0.0:
        lines.append(f"    m = m + {num(b1 / model.g_scale_)} * fabs({ctx.signal('tau_g')});")
    if model.v_max_ is not None and max(model.slope_) > 0.0:   # linear beyond the top training speeds
        top = [num(v) for v in model.v_max_]
        lines.append(f"    m = m + (pos_ ? {num(model.slope_[0])} * (qd > {top[0]} ? qd - {top[0]} : 0.0)"
                     f" : {num(model.slope_[1])} * (-qd > {top[1]} ? -qd - {top[1]} : 0.0));")
    return lines


def _prior(model, ctx: Context) -> list[str]:
    """m = blend m + (1 - blend) p / y_scale, p the prior's steady magnitude (as
    ``DissipativeFriction.prior_magnitude``), its coefficients scaled by (1 - blend) / y_scale;
    the Stribeck shape only when fs - fc or ks - kc is not 0."""
    p, blend = model.prior_, model.blend_
    c = (1.0 - blend) / model.y_scale_
    load = f"fabs({ctx.signal('tau_g')})"
    terms = []
    if p["fs"] != p["fc"] or p["ks"] != p["kc"]:
        level = " + ".join([*([f"load * {num((p['ks'] - p['kc']) * c)}"] if p["ks"] != p["kc"] else []),
                            *([num((p["fs"] - p["fc"]) * c)] if p["fs"] != p["fc"] else [])])
        # exp(-|v / vs|^delta), taken as 0 from v_cut on, where |v / vs|^delta >= SETTLED (no log, no exp)
        v_cut = p["vs"] * SETTLED ** (1.0 / p["delta"])
        terms.append(f"(absv < {num(v_cut)} ? (absv > 0.0 ? exp(-exp((log(absv) - {num(math.log(p['vs']))}) * "
                     f"{num(p['delta'])})) : 1.0) : 0.0) * ({level})")
    terms += [*([f"load * {num(p['kc'] * c)}"] if p["kc"] else []), *([num(p["fc"] * c)] if p["fc"] else []),
              *([f"absv * {num(p['fv'] * c)}"] if p["fv"] else [])]
    uses_load = any("load" in term for term in terms)
    return [f"    {{ {f'const double load = {load}; ' if uses_load else ''}const double absv = fabs(qd);"
            f"{' (void)absv;' if not any('absv' in term for term in terms) else ''}",
            f"      m = m{f' * {num(blend)}' if blend != 1.0 else ''} + ({' + '.join(terms) or '0.0'}); }}"]


def _bristles(model, ctx: Context) -> list[str]:
    """The end of a dissipative step function with the pre-sliding state: g = y_scale m floored at
    G_MIN, the bristle update, tau_f = sigma0 z (as ``DissipativeFriction.predict``), written in m
    (y_scale folded into the constants) so that one division and one exp follow the magnitude."""
    t, sigma0, y = ctx.signal("t"), model.sigma0_, model.y_scale_
    return [f"    {{ const double dt_ = s->started ? {t} - s->t_prev : 0.0;",
            "      double a, zss, z;",
            f"      m = m > {num(G_MIN / y)} ? m : {num(G_MIN / y)};",
            f"      a = fabs(qd) * {num(sigma0 / y)} * dt_ / m;",
            f"      zss = (pos_ ? m : (qd < 0.0 ? -m : 0.0)) * {num(y / sigma0)};",
            f"      if (a < {num(SETTLED)}) {{ a = exp(-a); z = zss + a * ((s->started ? s->z : zss) - zss); }}",
            "      else z = zss;   /* settled: the decay is below 4.3e-18 */",
            f"      s->z = z; s->t_prev = {t}; s->started = 1;",
            f"      return z * {num(sigma0)}; }}", "}", ""]
