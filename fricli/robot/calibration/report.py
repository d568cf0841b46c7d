"""What a calibration reports: the motors' and the friction's tables, each body's mass, centre of
mass and inertia, physical consistency and the parameters far from CAD."""

from __future__ import annotations

import numpy as np

from fricli.core.errors import FitError
from fricli.robot.calibration.motion import Motion, reflected
from fricli.robot.calibration.parameters import FRICTION, _pin, pseudo_inertia
from fricli.robot.calibration.result import Calibration


SUSPICIOUS = 0.30          # a mass or armature this far from its prior value is flagged
TOLERANCE = 1e-9           # relative: a body on the boundary of consistency (a thin rod, a point) passes
OTHER_CAUSES = ("a drive gain off by a similar share on the joints that carry it", "a cable or hose pulling on the arm",
                "a counterbalance spring", "a tool or payload not in the URDF")


def _motor_report(cal: Calibration, motion: Motion) -> dict:
    """Per motor of the transmission: its joint, row of R, prior and identified rotor inertia; and the
    reflected inertia R^T diag(J_m) R of those joints (its off-diagonal: the rotors' cross-term)."""
    nj, listed = len(cal.joints), cal.motors
    joints = [cal.joints[i] for i in listed]
    sub = lambda x: reflected(cal.ratio, x[10 * nj:11 * nj])[np.ix_(listed, listed)].tolist()  # noqa: E731
    return {
        "motors": {cal.joints[m]: {"log_joint": str(motion.names[m]),
                                   "ratio": {cal.joints[j]: float(cal.ratio[m, j]) for j in listed if cal.ratio[m, j]},
                                   "prior": float(cal.x0[10 * nj + m]), "identified": float(cal.x[10 * nj + m])}
                   for m in listed},
        "reflected_inertia": {"joints": joints, "prior": sub(cal.x0), "identified": sub(cal.x)},
    }


def _friction_report(robot, motion: Motion, x: np.ndarray, vs: np.ndarray | None, motors: list[int] | None) -> dict:
    """Friction per log joint, or per motor (named by its joint, ``"motor": true``, in its velocity w)."""
    nj = len(robot.joints)
    rotary = robot.kinds[0] == "rotary"
    units = {"Fv": "Nm s/rad", "Fc": "Nm", "offset": "Nm"} if rotary else {"Fv": "N s/m", "Fc": "N", "offset": "N"}
    joints = {}
    for j in range(nj):
        row = {"urdf_joint": robot.joints[j], **{f: float(x[11 * nj + 3 * j + k]) for k, f in enumerate(FRICTION)}}
        if j in (motors or ()):
            row["motor"] = True
        if vs is not None:
            row.update(Fs=row["Fc"] + float(x[14 * nj + j]), vs=float(vs[j]), delta=2.0)
        joints[str(motion.names[j])] = row
    side = {} if motors is None else {"motors": "a motor's friction f is in its velocity w = (R qd)_m, its "
                                                 "torque in motor units; the joints feel R^T f"}
    if vs is None:
        return {"kind": "linear", "model": "Fv*qd + Fc*sign(qd) + offset", "units": units, "joints": joints, **side}
    units.update(Fs=units["Fc"], vs="rad/s" if rotary else "m/s", delta="-")
    return {"kind": "stribeck", "model": "Fv*qd + (Fc + (Fs - Fc) exp(-|qd/vs|^delta)) sign(qd) + offset",
            "units": units, "joints": joints, **side}


def body_inertias(cal: Calibration, x: np.ndarray | None = None) -> list:
    """pin.Inertia of every body for parameters ``x`` (default the identified ones)."""
    pin = _pin()
    x = cal.x if x is None else x
    # a massless body (a URDF link with no <inertial>, or mass 0) has no centre of mass to divide by
    return [pin.Inertia.FromDynamicParameters(pi) if pi[0] != 0 else pin.Inertia.Zero()
            for pi in (np.asarray(x[10 * b:10 * b + 10], dtype=float) for b in range(len(cal.bodies)))]


def link_table(cal: Calibration) -> dict:
    """Mass [kg], centre of mass [m] and inertia at the centre of mass [kg m^2] of every body, CAD and identified."""
    out = {}
    for body, cad, new in zip(cal.bodies, body_inertias(cal, cal.x0), body_inertias(cal)):
        out[body] = {"mass_cad": float(cad.mass), "mass": float(new.mass),
                     "com_cad": cad.lever.tolist(), "com": new.lever.tolist(),
                     "inertia_cad": cad.inertia.tolist(), "inertia": new.inertia.tolist()}
    return out


