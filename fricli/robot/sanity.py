"""Does the mapping agree with the robot model? A check of a fresh import against its URDF.

A mapping written by hand goes wrong in a few ways that an import cannot see by itself: a joint's
zero a quarter or half turn away from the URDF's (an encoder offset left out), a joint turning the
other way than the URDF's axis (a sign), a joint's motion in degrees read as radians (or mm as m,
and the reverse; joint-side mappings), a gear ratio or drive gain off by a large factor (a
joint-side torque's, a unit's 1000 among them: ``_torque_scales``), a coupling term of a wrist
guessed wrong. Each leaves ``tau_m`` far from what the robot model and
friction explain. ``check`` scores the mapping as it is and under each such change:

    score   motor by motor (joint by joint without a transmission), the sum of squares that the
            least-squares fit  tau_motor - R^-T tau_g  ~  a R^-T tau_dyn + Fv w + Fc sign(w) + c
            leaves, with w = R qd the motor velocity (friction lives in the motors; a free gain a on
            tau_dyn, whose rotor inertias are often unknown); tau_g enters with its own scale, 1
    gain    sum over the motors of 1 - score_changed / score_now: 1 is one motor's residual gone

A change whose gain is at least ``GAIN_MIN`` explains the torques much better than the mapping:
it is reported with the joint, the likely mistake, the mapping line that makes it, and the RMS
before and after. The changes are scored on ``ROWS`` rows evenly spaced over the recording; the
robot model's terms are recomputed for each (positions, velocities and accelerations change with
a zero, a sign or a ratio). Every change is first screened on ``SCREEN_ROWS`` of those rows; those
whose gain there is at least ``GAIN_MIN / 2`` are scored (and a ratio's factor refined) on all of
them. Up to ``MAX_FINDINGS`` changes are found one after the other (each applied before the next is
looked for).

Alongside, per joint: the correlation and the least-squares scale of tau_m against the model's
torque tau_g + tau_dyn, the figures a user checks first.
"""

from __future__ import annotations

import math

import numpy as np

ROWS = 2000
SCREEN_ROWS = 400
GAIN_MIN = 0.5
MAX_FINDINGS = 3
QUARTERS = (1, 2, -1)                      # zero offsets tried: +pi/2, pi, -pi/2
GROSS = (0.8, 1.25)                        # a diagonal ratio's or drive gain's factor inside this is no mistake
FACTORS = np.geomspace(0.25, 4.0, 41)      # factors tried on a ratio term (then refined)
# a joint-side torque whose least-squares scale against the robot model's is about 1/1000 or 1000 (within
# a factor UNIT_WITHIN), and which that factor explains (``_torque_scales``): a current or torque in the wrong unit
UNIT, UNIT_WITHIN = 1e3, 2.0
# a joint's motion (q, qd, qdd) in another unit than the mapping says, by the joint's kind: (the factor
# that makes it right, the unit it is in, the unit the mapping gave)
UNIT_SLIPS = {"rotary": ((math.pi / 180, "deg", "rad"), (180 / math.pi, "rad", "deg")),
              "linear": ((1e-3, "mm", "m"), (1e3, "m", "mm"))}
LIMIT_MARGIN = 0.05   # a position within this share of the span beyond a URDF limit is within it


