"""C code of the kinds made of other models: ``residual`` (base + NN_add) and ``augmented``
(base + coefficient-weighted terms of diagnosed effects). Children are emitted with their own
emitters under ``<name>_<child>``; their states nest in the parent's state struct.
"""

from __future__ import annotations

from fricli.export import terms as T
from fricli.export.c import Context, Part, comment, emit, emitter, num


def _state(name: str, fields: list[str]) -> list[str]:
    return ["typedef struct {", *[f"    {f};" for f in fields], f"}} {name}_state;", ""]


@emitter("residual")
def residual(model, name: str, ctx: Context) -> Part:
    base = emit(model.base, f"{name}_base", ctx)
    add = emit(model.add, f"{name}_add", ctx)
    code = [base.code, add.code]
    if base.stateful:
        code += _state(name, [f"{base.name}_state base"])
        code += [f"static inline void {name}_init({name}_state *s) {{ {base.init('&s->base')} }}", "",
                 f"static inline double {name}_step({name}_state *s, const {ctx.in_type} *in) {{"]
    else:
        code.append(f"static inline double {name}_step(const {ctx.in_type} *in) {{")
    code += [f"    return {base.step('&s->base')} + {add.step()};", "}", ""]
    return Part(name, "\n".join(code), stateful=base.stateful)


@emitter("augmented")
def augmented(model, name: str, ctx: Context) -> Part:
    """tau_f = p + sum_j coef[j] * term_j, p the base's friction; the held direction of motion
    (0 before the first motion) is state."""
    base = emit(model.base, f"{name}_base", ctx)
    held = T.uses_direction(model.terms)
    fields = ([f"{base.name}_state base"] if base.stateful else []) + (["double dir"]
                                                                         if held else [])
    code = [base.code]
    body = [f"    const double p = {base.step('&s->base')};"]
    if model.terms:
        body.append("    double v, acc = 0.0;")
    if held:
        qd = ctx.signal("qd")
        body += [f"    if ({qd} != 0.0) s->dir = {ctx.sgn}({qd});", "    const double dir = s->dir;"]
    for spec, c in zip(model.terms, model.coef):
        body += [f"    /* {comment(spec['name'])} */", f"    {T.term(spec, ctx)}",
                 f"    acc += {num(c)} * v;"]
    body.append("    return p + acc;" if model.terms else "    return p;")
    if fields:
        inits = ([base.init("&s->base")] if base.stateful else []) + (["s->dir = 0.0;"] if held else [])
        code += _state(name, fields)
        code += [f"static inline void {name}_init({name}_state *s) {{ {' '.join(inits)} }}", "",
                 f"static inline double {name}_step({name}_state *s, const {ctx.in_type} *in) {{"]
    else:
        code.append(f"static inline double {name}_step(const {ctx.in_type} *in) {{")
    code += [*body, "}", ""]
    return Part(name, "\n".join(code), stateful=bool(fields))