def _physical(pi: np.ndarray, scale: float = 0.0) -> str | None:
    """Why the 10 parameters ``pi`` are no real body, or None: the mass positive, the inertia at the
    centre of mass positive definite, its principal moments satisfying the triangle inequality, each to
    ``TOLERANCE`` of the body's largest moment or of ``scale`` [kg m^2] (the arm's: a body the fit
    shrank to nothing must not fail on round-off)."""
    m = float(pi[0])
    if not m > 0:
        return f"mass {m:.4g} kg is not positive"
    inertia = _pin().Inertia.FromDynamicParameters(np.asarray(pi, dtype=float))
    moments = np.sort(np.linalg.eigvalsh(inertia.inertia))
    text = ", ".join(f"{v:.4g}" for v in moments)
    pseudo = np.linalg.eigvalsh(pseudo_inertia(pi))
    if moments[0] <= -TOLERANCE * max(abs(moments[-1]), scale):
        return f"inertia at the centre of mass is not positive definite (principal moments {text} kg m^2)"
    if pseudo[0] < -TOLERANCE * max(pseudo[-1], scale):   # with the above: the triangle inequality
        return f"principal moments {text} kg m^2 break the triangle inequality (no real body has them)"
    return None


def _scale(cal: Calibration) -> float:
    """The largest principal moment at the centre of mass of the CAD bodies [kg m^2]."""
    return max((float(np.abs(np.linalg.eigvalsh(b.inertia)).max()) for b in body_inertias(cal, cal.x0)), default=0.0)


def whole_bodies(cal: Calibration) -> list[bool]:
    """Per body, whether the calibrated URDF writes all of it into its moving link (and gives the links
    fixed to it no inertia): when with those links at CAD the moving link could be no real body."""
    links, scale = cal.links(), _scale(cal)
    return [bool(cal.attached and cal.attached[b]) and _physical(links[10 * b:10 * b + 10], scale) is None
            and _physical(links[10 * b:10 * b + 10] - cal.attached_cad[10 * b:10 * b + 10], scale) is not None
            for b in range(len(cal.bodies))]


def consistency(cal: Calibration) -> dict:
    """Physical consistency: ``problems`` (each body, less a declared payload, a real body (``_physical``);
    each armature (a motor's rotor inertia) not negative) and ``warnings`` (negative friction
    coefficients; a body whose fixed links' CAD its moving link cannot complete, ``whole_bodies``)."""
    problems, warnings = [], []
    nj = len(cal.joints)
    links, scale = cal.links(), _scale(cal)
    for b, body in enumerate(cal.bodies):
        why = _physical(links[10 * b:10 * b + 10], scale)
        if why:
            problems.append(f"link {body}: {why}")
    for b in np.flatnonzero(whole_bodies(cal)):
        names, body, fixed = ", ".join(cal.attached[b]), cal.bodies[b], cal.attached_cad[10 * b:10 * b + 10]
        own = links[10 * b:10 * b + 10] - fixed
        why = ("lighter than they are" if own[0] <= 0 else
               f"and {body} would be no real body with them at CAD ({_physical(own, scale)})")
        warnings.append(f"link {body}: with {names} fixed to it ({fixed[0]:.4g} kg at CAD), its body comes out at "
                        f"{links[10 * b]:.4g} kg, {why}: the calibrated URDF holds the whole body in {body} and no "
                        f"inertia in {names}. The joint torques see only the body they form; a large gap means they "
                        "are not mounted as the URDF says")
    for j in range(nj):
        who, a = cal.motor_of(j), float(cal.x[10 * nj + j])
        if a < 0:
            problems.append(f"{who}: {'rotor inertia' if j in (cal.motors or ()) else 'armature'} {a:.4g} kg m^2 "
                            "is negative")
        fv, fc = cal.x[11 * nj + 3 * j], cal.x[11 * nj + 3 * j + 1]
        if fv < 0 or fc < 0:
            warnings.append(f"{who}: friction Fv {fv:.4g}, Fc {fc:.4g}: a negative coefficient "
                            f"makes the {'motor' if j in (cal.motors or ()) else 'joint'} gain energy")
        if len(cal.x) == 15 * nj and fc + cal.x[14 * nj + j] < 0:
            warnings.append(f"{who}: friction Fs {fc + cal.x[14 * nj + j]:.4g} at zero speed is negative")
    return {"ok": not problems, "problems": problems, "warnings": warnings}