class _Case:
    """Joint-side samples (n, k) in the mapping's order, the ratio R and what the model gives
    (``terms``, or ``given``: its (tau_g, tau_dyn) when the samples' motion is that of a case's)."""

    def __init__(self, q, qd, qdd, tau, ratio, terms, given=None):
        self.q, self.qd, self.qdd, self.tau, self.ratio = q, qd, qdd, tau, ratio
        self.g, self.d = terms(q, qd, qdd) if given is None else given

    def take(self, rows: np.ndarray) -> "_Case":
        """The same case on ``rows`` only."""
        return _Case(self.q[rows], self.qd[rows], self.qdd[rows], self.tau[rows], self.ratio, None,
                     (self.g[rows], self.d[rows]))

    def residual_ss(self) -> np.ndarray:
        """The score of every motor (k,) and the residuals (n, k) [Nm, motor side]."""
        rit = np.linalg.inv(self.ratio).T
        e = (self.tau - self.g) @ rit.T
        dyn = self.d @ rit.T
        w = self.qd @ self.ratio.T
        ss, res = np.zeros(e.shape[1]), np.zeros_like(e)
        for m in range(e.shape[1]):
            a = np.column_stack([dyn[:, m], w[:, m], np.sign(w[:, m]), np.ones(len(w))])
            coef = np.linalg.lstsq(a, e[:, m], rcond=None)[0]
            res[:, m] = e[:, m] - a @ coef
            ss[m] = float(res[:, m] @ res[:, m])
        return ss, res


def _with_ratio(case: _Case, new: np.ndarray, terms) -> _Case:
    """The samples as the mapping with ratio ``new`` instead of ``case.ratio`` reads them: the motor
    angles, velocities and torques stay; q = R'^-1 R q, tau = R'^T R^-T tau."""
    a = np.linalg.solve(new, case.ratio)
    b = new.T @ np.linalg.inv(case.ratio).T
    return _Case(case.q @ a.T, case.qd @ a.T, case.qdd @ a.T, case.tau @ b.T, new, terms)


def _gain(ss0: np.ndarray, ss1: np.ndarray) -> float:
    return float(np.sum(1.0 - ss1 / np.maximum(ss0, 1e-300)))


def check(model, mapping, order: list[int], per_joint: list[dict], transmission=None) -> dict:
    """The check of an import with ``model`` (``RobotModel``) of the joints of ``mapping`` (their
    signals ``per_joint`` after ``importing.robot_terms``, ``order``: each one's URDF joint) and the
    mapping's ``transmission`` (None: none). Returns {"joints": {name: figures}, "findings": [...]};
    each finding has ``joint``, ``cause``, ``line`` (the mapping's fix), ``rms_before``/``rms_after``
    [Nm] and ``message``. Empty when a joint lacks q or tau_m."""
    names = [str(jm.name) for jm in mapping.joints]
    if not per_joint or not all("q" in s and "tau_m" in s and "qd" in s and "qdd" in s for s in per_joint):
        return {"joints": {}, "findings": []}
    n = len(per_joint[0]["q"])
    edge = n // 50                                   # derived accelerations ring at the ends
    rows = np.unique(np.linspace(edge, n - 1 - edge, min(ROWS, max(n - 2 * edge, 1))).astype(int))
    stack = lambda c: np.column_stack([s[c][rows] for s in per_joint])  # noqa: E731
    q, qd, qdd, tau = stack("q"), stack("qd"), stack("qdd"), stack("tau_m")
    k = len(names)
    inverse = [order.index(j) for j in range(k)]
    inertia = np.array([mapping.joints[i].rotor_inertia for i in inverse], dtype=float)
    cross = transmission.cross_inertia() if hasattr(transmission, "cross_inertia") else np.zeros((k, k))

    def terms(qq, vv, aa):
        g, d = model.terms(qq[:, inverse], vv[:, inverse], aa[:, inverse], inertia)
        return g[:, order], d[:, order] + aa @ cross.T

    ratio = np.array(transmission.ratio, dtype=float) if transmission is not None else np.eye(k)
    # a motor's unit is no joint's: the motion's units are tried on joint-side mappings only
    slips = None if transmission is not None else _unit_slips(q, [model.kinds[j] for j in order], model.limits[order])
    cross = cross if cross.shape == (k, k) else np.zeros((k, k))
    case = _Case(q, qd, qdd, tau, ratio, terms)
    figures = {name: _figures(case, i) for i, name in enumerate(names)}
    findings = []
    if transmission is None:
        findings, case = _torque_scales(case, names, units_only=True)
    given = getattr(transmission, "offset", None)
    offset = None if transmission is not None and given is None else \
        np.array(given, dtype=float) if transmission is not None else np.zeros(k)
    screen_rows = np.unique(np.linspace(0, len(rows) - 1, SCREEN_ROWS).astype(int)) \
        if len(rows) > SCREEN_ROWS else None
    for _ in range(MAX_FINDINGS):
        ss0, _ = case.residual_ss()
        screen = case if screen_rows is None else case.take(screen_rows)
        best = None
        for hyp in _hypotheses(screen, case, terms, ss0, slips):
            ss1, _ = hyp["case"].residual_ss()
            gain = _gain(ss0, ss1)
            if best is None or gain > best["gain"]:
                best = dict(hyp, gain=gain, ss1=ss1)
        if best is None or best["gain"] < GAIN_MIN:
            break
        m = int(np.argmax(1.0 - best["ss1"] / np.maximum(ss0, 1e-300)))
        before = math.sqrt(ss0[m] / len(rows))
        after = math.sqrt(best["ss1"][m] / len(rows))
        finding = _describe(best, names, case, offset, transmission is not None, m, before, after)
        findings.append(finding)
        if best["kind"] == "offset" and offset is not None:
            offset = offset - best["delta"] * case.ratio[:, best["joint"]]
        case = best["case"]
    if transmission is None:
        more, case = _torque_scales(case, names, units_only=False)
        findings += more
    return {"joints": figures, "findings": findings}


