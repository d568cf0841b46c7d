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

A member of the group (``GroupMember``, the model of one of its joints, alone or as the base of
an adapted or fixed model) is a part like any model of one joint (emitter ``coupled-member``): its
step function takes the joint's ``qd`` and its partners' velocities ``qd@<joint>`` (C names
``qd_<joint>``) and returns that joint's friction.
"""

from __future__ import annotations

from fricli.core.errors import ModelFileError
from fricli.export.c import Context, Part, comment, emit, emitter, num, whole_emitter


def motor_friction(model, i: int, w: str, sgn: str) -> str:
    """The C expression of motor ``i``'s friction [Nm] at the motor velocity ``w`` (a C expression)."""
    f = f"{num(model.fv[i])} * {w} + {num(model.fc[i])} * {sgn}({w}) + {num(model.offset[i])}"
    if model.stribeck:
        f += (f" + {num(model.fs[i] - model.fc[i])} * {sgn}({w}) * exp(-(({w} / {num(model.vs[i])}) * "
              f"({w} / {num(model.vs[i])})))")
    return f


@emitter("coupled-member")
def member(model, name: str, ctx: Context) -> Part:
    """One joint of a coupled group (``GroupMember``), a part like any model of one joint: the
    velocities of the motors that drive the joint, w_m = R[m] qd, from the joint's qd and its
    partners' ``qd@<joint>``; their friction f_m; the joint's friction sum_m R[m, i] f_m."""
    from fricli.models.coupled import partner_key

    group, i = model.group, model.i
    if group.children():   # motor friction of other forms than motor_friction writes
        raise ModelFileError(f"cannot export joint {model.joint} of a coupled group whose motors have models of "
                             "their own to C")
    r, k = group.ratio, len(group.joints)
    qd = [ctx.signal("qd") if c == i else ctx.signal(partner_key(j)) for c, j in enumerate(group.joints)]
    motors = [m for m in range(k) if r[m, i] != 0]
    body = []
    for m in motors:
        w = " + ".join(f"{num(r[m, c])} * {qd[c]}" for c in range(k) if r[m, c] != 0)
        body += [f"    const double w{m} = {w};", f"    const double f{m} = {motor_friction(group, m, f'w{m}', ctx.sgn)};"]
    body.append(f"    return {' + '.join(f'{num(r[m, i])} * f{m}' for m in motors)};")
    names = ", ".join(map(str, group.joints))
    return Part(name, "\n".join([f"/* joint {comment(str(model.joint))} of the coupled group of joints {comment(names)} */",
                                 f"static inline double {name}_step(const {ctx.in_type} *in) {{", *body, "}", ""]),
                stateful=False)


@whole_emitter("coupled")
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
        body.append(f"    const double f{i} = {motor_friction(model, i, f'w{i}', sgn)};")
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
