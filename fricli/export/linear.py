"""C code of the linear friction model (``fricli.models.linear``): the model's regressors
weighted by its parameters and summed in the order of ``LinearFriction.predict``. Stateless."""

from __future__ import annotations

from fricli.export.c import Context, Part, emitter, num


@emitter("linear")
def linear(m, name: str, ctx: Context) -> Part:
    v = ctx.signal("qd")
    if m.asymmetric:   # the columns of fricli.models.linear.regressors, asymmetric
        columns = [f"({v} > 0.0 ? {v} : 0.0)", f"({v} > 0.0 ? 1.0 : 0.0)",
                   f"({v} < 0.0 ? {v} : 0.0)", f"({v} < 0.0 ? -1.0 : -0.0)"]
    else:
        columns = [v, f"{ctx.sgn}({v})", "1.0"]
    body = ["    double tau = 0.0;"]
    body += [f"    tau += {num(coef)} * {col};" for coef, col in zip(m.coefficients(), columns)]
    code = "\n".join([f"static inline double {name}_step(const {ctx.in_type} *in) {{", *body, "    return tau;",
                      "}", ""])
    return Part(name, code, stateful=False)