def _figures(case: _Case, i: int) -> dict:
    """Joint i's torque against the robot model's tau_g + tau_dyn: their correlation (None when
    either is constant), the least-squares scale of tau_m on it, and both RMS [Nm]."""
    model_tau, tau = case.g[:, i] + case.d[:, i], case.tau[:, i]
    sd = float(np.std(model_tau)) * float(np.std(tau))
    denom = float(model_tau @ model_tau)
    return {"correlation": float(np.corrcoef(model_tau, tau)[0, 1]) if sd > 0 else None,
            "scale": float(model_tau @ tau) / denom if denom > 0 else None,
            "rms_tau_m": float(np.sqrt(np.mean(tau ** 2))), "rms_model": float(np.sqrt(np.mean(model_tau ** 2)))}


def _torque_scales(case: _Case, names: list[str], units_only: bool) -> tuple[list[dict], _Case]:
    """Findings of joint-side torques whose least-squares scale against the robot model's torque
    tau_g + tau_dyn (``_figures``) lies outside ``GROSS`` and whose inverse explains them (a drive
    gain off; about 1/UNIT or UNIT: a unit), and ``case`` with them corrected. Judged by the share
    of the torque's variance the fit leaves unexplained, which no scale of the torque changes by
    itself (its residual does, so the hypotheses of ``check`` do not scale a joint-side torque):
    the factor must leave at most half of it, and half of what is left without it. ``units_only``:
    the units alone (they come first: a torque mapped 1000 times too small lets any change that
    shrinks the model's torques win; the other factors come last, once the positions are right)."""
    findings = []
    for i, name in enumerate(names):
        fig = _figures(case, i)
        corr, scale = fig["correlation"], fig["scale"]
        if scale is None or not scale > 0 or GROSS[0] <= scale <= GROSS[1]:
            continue
        f, why = 1.0 / scale, ("a drive gain (kt) or a gear ratio off, or the robot model's own error: the URDF's "
                               "masses (fricli calibrate) or a payload not declared (--payload-mass)")
        for unit, text in ((UNIT, "a current in A mapped as mA or a torque in Nm mapped as mNm"),
                           (1 / UNIT, "a current in mA mapped as A or a torque in mNm mapped as Nm")):
            if abs(math.log(scale * unit)) <= math.log(UNIT_WITHIN):
                f, why = unit, text
        if units_only != (f in (UNIT, 1 / UNIT)):
            continue
        ss0, _ = case.residual_ss()
        s = np.where(np.arange(len(names)) == i, f, 1.0)
        fixed = _Case(case.q, case.qd, case.qdd, case.tau * s, case.ratio, None, (case.g, case.d))
        ss1, _ = fixed.residual_ss()
        left0, left1 = (ss[i] / max(float(np.sum((x - x.mean()) ** 2)), 1e-300)
                        for ss, x in ((ss0, case.tau[:, i]), (ss1, fixed.tau[:, i])))
        if not (left1 <= GAIN_MIN and left1 <= GAIN_MIN * left0):
            continue
        case, n = fixed, len(case.tau)
        before, after = math.sqrt(ss0[i] / n), math.sqrt(ss1[i] / n)
        line = f"joint {name}'s tau_m: scale multiplied by {f:.4g}"
        told = "" if corr is None else f"; correlation {corr:.2f}"
        message = (f"joint {name}: its torque is x{scale:.3g} of the robot model's, {why} (least-squares "
                   f"scale{told}): what the robot model and friction leave of joint {name}'s tau_m "
                   f"falls from {before:.3g} to {after:.3g} Nm RMS with {line}")
        findings.append({"joint": name, "cause": "torque-scale", "line": line, "rms_before": before,
                         "rms_after": after, "gain": float(1.0 - ss1[i] / max(ss0[i], 1e-300)),
                         "message": message})
    return findings, case


