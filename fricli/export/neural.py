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
from fricli.export import network
from fricli.export.c import Context, Part, emitter, num
from fricli.models.dissipative import G_MIN
from fricli.numerics.nn import activations as acts


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
    ensemble of K networks: the mean of the K magnitudes (K network evaluations)."""
    if model.net_ is None:
        raise ModelFileError("cannot export a network that is not fitted")
    nets = model.nets_
    b1 = float(np.mean(acts.softplus(np.array([float(net.weights[-1][1, -1]) for net in nets]))))
    qd, tau_g = ctx.signal("qd"), ctx.signal("tau_g")
    names = [f"{name}_net" if k == 0 else f"{name}_net{k}" for k in range(len(nets))]
    softplus = "log(1.0 + exp(-fabs(r_))) + (r_ > 0.0 ? r_ : 0.0)"   # softplus(r_), to 1e-16 absolute
    lines = [*(network.dense(net, net_name, output=0) for net, net_name in zip(nets, names)),
             f"static inline double {name}_step(const {ctx.in_type} *in) {{",
             f"    const double qd = {qd};",
             "    double x[2], r0, r_, s_;",
             (f"    s_ = fabs(qd) / {num(model.v0_)};" if model.v_max_ is None else
              f"    s_ = fmin(fabs(qd), qd > 0.0 ? {num(model.v_max_[0])} : {num(model.v_max_[1])}) / {num(model.v0_)};"),
             *([] if model.v_min_ is None else [   # held at the slowest training speeds below them
                 f"    s_ = fmax(s_, (qd > 0.0 ? {num(model.v_min_[0])} : {num(model.v_min_[1])}) / {num(model.v0_)});"]),
             "    /* asinh(s_) for s_ >= 0, to a few 1e-16 (as a library asinh, faster) */",
             "    s_ = s_ < 1e8 ? log(s_ + sqrt(s_ * s_ + 1.0)) : log(s_) + 0.69314718055994531;",
             f"    x[0] = (s_ - {num(model.u_mean_)}) / {num(model.u_scale_)};",
             f"    x[1] = {ctx.sgn}(qd);",
             "    r0 = 0.0;",
             *(f"    r_ = {net_name}(x); r0 += {softplus};" for net_name in names),
             *([] if len(nets) == 1 else [f"    r0 = r0 / {num(float(len(nets)))};"]),
             *([f"    r0 = r0 + {num(b1)} * (fabs({tau_g}) / {num(model.g_scale_)});"] if model.load_ else []),
             *([] if model.v_max_ is None else [   # linear beyond the top training speeds
                 f"    r0 = r0 + (qd > 0.0 ? {num(model.slope_[0])} * fmax(qd - {num(model.v_max_[0])}, 0.0)"
                 f" : {num(model.slope_[1])} * fmax(-qd - {num(model.v_max_[1])}, 0.0));"]),
             *([] if model.prior_ is None else _prior(model, ctx)),
             *([f"    return r0 * tanh(qd / {num(model.v_ps_)}) * {num(model.y_scale_)};", "}", ""]
               if model.sigma0_ is None else _bristles(model, ctx))]
    if model.sigma0_ is None:
        return Part(name, "\n".join(lines), stateful=False)
    lines[len(nets):len(nets)] = [
        "typedef struct {", "    double z;       /* bristle deflection [rad] */",
        "    double t_prev;  /* time of the previous sample [s] */",
        "    int started;    /* 0 until the first sample */", f"}} {name}_state;", "",
        f"static inline void {name}_init({name}_state *s) {{ s->z = 0.0; s->t_prev = 0.0; s->started = 0; }}", ""]
    lines[lines.index(f"static inline double {name}_step(const {ctx.in_type} *in) {{")] = (
        f"static inline double {name}_step({name}_state *s, const {ctx.in_type} *in) {{")
    return Part(name, "\n".join(lines), stateful=True)


def _prior(model, ctx: Context) -> list[str]:
    """r0 = blend r0 + (1 - blend) p / y_scale, p the prior's steady magnitude (as
    ``DissipativeFriction.prior_magnitude``)."""
    p, blend = model.prior_, model.blend_
    tau_g = ctx.signal("tau_g")
    return [f"    {{ const double load = fabs({tau_g}), absv = fabs(qd);",
            f"      const double shape = absv > 0.0 ? exp(-exp((log(absv) - {num(math.log(p['vs']))}) * "
            f"{num(p['delta'])})) : 1.0;",
            f"      const double p = shape * (load * {num(p['ks'] - p['kc'])} + {num(p['fs'] - p['fc'])})"
            f" + (load * {num(p['kc'])} + {num(p['fc'])}) + absv * {num(p['fv'])};",
            f"      r0 = r0 * {num(blend)} + p * {num((1.0 - blend) / model.y_scale_)}; }}"]


def _bristles(model, ctx: Context) -> list[str]:
    """The end of a dissipative step function with the pre-sliding state: g = y_scale r0, the
    bristle update, tau_f = sigma0 z (as ``DissipativeFriction.predict``)."""
    t = ctx.signal("t")
    return [f"    {{ double g = r0 * {num(model.y_scale_)}, rate, a, zss, z;",
            f"      g = g > {num(G_MIN)} ? g : {num(G_MIN)};",
            f"      rate = fabs(qd) * {num(model.sigma0_)} / g;",
            f"      a = rate * (s->started ? {t} - s->t_prev : 0.0);",
            "      a = exp(-(a < 700.0 ? a : 700.0));",
            f"      zss = {ctx.sgn}(qd) * g / {num(model.sigma0_)};",
            "      z = (1.0 - a) * zss + a * (s->started ? s->z : zss);",
            f"      s->z = z; s->t_prev = {t}; s->started = 1;",
            f"      return z * {num(model.sigma0_)}; }}", "}", ""]
