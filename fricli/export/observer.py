"""C code of what ``fricli replay`` runs (fricli.applying.observer): one arm's momentum observer,
online friction-level adaptation and contact detection around each joint's exported friction model,
with the same operations in the same order as ``Observer.step``.

The rigid-body terms come from the controller (C has no Pinocchio): per joint p = M(q) qd and
w = g(q) - C(q, qd)^T qd, or the per-joint form p = 0, w = tau_g + tau_dyn (docs/contact-detection.md).
"""

from __future__ import annotations

import dataclasses
import os

from fricli.applying import observer
from fricli.core.errors import ModelFileError
from fricli.export import c


def _joint_of(entry: c.Entry):
    return entry.meta.get("joint")


def _joints(entry: c.Entry) -> list[c.Entry]:
    """The entry of each joint ``entry`` covers: a coupled group's model gives its members
    (``PREFIX_<file>_joint_<joint>_*``, reading the partners' velocities as ``fricli replay`` applies it),
    any other model itself."""
    if not hasattr(entry.model, "member"):
        return [entry]
    return [dataclasses.replace(entry, model=entry.model.member(j), meta=dict(entry.meta, joint=j),
                                prefix=f"{entry.prefix}_{c.identifier(f'joint_{j}')}") for j in entry.model.joints]


