"""C code of the regressor terms of diagnosed effects (``fricli.models.terms``).

A term is a product of factors; ``FACTORS`` maps each factor kind to a function
(factor, context) -> C expression. The held direction of motion is the variable ``dir``
(updated before the terms, as ``Columns.direction``), the held gear torque ``gear`` (as
``Columns.held_gravity``, held tau_g) and the base prediction ``p``; a slip element of limit d
reads its deflection ``slip_name(d)`` (a state field, moved on before the terms as
``Columns.deflection``). A new factor kind needs one entry here.
"""

from __future__ import annotations

import struct

from fricli.core.errors import ModelFileError
from fricli.export.c import Context, num

def gear(ctx: Context) -> str:
    """tau_l = tau_m - tau_dyn - p, as ``Columns.gear`` (the payload effect)."""
    return f"{ctx.signal('tau_m')} - {ctx.signal('tau_dyn')} - p"


FACTORS = {
    "one": lambda f, ctx: "1.0",
    "p": lambda f, ctx: "p",
    "signal": lambda f, ctx: ctx.signal(f["name"]),
    "dev": lambda f, ctx: (f"(fmin(fmax({ctx.signal(f['name'])}, {num(f['low'])}), {num(f['high'])}) - "
                           f"{num(f['center'])})" if "low" in f else f"({ctx.signal(f['name'])} - {num(f['center'])})"),
    "abs": lambda f, ctx: f"fabs({ctx.signal(f['name'])})",
    "overload": lambda f, ctx: f"(fabs({gear(ctx)}) - fabs({ctx.signal('tau_g')}))",
    "heldgravity": lambda f, ctx: "gear",
    "sign": lambda f, ctx: "dir",
    "moving": lambda f, ctx: "fabs(dir)",
    "pos": lambda f, ctx: "(dir > 0.0 ? 1.0 : 0.0)",
    "sat": lambda f, ctx: (f"({ctx.sgn}({ctx.signal('qd')}) * -expm1(-fabs({ctx.signal('qd')}) / "
                           f"{num(f['scale'])}))"),
    "slip": lambda f, ctx: f"(s->{slip_name(f['d'])} / {num(f['d'])})",
    "sin": lambda f, ctx: f"sin({num(f['w'])} * {ctx.signal(f['name'])})",
    "cos": lambda f, ctx: f"cos({num(f['w'])} * {ctx.signal(f['name'])})",
}
HELD_DIRECTION = ("sign", "moving", "pos")   # factors that read the held direction


def uses_direction(terms: list[dict]) -> bool:
    return any(f["f"] in HELD_DIRECTION for term in terms for f in term["factors"])


def slip_name(d: float) -> str:
    """The state field of the slip element of limit d: named by the bits of d (one field per limit)."""
    return "z_" + format(struct.unpack("<Q", struct.pack("<d", float(d)))[0], "016x")


def slip_limits(terms: list[dict]) -> list[float]:
    """The distinct limits d of the slip elements the terms read, in first use order."""
    out: list[float] = []
    for term in terms:
        for f in term["factors"]:
            if f["f"] == "slip" and float(f["d"]) not in out:
                out.append(float(f["d"]))
    return out


def uses_held_gear(terms: list[dict]) -> bool:
    return any(f["f"] == "heldgravity" for term in terms for f in term["factors"])


def term(spec: dict, ctx: Context) -> str:
    """C statements setting ``v`` to the term's value (1 times each factor, in order)."""
    out = ["v = 1.0;"]
    for factor in spec["factors"]:
        fn = FACTORS.get(factor["f"])
        if fn is None:
            raise ModelFileError(f"cannot export the term factor {factor['f']!r} to C")
        out.append(f"v = v * {fn(factor, ctx)};")
    return " ".join(out)