def suspicious(cal: Calibration, tied: dict | None = None) -> list[str]:
    """Parameters far (> SUSPICIOUS) from CAD or from the prior armature (a motor's rotor inertia), with
    the other causes that give the same torque shape. ``tied``: the masses no joint torque determines
    alone, with the parameters they trade with (the excitation report's ``masses_not_determined_alone``)."""
    out = []
    causes = "; ".join(OTHER_CAUSES)
    for body, cad, new in zip(cal.bodies, body_inertias(cal, cal.x0), body_inertias(cal)):
        if cad.mass > 0 and abs(new.mass / cad.mass - 1) > SUSPICIOUS:
            change = f"link {body}: mass {cad.mass:.4g} -> {new.mass:.4g} kg ({100 * (new.mass / cad.mass - 1):+.0f} %)"
            partners = (tied or {}).get(f"{body}.m")
            if partners:
                out.append(f"{change}; no joint torque determines this mass alone: it trades with "
                           f"{', '.join(partners)}, and the prior splits what the data determine between them")
            elif partners is not None:
                out.append(f"{change}; no joint torque sees this mass")
            else:
                out.append(f"{change}; also consistent with: {causes}")
    nj = len(cal.joints)
    # friction rising towards rest peaks where a reversing joint's acceleration does: linear friction
    # leaves it to the inertia
    bump = "" if len(cal.x) == 15 * nj else ("; friction that rises towards rest, which linear friction cannot "
                                             "follow (--friction stribeck fits it)")
    for j in range(nj):
        a0, a = cal.x0[10 * nj + j], cal.x[10 * nj + j]
        if a0 > 0 and abs(a / a0 - 1) > SUSPICIOUS and j in (cal.motors or ()):
            out.append(f"{cal.motor_of(j)}: rotor inertia {a0:.4g} -> {a:.4g} kg m^2 ({100 * (a / a0 - 1):+.0f} %); "
                       "also consistent with: a drive gain off on the joints it drives; a gear ratio off; inertia "
                       f"of those links' own axes that the data cannot tell from the rotor's{bump}")
        elif a0 > 0 and abs(a / a0 - 1) > SUSPICIOUS:
            out.append(f"joint {cal.joints[j]}: armature {a0:.4g} -> {a:.4g} kg m^2 ({100 * (a / a0 - 1):+.0f} %); "
                       "also consistent with: a drive gain off on that joint; inertia of the link's own axis "
                       f"that the data cannot tell from the armature{bump}")
        fc, offset = cal.x[11 * nj + 3 * j + 1], cal.x[11 * nj + 3 * j + 2]
        if fc >= 0 and abs(offset) > fc:     # a negative Fc: the warning of ``consistency``
            out.append(f"{cal.motor_of(j)}: friction offset {offset:.4g} exceeds its Coulomb level {fc:.4g}: a "
                       "torque the rigid-body model does not explain is taken for friction; also consistent with: "
                       f"{causes}")
    return out


def warnings(report: dict) -> list[str]:
    """The lines a calibration's report warns of: a consistent fit stopped short of its optimum,
    consistency warnings, then suspicious parameters."""
    enforced = report.get("consistency_enforced") or {}
    short = [] if enforced.get("converged", True) else [
        f"the physically consistent fit stopped after {enforced['newton_steps']} Newton steps, up to "
        f"{enforced['optimality_gap']:.3g} (weighted cost) above its optimum: the calibrated parameters may "
        "still move; excite the arm more or tighten the prior (--prior)"]
    return short + report["consistency"]["warnings"] + report["suspicious"]


def refuse_inconsistent(cal: Calibration) -> None:
    """FitError (exit 5) when the identified model is physically impossible."""
    problems = cal.report["consistency"]["problems"]
    if problems:
        raise FitError(f"the identified model is physically inconsistent: {'; '.join(problems)}; excite the arm "
                       "more, tighten the prior (--prior) or enforce consistency (--consistency enforce)")