def arm_code(entries: list[c.Entry], prefix: str, gain: float, thresholds: observer.Thresholds | None,
             adaptation: observer.Adaptation | None) -> str:
    """The arm's state, init and step functions over the joints' friction functions ``entries``."""
    n = len(entries)
    names = [str(_joint_of(e)) for e in entries]
    if thresholds is not None:
        thr = thresholds.for_joints(names, "the thresholds file")
        move, band, scale, share = thr.threshold, thr.static_friction, thr.friction_scale, thr.shares
        release, speed, persist = thr.release, thr.moving_speed, int(thr.persistence)
    else:
        move = band = None
        scale, share, release, speed, persist = [1.0] * n, [0.0] * n, observer.DEFAULT_RELEASE, \
            observer.DEFAULT_MOVING_SPEED, 1
    if adaptation is not None and thresholds is None:
        raise ModelFileError("adaptation needs the contact thresholds of fricli thresholds")
    ad = adaptation or observer.Adaptation()
    a = f"{prefix}_arm"
    table = lambda xs: "{" + ", ".join(c.num(x) for x in xs) + "}"   # noqa: E731
    huge = "{" + ", ".join(["HUGE_VAL"] * n) + "}"
    detection = (f"thresholds of fricli thresholds on {', '.join(thresholds.logs) or 'its logs'} (in motion plus a "
                 f"share of the predicted friction), flagged after {persist} samples in a row beyond" if thresholds
                 else "detection off (no thresholds)")
    adapting = "off"
    if adaptation is not None:
        adapting = (f"on: time constant {ad.time_constant:g} s, scale in [{ad.scale_bounds[0]:g}, {ad.scale_bounds[1]:g}]"
                    + (f", offset within +-{ad.offset_bound:g} x friction scale" if ad.offset else ", no offset"))
    out = [f"/* ---------------------------------------------------------------- {a}: observer, adaptation, contact",
           f" * Joints, in the order of every array below: {c.comment(', '.join(names))}.",
           f" * Observer gain K = {gain:g} 1/s; contact {c.comment(detection)};",
           f" * adaptation {adapting}. */",
           f"enum {{ {a.upper()}_JOINTS = {n} }};",
           "typedef struct {"]
    out += [f"    {e.prefix}_state friction_{i};" for i, e in enumerate(entries)]
    out += [f"    double t, t_adapt, p[{n}], y[{n}], f[{n}], a[{n}], b[{n}], P11[{n}], P12[{n}], P22[{n}], suspected[{n}];",
            f"    int started, adapt_started, contact[{n}], run[{n}], side[{n}];", f"}} {a}_state;", "",
            "/* Start a run (and after any pause in the samples). */",
            f"static inline void {a}_init({a}_state *s) {{", "    int j;"]
    out += [f"    {e.prefix}_init(&s->friction_{i});" for i, e in enumerate(entries)]
    out += ["    s->t = 0.0; s->t_adapt = 0.0; s->started = 0; s->adapt_started = 0;",
            f"    for (j = 0; j < {n}; ++j) {{",
            "        s->p[j] = 0.0; s->y[j] = 0.0; s->f[j] = 0.0; s->a[j] = 1.0; s->b[j] = 0.0; s->contact[j] = 0;",
            "        s->run[j] = 0; s->side[j] = 0;",
            "        s->suspected[j] = -HUGE_VAL;",
            f"        s->P11[j] = {c.num(ad.initial_covariance)}; s->P12[j] = 0.0; s->P22[j] = {c.num(ad.initial_covariance)};",
            "    }", "}", "",
            "/* One sample at time t [s]. x[j]: joint j's friction signals (its PREFIX_step_array order); tau_m, qd, p",
            " * (= M(q) qd, or 0) and w (= g(q) - C(q, qd)^T qd, or tau_g + tau_dyn) per joint. Writes per joint the",
            " * friction tau_f (compensation), the external torque tau_ext and the contact flag (0/1). */",
            f"static inline void {a}_step({a}_state *s, double t, const double *const *x, const double *tau_m,",
            "        const double *qd, const double *p, const double *w, double *tau_f, double *tau_ext, int *contact) {",
            f"    static const double thr[{n}] = {table(move) if move is not None else huge};",
            *([f"    static const double band[{n}] = {table(band)};"] if band is not None else []),
            f"    static const double scale[{n}] = {table(scale)};",
            f"    static const double share[{n}] = {table(share)};",
            f"    const double k = {c.num(gain)}, release = {c.num(release)}, speed = {c.num(speed)};",
            f"    const int persistence = {persist};",
            f"    double f0[{n}], e[{n}], r[{n}], mag[{n}], lim[{n}];",
            f"    int moves[{n}], j;",
            "    /* f0: friction, scaled by the adapted level; e: the robot-model error part (with w) */"]
    out += [f"    f0[{i}] = {entry.prefix}_step_parts_array(&s->friction_{i}, x[{i}], &e[{i}]);"
            for i, entry in enumerate(entries)]
    out += [f"    for (j = 0; j < {n}; ++j) tau_f[j] = s->a[j] * f0[j] + s->b[j] * scale[j];",
            "    if (!s->started) {",
            "        s->started = 1;",
            f"        for (j = 0; j < {n}; ++j) {{ s->f[j] = f0[j]; s->y[j] = tau_f[j]; }}",
            "    } else {",
            "        const double kd = k * (t - s->t);",
            f"        for (j = 0; j < {n}; ++j) {{",
            "            s->y[j] = (s->y[j] - k * (p[j] - s->p[j]) + kd * (tau_m[j] - (w[j] + e[j]))) / (1.0 + kd);",
            "            s->f[j] = (s->f[j] + kd * f0[j]) / (1.0 + kd);",
            "        }", "    }",
            "    s->t = t;",
            f"    for (j = 0; j < {n}; ++j) {{",
            "        s->p[j] = p[j];",
            "        const double level = s->a[j] * s->f[j] + s->b[j] * scale[j];",
            "        int side;",
            "        r[j] = level - s->y[j];",
            "        moves[j] = fabs(qd[j]) > speed;",
            "        lim[j] = thr[j];",
            "        if (moves[j]) lim[j] += share[j] * fabs(level);",
            *(["        else {   /* at rest: the torque outside the static friction band at the adapted level */",
               "            const double half = s->a[j] * band[j], off = s->b[j] * scale[j];",
               "            const double lo = off - half, hi = off + half;",
               "            const double c = s->y[j] < lo ? lo : (s->y[j] > hi ? hi : s->y[j]);",
               "            r[j] = c - s->y[j];", "        }"] if band is not None else []),
            "        mag[j] = fabs(r[j]);",
            "        side = r[j] > lim[j] ? 1 : (r[j] < -lim[j] ? -1 : 0);",
            "        s->run[j] = side == 0 ? 0 : (side == s->side[j] ? s->run[j] + 1 : 1);",
            "        s->side[j] = side;",
            "        s->contact[j] = s->contact[j] ? mag[j] >= release * lim[j] : s->run[j] >= persistence;",
            "        tau_ext[j] = r[j];", "        contact[j] = s->contact[j];", "        tau_f[j] += e[j];", "    }"]
    if adaptation is not None:
        lo, hi = (c.num(v) for v in ad.scale_bounds)
        out += ["    if (!s->adapt_started) { s->adapt_started = 1; s->t_adapt = t; return; }",
                "    {",
                f"        const double lam = fmax(exp(-(t - s->t_adapt) / {c.num(ad.time_constant)}), "
                f"{c.num(observer.FORGET_MIN)});",
                f"        const double freeze = {c.num(ad.freeze)}, holdoff = {c.num(ad.holdoff)}, "
                f"pmax = {c.num((2.0 if ad.offset else 1.0) * ad.initial_covariance)}, x2 = {'1.0' if ad.offset else '0.0'};",
                "        s->t_adapt = t;",
                f"        for (j = 0; j < {n}; ++j) {{",
                "            const double x1 = s->f[j] / scale[j], e = -r[j] / scale[j];",
                "            const double g1 = s->P11[j] * x1 + s->P12[j] * x2, g2 = s->P12[j] * x1 + s->P22[j] * x2;",
                "            const double den = lam + x1 * g1 + x2 * g2;",
                "            const double k1 = g1 / den, k2 = g2 / den;",
                "            double an = s->a[j] + k1 * e, bn = s->b[j] + k2 * e;",
                "            const double n11 = (s->P11[j] - k1 * g1) / lam, n12 = (s->P12[j] - k1 * g2) / lam;",
                "            const double n22 = " + ("(s->P22[j] - k2 * g2) / lam" if ad.offset else "s->P22[j]")
                + ", tr = n11 + n22 * x2;",
                "            const double cap = tr > pmax ? pmax / tr : 1.0;",
                "            if (s->contact[j]) s->suspected[j] = t;",
                "            if (!(moves[j] && mag[j] <= freeze * lim[j] && t - s->suspected[j] >= holdoff)) continue;",
                f"            an = an < {lo} ? {lo} : (an > {hi} ? {hi} : an);",
                f"            bn = bn < -{c.num(ad.offset_bound)} ? -{c.num(ad.offset_bound)} : "
                f"(bn > {c.num(ad.offset_bound)} ? {c.num(ad.offset_bound)} : bn);",
                "            s->a[j] = an; s->b[j] = bn;",
                "            s->P11[j] = n11 * cap; s->P12[j] = n12 * cap; s->P22[j] = n22 * cap;",
                "        }", "    }"]
    out.append("}")
    return "\n".join(out) + "\n"