def _unit_slips(q: np.ndarray, kinds: list[str], limits: np.ndarray) -> list[tuple]:
    """The unit slips (``UNIT_SLIPS``) worth trying on positions q (n, k) of joints of ``kinds`` with
    URDF ``limits`` (k, 2) (NaN: none): (joint index, or None for every joint; factor; unit; the
    mapping's unit). Motion read 57 (or 1000) times too small makes every torque of the robot
    model small: it would explain a torque mapped in the wrong unit as well. So a slip that shrinks
    the motion is tried only where a position read as the mapping says lies beyond its limits and
    within them once shrunk; one that enlarges it only where it stays within them."""
    span = limits[:, 1] - limits[:, 0]
    inside = lambda x: (~np.isfinite(span)) | ((x.min(axis=0) >= limits[:, 0] - LIMIT_MARGIN * span)  # noqa: E731
                                              & (x.max(axis=0) <= limits[:, 1] + LIMIT_MARGIN * span))
    as_read = inside(q)
    out = []
    for kind in sorted(set(kinds)):
        mine = np.array([k == kind for k in kinds])
        for factor, unit, said in UNIT_SLIPS[kind]:
            fits = inside(q * factor)
            ok = fits & ~as_read & np.isfinite(span) if factor < 1 else fits
            if mine.all() and len(kinds) > 1 and fits.all() and (factor > 1 or ok.any()):
                out.append((None, factor, unit, said))
            out += [(i, factor, unit, said) for i in np.flatnonzero(mine & ok)]
    return out


