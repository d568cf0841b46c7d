"""C code of a coupled group's model (``fricli.models.coupled``): one step function for the group.

    enum { PREFIX_N_JOINTS = k };
    static inline void PREFIX_init(PREFIX_state *s);
    static inline void PREFIX_step(PREFIX_state *s, const double *qd, double *tau_f);
        qd[k]: the group's joint velocities [rad/s], tau_f[k]: each joint's friction [Nm]

in the order of ``CoupledModel.predict_group``: motor velocities w = R qd, motor friction
f = fv w + fc sign(w) + offset (+ (fs - fc) sign(w) exp(-(w/vs)^2) with the Stribeck curve), or
each motor's model (a network per motor: its step function, as ``fricli.export.c.emit`` writes
it, reading the motor's velocity as ``qd`` and a zero ``tau_g``), joint friction tau_f = R^T f.
The model has no state; the state argument keeps the calls of every other exported model.
"""

from __future__ import annotations

from fricli.core.errors import ModelFileError
from fricli.export.c import Context, emit, num


def group_code(model, meta: dict, prefix: str, sgn: str) -> str:
    """The public API of a coupled model under ``prefix``; ``sgn`` names the header's sign function."""
    k = len(model.joints)
    tau = meta.get("units", {}).get("tau", "Nm")
    qd = meta.get("units", {}).get("qd", "rad/s")
    r = model.ratio
    body = []
    for i in range(k):
        w = " + ".join(f"{num(r[i, j])} * qd[{j}]" for j in range(k) if r[i, j] != 0) or "0.0"
        body.append(f"    const double w{i} = {w};")
    motors = _motor_code(model, prefix, sgn, body) if model.motors is not None else []
    for i in range(k if model.motors is None else 0):
        f = f"{num(model.fv[i])} * w{i} + {num(model.fc[i])} * {sgn}(w{i}) + {num(model.offset[i])}"
        if model.stribeck:
            f += (f" + {num(model.fs[i] - model.fc[i])} * {sgn}(w{i}) * exp(-((w{i} / {num(model.vs[i])}) * "
                  f"(w{i} / {num(model.vs[i])})))")
        body.append(f"    const double f{i} = {f};")
    for j in range(k):
        terms = " + ".join(f"{num(r[i, j])} * f{i}" for i in range(k) if r[i, j] != 0) or "0.0"
        body.append(f"    tau_f[{j}] = {terms};")
    names = ", ".join(str(j) for j in model.joints)
    return "\n".join([
        f"/* Coupled group of joints {names} (they share motors): {prefix}_step takes the group's joint velocities",
        f" * qd[{prefix}_N_JOINTS] [{qd}] in the order {names} and writes each joint's friction torque",
        f" * tau_f[{prefix}_N_JOINTS] [{tau}], positive along the motion, in the same order. */",
        f"enum {{ {prefix}_N_JOINTS = {k} }};",
        f"typedef struct {{ int unused; }} {prefix}_state;  /* the model has no state */", "", *motors,
        "/* Start a run (the model has no state: kept so that every kind has the same calls). */",
        f"static inline void {prefix}_init({prefix}_state *s) {{ s->unused = 0; }}", "",
        "/* One sample of the group: motor velocities w = R qd, motor friction "
        + ("f = fv w + fc sign(w) + offset," if model.motors is None else "f_i = motor i's model of w_i,"),
        " * joint friction tau_f = R^T f. */",
        f"static inline void {prefix}_step({prefix}_state *s, const double *qd, double *tau_f) {{",
        "    (void)s;", *body, "}", ""])


MOTOR_SIGNALS = {"qd": "w", "tau_g": None}   # coupled.motor_signals: its velocity, no load (0)


def _motor_code(model, prefix: str, sgn: str, body: list[str]) -> list[str]:
    """The definitions of the motor models' step functions (returned) and the statements of the
    group step that compute f<i> from w<i> (appended to ``body``)."""
    ctx = Context(prefix, sgn)
    parts = [emit(motor, f"{prefix}_motor{i + 1}", ctx) for i, motor in enumerate(model.motors)]
    if any(part.stateful for part in parts):
        raise ModelFileError("cannot export a coupled group whose motor models have a state")
    other = [s for s in ctx.signals() if s not in MOTOR_SIGNALS]
    if other:
        raise ModelFileError(f"a motor model reads {', '.join(other)}: a motor's model reads its velocity alone")
    fields = [(ctx.fields[s], MOTOR_SIGNALS[s]) for s in ctx.signals()]
    body.append(f"    {ctx.in_type} in_;")
    body.append(f"    const {ctx.in_type} *in = &in_;")
    for i, part in enumerate(parts):
        body += [f"    in_.{field} = {f'w{i}' if value else '0.0'};" for field, value in fields]
        body.append(f"    const double f{i} = {part.step()};")
    return ["/* A motor's signals: its velocity qd [rad/s] (and no load: tau_g 0). */",
            "typedef struct {", *[f"    double {field};" for field, _ in fields], f"}} {ctx.in_type};", "",
            *[part.code.rstrip() + "\n" for part in parts]]
