"""C code of the extended LuGre model (``fricli.models.lugre``), in the same order of operations
as ``LuGreModel.predict``: the Stribeck curve with its load, direction and temperature levels,
the exact zero-order-hold bristle update

    z = z_ss + (z_prev - z_ss) * exp(-sigma0 |v| / g * dt),   z_ss = sign(v) g / sigma0

and tau_f = sigma0 z + sigma1 dz/dt + Fv v. State: z [rad], the previous sample time [s] and
whether a sample was seen; the first sample starts in the steady state z = z_ss.
"""

from __future__ import annotations

import math

from fricli.export.c import Context, Part, emitter, num
from fricli.models.lugre import _G_MIN


@emitter("lugre")
def lugre(m, name: str, ctx: Context) -> Part:
    v, t = ctx.signal("qd"), ctx.signal("t")
    body = [f"    const double v = {v};",
            "    const double absv = fabs(v);",
            f"    const double shape = absv > 0.0 ? exp(-exp((log(absv) - {num(math.log(m.vs))}) * {num(m.delta)}))"
            " : 1.0;",
            "    double g, fv, rate, a, zss, z0, z, dt, tau;"]
    if m.asymmetric or m.thermal:
        fc_n, fs_n, fv_n = m.negative_levels()
        if m.asymmetric:
            body += [f"    double fc = v < 0.0 ? {num(fc_n)} : {num(m.fc)};",
                     f"    double fs = v < 0.0 ? {num(fs_n)} : {num(m.fs)};",
                     f"    fv = v < 0.0 ? {num(fv_n)} : {num(m.fv)};"]
        else:
            body += [f"    double fc = {num(m.fc)};", f"    double fs = {num(m.fs)};", f"    fv = {num(m.fv)};"]
        if m.loaded:
            tau_g = ctx.signal("tau_g")
            body += [f"    fc = fc + {num(m.kc)} * fabs({tau_g});", f"    fs = fs + {num(m.ks)} * fabs({tau_g});"]
        if m.thermal:
            body += [f"    {{ const double dT = {ctx.signal('temp')} - {num(m.t_ref)};",
                     f"      const double scale = 1.0 - {num(m.alpha_c)} * dT;",
                     "      fc = fc * scale;", "      fs = fs * scale;"]
            if m.alpha_v != 0.0:
                body.append(f"      fv = fv * exp(-{num(m.alpha_v)} * dT);")
            body.append("    }")
        body.append("    g = (fs - fc) * shape + fc;")
    elif m.loaded:
        body += [f"    fv = {num(m.fv)};",
                 f"    {{ const double load = fabs({ctx.signal('tau_g')});",
                 f"      g = (load * {num(m.kc)} + {num(m.fc)}) + (load * {num(m.ks - m.kc)} + {num(m.fs - m.fc)})"
                 " * shape; }"]
    else:
        body += [f"    fv = {num(m.fv)};", f"    g = shape * {num(m.fs - m.fc)} + {num(m.fc)};"]
    body += [f"    g = g > {num(_G_MIN)} ? g : {num(_G_MIN)};",
             f"    rate = absv / g * {num(m.sigma0)};",
             f"    dt = s->started ? {t} - s->t_prev : 0.0;",
             "    a = rate * dt;",
             "    a = exp(-(a < 700.0 ? a : 700.0));",
             f"    zss = {ctx.sgn}(v) * g * {num(1.0 / m.sigma0)};",
             "    z0 = s->started ? s->z : zss;",
             "    z = (1.0 - a) * zss + a * z0;",
             f"    tau = v * {num(m.sigma1)} + ({num(m.sigma0)} + rate * {num(-m.sigma1)}) * z;",
             "    tau += fv * v;",
             "    s->z = z;", f"    s->t_prev = {t};", "    s->started = 1;",
             "    return tau;"]
    code = "\n".join([
        "typedef struct {", "    double z;       /* bristle deflection [rad] */",
        "    double t_prev;  /* time of the previous sample [s] */",
        "    int started;    /* 0 until the first sample */", f"}} {name}_state;", "",
        f"static inline void {name}_init({name}_state *s) {{ s->z = 0.0; s->t_prev = 0.0; s->started = 0; }}", "",
        f"static inline double {name}_step({name}_state *s, const {ctx.in_type} *in) {{", *body, "}", ""])
    return Part(name, code, stateful=True)