def _hypotheses(screen: _Case, case: _Case, terms, ss_case: np.ndarray, slips: list[tuple] | None = None):
    """Every change tried (zeros, directions, torque signs, the unit ``slips`` of the joints' motion,
    ratio terms), screened on ``screen`` (some of ``case``'s rows, or ``case``): those that come
    near a finding there, made on ``case`` (whose scores are ``ss_case``)."""
    k = case.q.shape[1]
    ss_screen, _ = screen.residual_ss()
    near = lambda c: _gain(ss_screen, c.residual_ss()[0]) >= GAIN_MIN / 2    # noqa: E731

    def rescaled(c, s):
        return _Case(c.q * s, c.qd * s, c.qdd * s, c.tau, c.ratio, terms)

    # a recorder writes every joint in one unit: the whole arm's slip too (one joint's alone would
    # leave the others' torques, which its angle enters, worse)
    for joint, factor, unit, said in slips or ():
        s = np.full(k, factor) if joint is None else np.where(np.arange(k) == joint, factor, 1.0)
        if near(rescaled(screen, s)):
            yield {"kind": "unit", "joint": joint, "unit": unit, "said": said, "case": rescaled(case, s)}
    for i in range(k):
        for quarter in QUARTERS:
            def moved(c, i=i, quarter=quarter):
                q = c.q.copy()
                q[:, i] += quarter * math.pi / 2
                return _Case(q, c.qd, c.qdd, c.tau, c.ratio, terms)
            if near(moved(screen)):
                yield {"kind": "offset", "joint": i, "delta": quarter * math.pi / 2, "case": moved(case)}
        flip = case.ratio.copy()
        flip[:, i] = -flip[:, i]
        if near(_with_ratio(screen, flip, terms)):
            yield {"kind": "direction", "joint": i, "case": _with_ratio(case, flip, terms)}
        d = np.eye(k)
        d[i, i] = -1.0
        sign = case.ratio.T @ d @ np.linalg.inv(case.ratio).T     # motor i's torque reversed
        def reversed_(c, sign=sign):      # the same motion: the model's terms are the case's
            return _Case(c.q, c.qd, c.qdd, c.tau @ sign.T, c.ratio, None, (c.g, c.d))
        if near(reversed_(screen)):
            yield {"kind": "torque-sign", "joint": i, "motor": i, "case": reversed_(case)}
    for m in range(k if slips is None else 0):    # a joint-side torque's scale: ``_torque_scales``
        for j in range(k):
            if case.ratio[m, j] == 0.0:
                continue
            hyp = _best_factor(screen, case, terms, m, j, ss_screen, ss_case)
            if hyp is not None:
                yield hyp


def _best_factor(screen: _Case, case: _Case, terms, m: int, j: int, ss_screen: np.ndarray, ss_case: np.ndarray):
    """The ratio term R[m, j] times the factor that explains the torques best (a grid on ``screen``,
    refined on ``case`` when it comes near ``GAIN_MIN``), or None for a diagonal term within ``GROSS``
    (a gear ratio is a small integer's ratio off, not a few percent: those are the robot model's own
    errors)."""

    def scaled(c, f):
        new = c.ratio.copy()
        new[m, j] *= f
        try:
            return _with_ratio(c, new, terms)
        except np.linalg.LinAlgError:
            return None

    def cost(c, ss0, f):
        s = scaled(c, f)
        return -math.inf if s is None else _gain(ss0, s.residual_ss()[0])

    grid = FACTORS[(FACTORS < GROSS[0]) | (FACTORS > GROSS[1])] if m == j else FACTORS
    gains = [cost(screen, ss_screen, f) for f in grid]
    i = int(np.argmax(gains))
    if gains[i] < GAIN_MIN / 2:
        return None                                  # nowhere near a finding: no need to refine
    at_grid = gains[i] if screen is case else cost(case, ss_case, grid[i])
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    from scipy.optimize import minimize_scalar

    res = minimize_scalar(lambda x: -cost(case, ss_case, math.exp(x)), bounds=(math.log(lo), math.log(hi)),
                          method="bounded", options={"xatol": 1e-4})
    f = math.exp(res.x) if -res.fun >= at_grid else float(grid[i])
    if m == j and GROSS[0] <= f <= GROSS[1]:
        return None
    c = scaled(case, f)
    return None if c is None else {"kind": "ratio", "motor": m, "joint": j, "factor": f, "case": c}


def _matrix(r: np.ndarray) -> str:
    return "[" + ", ".join("[" + ", ".join(f"{x:.4g}" for x in row) + "]" for row in r) + "]"


