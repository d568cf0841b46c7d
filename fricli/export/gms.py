"""C code of the Generalized Maxwell-slip model (``fricli.models.gms``), in the order of
operations of ``GMSModel.predict_parts``: the element deflections

    z_i = clip(z_i + (q - q_prev), -d_i, d_i)   (a step beyond half a turn less a turn: a wrap)

(the first sample starts every element slipped in its direction of motion, sign(qd) d_i), the
friction sum_i F_i z_i / d_i + (c(u) + kc |tau_g|) s + fst exp(-(qd/vs)^2) s + fv qd (s the
direction of motion, held at rest)
and, apart, the robot-model error e(u). State: z (N,) [rad], the previous position and whether
a sample was seen, and the direction of motion held at rest."""

from __future__ import annotations

from fricli.export.c import Context, Part, array, emitter, num, position_step
from fricli.export.composite import _with_parts


@emitter("gms")
def gms(m, name: str, ctx: Context) -> Part:
    v, q = ctx.signal("qd"), ctx.signal("q")
    n = len(m.force)
    size = max(n, 1)
    body = [f"    const double v = {v};", f"    const double q = {q};", "    double sg;",
            "    double friction = 0.0, err = 0.0, level, x;", "    int i, j;", "    (void)i; (void)j; (void)x;"]
    body += [f"    if (v != 0.0) s->dir = {ctx.sgn}(v);", "    sg = s->dir;"]
    if n:
        body += [f"    static const double d[{n}] = {array(m.deflection)};",
                 f"    static const double force[{n}] = {array(m.force)};",
                 "    if (!s->started) {",
                 f"        for (i = 0; i < {n}; i++) s->z[i] = {ctx.sgn}(v) * d[i];",
                 "        s->q_prev = q;",
                 "    }",
                 "    double dq = q - s->q_prev;",
                 f"    {position_step('dq')}",
                 f"    for (i = 0; i < {n}; i++) {{",
                 "        double z = s->z[i] + dq;",
                 "        z = z < d[i] ? z : d[i];",
                 "        z = z > -d[i] ? z : -d[i];",
                 "        s->z[i] = z;",
                 "        friction += force[i] * (z / d[i]);",
                 "    }"]
    span = m.q_hi - m.q_lo
    body += [f"    x = (q - {num(m.q_lo)}) / {num(span)};", "    x = x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x);"]
    body.append(f"    level = {num(m.fc)};")
    if m.coulomb_k:
        k = m.coulomb_k
        body += [f"    {{ static const double c[{k + 1}] = {array(m.coulomb_pos)};",
                 f"      const double y = x * {num(float(k))};",
                 f"      j = (int)y; if (j > {k - 1}) j = {k - 1};",
                 "      level += (y - (double)j) * ((c[j + 1] - c[j]) / 1.0) + c[j]; }"]
    if m.loaded:
        body.append(f"    level = level + {num(m.kc)} * fabs({ctx.signal('tau_g')});")
    body += ["    friction += level * sg;",
             f"    friction += {num(m.fst)} * (exp(-((v / {num(m.vs)}) * (v / {num(m.vs)}))) * sg);",
             f"    friction += {num(m.fv)} * v;"]
    if len(m.error):
        body.append(f"    err += {num(m.error[0])};")
        for h in range(1, m.error_k + 1):
            a, b = m.error[2 * h - 1], m.error[2 * h]
            body.append(f"    err += {num(a)} * sin({num(3.141592653589793 * h)} * x)"
                        f" + {num(b)} * cos({num(3.141592653589793 * h)} * x);")
    body += ["    s->q_prev = q;", "    s->started = 1;", "    *error = err;", "    return friction;"]
    code = "\n".join(["typedef struct {", f"    double z[{size}];  /* element deflections [rad] */",
                      "    double q_prev;  /* position of the previous sample [rad] */",
                      "    double dir;     /* direction of motion, held at rest (0 before the first motion) */",
                      "    int started;    /* 0 until the first sample */", f"}} {name}_state;", "",
                      f"static inline void {name}_init({name}_state *s) {{",
                      f"    int i; for (i = 0; i < {size}; i++) s->z[i] = 0.0;",
                      "    s->q_prev = 0.0; s->dir = 0.0; s->started = 0;", "}", ""])
    part = Part(name, "", stateful=True, parts=True)
    part.code = code + "\n" + "\n".join(_with_parts(part, ctx, body))
    return part
