"""C code of a coupled group's model (``fricli.models.coupled``): one step function for the group.

    enum { PREFIX_N_JOINTS = k };
    static inline void PREFIX_init(PREFIX_state *s);
    static inline void PREFIX_step(PREFIX_state *s, const double *qd, double *tau_f);
        qd[k]: the group's joint velocities [rad/s], tau_f[k]: each joint's friction [Nm]

in the order of ``CoupledModel.predict_group``: motor velocities w = R qd, motor friction
f = fv w + fc sign(w) + offset (+ (fs - fc) sign(w) exp(-(w/vs)^2) with the Stribeck curve), joint friction
tau_f = R^T f. The model has no state; the state
argument keeps the calls of every other exported model.
"""

from __future__ import annotations

from fricli.export.c import num


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
    for i in range(k):
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
        f"typedef struct {{ int unused; }} {prefix}_state;  /* the model has no state */", "",
        "/* Start a run (the model has no state: kept so that every kind has the same calls). */",
        f"static inline void {prefix}_init({prefix}_state *s) {{ s->unused = 0; }}", "",
        "/* One sample of the group: motor velocities w = R qd, motor friction f = fv w + fc sign(w) + offset,",
        " * joint friction tau_f = R^T f. */",
        f"static inline void {prefix}_step({prefix}_state *s, const double *qd, double *tau_f) {{",
        "    (void)s;", *body, "}", ""])