def export(source: str, prefix: str, gain: float, thresholds: observer.Thresholds | None,
           adaptation: observer.Adaptation | None) -> str:
    """The header of ``fricli export MODELS --observer``: each joint's friction functions
    (``PREFIX_<file>_*``, as ``fricli export``; a coupled group's, one per member: ``_joints``) and the arm's
    (``PREFIX_arm_*``)."""
    c.check_prefix(prefix)
    paths, _ = c.model_paths(source)
    entries = [joint for entry in c.entries_for(paths, prefix, per_joint=True) for joint in _joints(entry)]
    text = c.header(entries, prefix)
    end = f"#endif /* FRICLI_{prefix.upper()}_H */"
    arm = arm_code(entries, prefix, gain, thresholds, adaptation)
    own = f"{prefix}_arm"
    for entry in entries:   # the arm's functions take PREFIX_arm_*: a model file named arm would define them too
        clash = sorted(n for n in c.names_of(entry.prefix, text) | {entry.prefix}
                       if n == own or n.startswith(own + "_"))
        if clash:
            raise ModelFileError(f"{entry.source} gives the C name {clash[0]}, which the arm's functions of --observer "
                                 "use: rename the file")
    top = ("/* The arm's observer, adaptation and contact detection (fricli export --observer) follow the joints' "
           "friction\n * functions: " + os.path.basename(source.rstrip("/")) + ". See docs/contact-detection.md. */\n")
    return text.replace(end, top + arm + "\n" + end)
