"""C code of the kinds made of other models: ``residual`` (base and NN_add, added or combined
against the motion) and ``augmented`` (base + coefficient-weighted terms of diagnosed effects,
friction apart from robot-model errors). Children are emitted with their own emitters under
``<name>_<child>``; their states nest in the parent's state struct.
"""

from __future__ import annotations

from fricli.export import terms as T
from fricli.export.c import Context, Part, comment, emit, emitter, num, position_step


def _state(name: str, fields: list[str]) -> list[str]:
    """A state struct; a field "decl  /* note */" keeps its note after the semicolon."""
    lines = [f"    {f};" if "/*" not in f else "    {0};  /*{1}".format(*f.split("  /*", 1)) for f in fields]
    return ["typedef struct {", *lines, f"}} {name}_state;", ""]


def _signature(name: str, fn: str, ctx: Context, stateful: bool, extra: str = "") -> str:
    state = f"{name}_state *s, " if stateful else ""
    return f"static inline double {name}_{fn}({state}const {ctx.in_type} *in{extra}) {{"


def _with_parts(part: Part, ctx: Context, body: list[str]) -> list[str]:
    """``_step_parts`` with ``body`` (friction returned, the robot-model error in ``*error``) and
    ``_step``, their sum."""
    return [_signature(part.name, "step_parts", ctx, part.stateful, ", double *error"), *body, "}", "",
            _signature(part.name, "step", ctx, part.stateful), "    double err;",
            f"    const double f = {part.step_parts('s', '&err')};", "    return f + err;", "}", ""]


@emitter("residual")
def residual(model, name: str, ctx: Context) -> Part:
    """p = base + NN_add; ``dissipative``: tau_f = w p + (1 - w) s T softplus(s p / T),
    s = sign(qd), w = (1 - min(|qd| / v_ps, 1)^2)^2, as ``ResidualFriction.on_base``; over a base
    with robot-model errors apart, p is the base's friction plus NN_add and the error is added after."""
    base = emit(model.base, f"{name}_base", ctx)
    add = emit(model.add, f"{name}_add", ctx)
    code = [base.code, add.code]
    if base.stateful:
        code += _state(name, [f"{base.name}_state base"])
        code += [f"static inline void {name}_init({name}_state *s) {{ {base.init('&s->base')} }}", ""]
    # a base with robot-model errors apart (augmented): NN_add and the combination act on its friction
    friction = base.step_parts("&s->base", "error") if base.parts else base.step("&s->base")
    if model.combine == "additive":
        body = [f"    return {friction} + {add.step()};"]
    else:
        qd, width = ctx.signal("qd"), num(model.width_)
        body = [f"    const double p = {friction} + {add.step()};",
                f"    const double sg = {ctx.sgn}({qd});",
                f"    double w = fabs({qd}) / {num(model.v_ps_)}, x, m;",
                "    w = w < 1.0 ? w : 1.0;",
                "    w = 1.0 - w * w;",
                "    w = w * w;",
                f"    x = sg * p / {width};",
                f"    m = {width} * ((x > 0.0 ? x : 0.0) + log1p(exp(-fabs(x))));   /* T softplus(s p / T) */",
                "    return w * p + (1.0 - w) * sg * m;"]
    part = Part(name, "", stateful=base.stateful, parts=base.parts)
    if base.parts:
        code += _with_parts(part, ctx, body)
    else:
        code += [_signature(name, "step", ctx, base.stateful), *body, "}", ""]
    part.code = "\n".join(code)
    return part


@emitter("augmented")
def augmented(model, name: str, ctx: Context) -> Part:
    """friction = p + sum_j coef[j] term_j, robot-model error = sum_k error_coef[k] error_term_k,
    p the base's prediction; ``_step`` returns their sum (as ``predict``), ``_step_parts`` the
    friction and the error apart. The held direction of motion and gravity torque are state."""
    base = emit(model.base, f"{name}_base", ctx)
    every = model.terms + model.error_terms
    held_dir, held_gear = T.uses_direction(every), T.uses_held_gear(every)
    fields = ([f"{base.name}_state base"] if base.stateful else [])
    fields += ["double dir  /* direction of the last motion, 0 before any */"] if held_dir else []
    fields += ["double gear  /* tau_g at the last moving sample [Nm] */"] if held_gear else []
    limits = T.slip_limits(every)
    if limits:
        fields += ["double slip_q  /* position at the last row [rad or m] */", "int slip_started"]
        fields += [f"double {T.slip_name(d)}  /* deflection of the slip element of limit {num(d)} */" for d in limits]
    stateful = bool(fields)
    code = [base.code]
    if base.parts:   # the base's own robot-model error stays apart from its friction
        body = ["    double base_err;", f"    const double pf = {base.step_parts('&s->base', '&base_err')};",
                "    const double p = pf + base_err;", "    double v, acc = 0.0, err = base_err;"]
    else:
        body = [f"    const double p = {base.step('&s->base')};", "    const double pf = p;",
                "    double v, acc = 0.0, err = 0.0;"]
    if held_dir or held_gear:
        qd = ctx.signal("qd")
        updates = ([f"s->dir = {ctx.sgn}({qd});"] if held_dir else []) + (
            [f"s->gear = {ctx.signal('tau_g')};"] if held_gear else [])
        body.append(f"    if ({qd} != 0.0) {{ {' '.join(updates)} }}")
        body += ["    const double dir = s->dir;"] if held_dir else []
        body += ["    const double gear = s->gear;"] if held_gear else []
    if limits:
        q = ctx.signal("q")
        body.append(f"    {{ double dq = s->slip_started ? {q} - s->slip_q : 0.0; s->slip_q = {q}; "
                    f"s->slip_started = 1; {position_step('dq')}")
        body += [f"      s->{T.slip_name(d)} = fmin(fmax(s->{T.slip_name(d)} + dq, -{num(d)}), {num(d)});" for d in limits]
        body.append("    }")
    for terms, coef, sum_ in ((model.terms, model.coef, "acc"), (model.error_terms, model.error_coef, "err")):
        for spec, c in zip(terms, coef):
            body += [f"    /* {comment(spec['name'])} */", f"    {T.term(spec, ctx)}", f"    {sum_} += {num(c)} * v;"]
    body += ["    (void)v; (void)p;", "    *error = err;", "    return pf + acc;"]
    if stateful:
        inits = ([base.init("&s->base")] if base.stateful else []) + (["s->dir = 0.0;"] if held_dir else []) + (
            ["s->gear = 0.0;"] if held_gear else []) + (
            (["s->slip_q = 0.0;", "s->slip_started = 0;"] + [f"s->{T.slip_name(d)} = 0.0;" for d in limits]
             if limits else []))
        code += _state(name, fields)
        code += [f"static inline void {name}_init({name}_state *s) {{ {' '.join(inits)} }}", ""]
    part = Part(name, "", stateful=stateful, parts=True)
    code += _with_parts(part, ctx, body)
    part.code = "\n".join(code)
    return part