def _describe(best: dict, names: list[str], case: _Case, offset: np.ndarray, motor_side: bool, m: int,
              before: float, after: float) -> dict:
    i = best["joint"]
    joint = names[i] if i is not None else ", ".join(names)    # None: every joint
    where = f"motor {m + 1}'s torque" if motor_side else f"joint {names[m]}'s tau_m"
    fig = f"what the robot model and friction leave of {where} falls from {before:.3g} to {after:.3g} Nm RMS"
    kind = best["kind"]
    if kind == "offset":
        turn = {1: "+pi/2", 2: "pi", -1: "-pi/2"}[round(best["delta"] / (math.pi / 2))]
        cause = f"its zero is {turn} away from the URDF's (an encoder offset left out?)"
        if motor_side and offset is None:
            line = f"joint {joint}'s zero moved by {best['delta']:+.6g} rad ([transmission] offset)"
        elif motor_side:
            new = offset - best["delta"] * case.ratio[:, i]
            line = f"[transmission] offset = [{', '.join(f'{x:.6g}' for x in new)}]"
        else:
            line = f"joint {joint}'s q: {best['delta']:+.6g} rad added to its offset (converted to the column's unit)"
    elif kind == "direction":
        cause = "it turns the other way than the URDF's axis (a sign)"
        if motor_side:
            new = case.ratio.copy()
            new[:, i] = -new[:, i]
            line = f"[transmission] ratio = {_matrix(new)} (the joint's column negated)"
        else:
            line = f"joint {joint}'s q, qd and tau_m: scale negated"
    elif kind == "unit":
        cause = (f"{'its' if i is not None else 'their'} position and velocity are in {best['unit']}, read as "
                 f"{best['said']}")
        line = (f"{'joint ' + joint if i is not None else 'every joint'}'s q and qd: unit \"{best['unit']}\" and "
                f"\"{best['unit']}/s\" in the mapping")
    elif kind == "torque-sign":
        cause = f"{'motor ' + str(i + 1) + ' of' if motor_side else 'its'} torque has the wrong sign"
        line = (f"joint {joint}'s tau_motor: scale negated" if motor_side else f"joint {joint}'s tau_m: scale negated")
    else:
        mm, f = best["motor"], best["factor"]
        old = case.ratio[mm, i]
        new = case.ratio.copy()
        new[mm, i] = old * f
        if mm == i and motor_side:
            cause = f"its gear ratio is {old:.6g} in the mapping, {old * f:.4g} fits (a ratio or a drive gain off by x{f:.3g})"
            line = f"[transmission] ratio = {_matrix(new)}"
        elif mm == i:
            cause = f"its torque is x{f:.3g} of what the robot model gives (a gear ratio or a drive gain)"
            line = f"joint {joint}'s tau_m: scale multiplied by {f:.4g}"
        else:
            cause = (f"the coupling term of motor {mm + 1} on joint {joint} is {old:.6g} in the mapping; "
                     f"{old * f:.4g} fits")
            line = f"[transmission] ratio = {_matrix(new)} (row {mm + 1}, column {i + 1})"
    message = f"{'joint' if i is not None else 'joints'} {joint}: {cause}: {fig} with {line}"
    return {"joint": joint, "cause": kind, "line": line, "rms_before": before, "rms_after": after,
            "gain": best["gain"], "message": message}


class _Joint:
    def __init__(self, name, rotor_inertia):
        self.name, self.rotor_inertia = name, rotor_inertia


class _Joints:
    def __init__(self, names, rotor_inertia):
        self.joints = [_Joint(n, float(r)) for n, r in zip(names, rotor_inertia)]


class _Ratio:
    """A ratio matrix without the offsets (a log's transmission records no zeros)."""

    def __init__(self, ratio):
        self.ratio = ratio


def check_motion(model, motion, ratio: np.ndarray | None) -> dict:
    """``check`` of a whole-arm log in the URDF's order (``calibration.Motion``) and the full ratio
    matrix of its motors (URDF order; None: one motor per joint): what ``fricli calibrate`` runs."""
    per_joint = [{"q": motion.q[:, j], "qd": motion.qd[:, j], "qdd": motion.qdd[:, j], "tau_m": motion.tau[:, j]}
                 for j in range(motion.q.shape[1])]
    joints = _Joints(motion.names, np.nan_to_num(motion.rotor_inertia))
    transmission = None if ratio is None or np.array_equal(ratio, np.eye(len(ratio))) else _Ratio(ratio)
    return check(model, joints, list(range(len(per_joint))), per_joint, transmission)
