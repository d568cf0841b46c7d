"""Rerun the UR10e case study: CSV recordings + URDF -> fricli models for the six joints,
validated on runs of other days; writes docs/studies/case-study-ur10e.md and docs/studies/img/ur10e-*.png.

    python studies/ur10e/run_case_study.py                      # the whole study (about 70 s on 2 cores)
    python studies/ur10e/run_case_study.py --joints 6 --runs 1 --out /tmp/x   # a small part

Every model comes from the fricli command line, run as a user would (the commands are
printed and listed in the document). The script itself only computes what fricli has no
command for: the standard linear friction model fitted by least squares (the baseline), the
dataset authors' published friction parameters, and the payload's reference torque (the
difference of two imports of the payload run, with and without the payload in the URDF).
Data: ../shared/data/ur10e (see ../shared/data/README.md), or --data.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

from fricli.core import logs, metrics  # noqa: E402
from fricli.fitting import learning  # noqa: E402
from fricli.core.atomic import atomic_write_bytes  # noqa: E402
from ur10e_neural import PAIRS  # noqa: E402  days with two runs: adapt on one, score on the other

DEFAULT_DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "ur10e")
MAPPING = os.path.join(ROOT, "docs", "ur10e-mapping.toml")
JOINTS = (1, 2, 3, 4, 5, 6)
CUTOFF_HZ = 10.0  # qdd for the robot model: zero-phase low-pass, far above the excitation (< 1 Hz)
FIT_RUN = "ur-20_02_19_14harm50sec"          # the fitting run (19 Feb 2020)
LOAD_RUN = "ur-20_02_19_14harm50secLoad"     # the same trajectory with the payload, same day
PAYLOAD = {"mass": 2.805, "com": (0.0, 0.0, 0.0), "frame": "tool0"}  # kg, m in the flange frame
SEEN_SPLIT = 0.5   # the payload the joints carry is identified before this share of the payload run
PUBLISHED = {1: (21.26, 12.55, 0.196), 2: (20.22, 13.27, -0.754), 3: (10.38, 4.99, 0.198),
             4: (3.58, 2.00, 0.055), 5: (2.49, 2.69, -0.010), 6: (3.03, 2.30, 0.043)}  # Fv, Fc, offset
FLOOR_HZ = 2.0  # the error above this frequency is not friction a model of the state can follow
TARGET_MEAN, TARGET_EXT = 0.66, 0.65   # mean ratio in motion; payload error ratio, joints 2 and 3

COMMANDS: list[str] = []


def fricli(*args: str, json_out: bool = False, skip: bool = False):
    """Run one fricli command as a user would; returns its JSON output when asked. ``skip``
    only records it (its output is already there)."""
    shown = " ".join(a if " " not in a else repr(a) for a in args)
    COMMANDS.append(shown)
    if skip:
        return None
    print(f"$ fricli {shown}", file=sys.stderr, flush=True)
    done = subprocess.run([sys.executable, "-m", "fricli", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    if done.returncode != 0:
        raise SystemExit(f"fricli {shown} failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout) if json_out else done.stderr


def validation_runs(data: str) -> list[str]:
    """Every identification run recorded on another day than the fitting run."""
    names = sorted(f[:-4] for f in os.listdir(os.path.join(data, "identification")) if f.endswith(".csv"))
    day = FIT_RUN[:11]
    return [n for n in names if not n.startswith(day)]


def import_run(data: str, work: str, name: str, urdf: str, tag: str, payload: dict | None = None,
               keep: bool = False, suffix: str = "payload") -> str:
    """``fricli import`` of one run with ``urdf`` (the CAD one or the calibrated one, ``tag``),
    with ``payload`` (mass, com, frame) declared if given."""
    out = os.path.join(work, f"{name}-{tag}{'-' + suffix if payload else ''}.parquet")
    args = ["import", os.path.join(data, "identification", name + ".csv"), "--mapping", MAPPING,
            "--urdf", urdf, "--cutoff", str(CUTOFF_HZ), "-o", out, "-q"]
    if payload:
        args += ["--payload-mass", f"{payload['mass']:.6g}", "--payload-com", *(f"{c:.6g}" for c in payload["com"]),
                 "--payload-frame", payload["frame"]]
    fricli(*args, skip=keep and os.path.exists(out))
    return out


def signals(path: str, joint: int) -> dict[str, np.ndarray]:
    return logs.load_log(path, joint=str(joint)).signals


def linear_columns(sig: dict[str, np.ndarray]) -> np.ndarray:
    """The standard model's regressor [qd, sign(qd), 1], shape (n, 3)."""
    qd = sig["qd"]
    return np.column_stack([qd, np.sign(qd), np.ones_like(qd)])


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def torque_errors(pred_of, val_logs: list[str], joint: int) -> dict[str, float]:
    """RMS of tau_m minus the whole model (tau_g + tau_dyn of the log's robot model + the friction
    prediction) over all validation rows, over the rows in motion and over those at rest; and the RMS
    of the error's part above FLOOR_HZ (zero-phase high-pass), which no model of q, qd, qdd and tau_g
    follows: the excitation lies below 1 Hz. With the same robot model for two friction models this
    is the RMS of their friction errors; it also compares logs of different robot models. And the
    RMS in motion once each run's own Fv, Fc, offset are added, fitted on that run: what the error
    would be if the model knew each day's friction level, which no model fitted on another day does;
    that level per run (``run_levels``: Fv, Fc, offset, and the controller's clock at the run's start)."""
    from scipy import signal

    every, moving, fast, fast_moving, own, levels = [], [], [], [], [], []
    for path in val_logs:
        sig = signals(path, joint)
        e = logs.friction_target(sig) - pred_of(path, sig)
        mv = metrics.in_motion(sig["qd"])
        cols = linear_columns(sig)[mv]          # the run's own friction level, fitted on itself
        level = np.linalg.lstsq(cols, e[mv], rcond=None)[0]
        own.append(e[mv] - cols @ level)
        levels.append({"start": float(sig["t"][0]), "Fv": float(level[0]), "Fc": float(level[1]),
                       "offset": float(level[2])})
        sos = signal.butter(4, FLOOR_HZ, btype="high", fs=1.0 / np.median(np.diff(sig["t"])), output="sos")
        hf = signal.sosfiltfilt(sos, e)
        every.append(e)
        moving.append(e[mv])
        fast.append(hf)
        fast_moving.append(hf[mv])
    every, moving = np.concatenate(every), np.concatenate(moving)
    return {"all": rms(every), "moving": rms(moving), "rest_share": 1.0 - moving.size / every.size,
            "above_floor": rms(np.concatenate(fast)), "above_floor_moving": rms(np.concatenate(fast_moving)),
            "own_friction_moving": rms(np.concatenate(own)), "run_levels": levels}


def predicted(model: str, path: str, joint: int) -> np.ndarray:
    """tau_f_pred of ``model`` on one joint of a log: what ``fricli predict`` writes (same code,
    called in-process: the validation takes 6 x 11 predictions per model)."""
    return predicting_model(model).predict(signals(path, joint))[0]


_MODELS: dict = {}


def predicting_model(path: str):
    if path not in _MODELS:
        from fricli import models

        _MODELS[path] = models.load(path)[0]
    return _MODELS[path]


def estimated_external(model: str, path: str, joint: int, work: str) -> np.ndarray:
    out = os.path.join(work, f"ext-j{joint}-{os.path.basename(path)}")
    fricli("estimate-ext", model, path, "--joint", str(joint), "-o", out, "-q")
    table = logs.read_table(out)[0]
    return np.asarray(table.column("tau_ext_pred").to_numpy(), dtype=np.float64)


def linear_fit(path: str, joint: int) -> np.ndarray:
    """The standard model's Fv, Fc, offset: least squares on the friction target of one run."""
    sig = signals(path, joint)
    return np.linalg.lstsq(linear_columns(sig), logs.friction_target(sig), rcond=None)[0]


def study(data: str, work: str, joints, runs: int | None, keep: bool = False, adapt: bool = True,
          calibrate_friction: str | None = None) -> dict:
    cad = os.path.join(data, "ur10e.urdf")
    cal, idim_urdf = os.path.join(work, "ur10e-cal.urdf"), os.path.join(work, "ur10e-idim.urdf")
    val_names = validation_runs(data)[:runs] if runs else validation_runs(data)
    # the path: import with the CAD URDF, identify, diagnose --fix --calibrate (docs/diagnose.md)
    fit_cad = import_run(data, work, FIT_RUN, cad, "cad", keep=keep)
    lugre_cad, fixed_cad, fixed = (os.path.join(work, d) for d in ("lugre-cad", "fixed-cad", "fixed"))
    fricli("identify", fit_cad, "-o", lugre_cad, "-q")
    # the memory kind beside it (docs/gms.md): the same fitting run, the same CAD URDF
    gms_cad = os.path.join(work, "gms-cad")
    fricli("identify", fit_cad, "--kind", "gms", "-o", gms_cad, "-q")
    law = ["--calibrate-friction", calibrate_friction] if calibrate_friction else []
    calibrated = fricli("diagnose", lugre_cad, fit_cad, "--fix", "--calibrate", cal, *law, "-o", fixed, "--json",
                        json_out=True)
    with open(cal[:-5] + ".calibration.json", encoding="utf-8") as fh:
        report = json.load(fh)
    # IDIM-LS: the rigid body with linear friction in one least-squares fit (fricli calibrate alone)
    fricli("calibrate", fit_cad, "--urdf", cad, "--friction", "linear", "-o", idim_urdf, "-q")
    with open(idim_urdf[:-5] + ".calibration.json", encoding="utf-8") as fh:
        idim_report = json.load(fh)
    # for comparison: the same path without the calibration (the CAD URDF's tau_g, diagnose --fix alone)
    diagnosed_cad = fricli("diagnose", lugre_cad, fit_cad, "--fix", "-o", fixed_cad, "--json", json_out=True)["joints"]
    # runs of other days, imported with each URDF; the fitting run with the calibrated one (LuGre alone)
    val_cad = [import_run(data, work, n, cad, "cad", keep=keep) for n in val_names]
    val_cal = [import_run(data, work, n, cal, "cal") for n in val_names]
    val_idim = [import_run(data, work, n, idim_urdf, "idim") for n in val_names]
    fit_cal = import_run(data, work, FIT_RUN, cal, "cal")
    lugre_cal = os.path.join(work, "lugre-cal")
    fricli("identify", fit_cal, "-o", lugre_cal, "-q")
    # the payload run: imported with the calibrated URDF and the declared payload (what the controller
    # knows); the reference payload torque from the CAD URDF with and without the payload
    load_cad = import_run(data, work, LOAD_RUN, cad, "cad", keep=keep)
    load_ref = import_run(data, work, LOAD_RUN, cad, "cad", payload=PAYLOAD, keep=keep)
    load_cal = import_run(data, work, LOAD_RUN, cal, "cal", payload=PAYLOAD)
    # the payload the joints carry: identified on the first part of the payload run (fricli payload),
    # declared at import, scored on the rest
    load_bare = import_run(data, work, LOAD_RUN, cal, "cal")
    seen = fricli("payload", load_bare, "--frame", PAYLOAD["frame"], "--until", f"{SEEN_SPLIT:.0%}", "--json", "-q",
                  json_out=True)
    load_seen = import_run(data, work, LOAD_RUN, cal, "cal", payload=seen, suffix="seen")
    load_idim = import_run(data, work, LOAD_RUN, idim_urdf, "idim", payload=PAYLOAD)
    load_idim_bare = import_run(data, work, LOAD_RUN, idim_urdf, "idim")

    aligned = twin_alignment(load_cad, fit_cad, joints)
    result = {"fit_run": FIT_RUN, "validation_runs": val_names, "joints": {}, "twin_alignment": aligned,
              "calibration": {k: report[k] for k in ("fit", "friction", "armature", "links", "suspicious",
                                                     "excitation", "prior", "prior_choice")},
              "robot_model": calibrated.get("robot_model")}
    for j in joints:
        fr = idim_report["friction"]["joints"][str(j)]
        idim = np.array([fr["Fv"], fr["Fc"], fr["offset"]])
        coef = linear_fit(fit_cad, j)
        published = np.asarray(PUBLISHED[j])

        def model(folder):
            path = os.path.join(folder, f"joint_{j}.npz")
            return lambda p, s: predicted(path, p, j)

        row = {
            "linear_coef": coef.tolist(), "idim_coef": idim.tolist(),
            "linear": torque_errors(lambda p, s: linear_columns(s) @ coef, val_cad, j),
            "published": torque_errors(lambda p, s: linear_columns(s) @ published, val_cad, j),
            "lugre": torque_errors(model(lugre_cad), val_cad, j),
            "gms": torque_errors(model(gms_cad), val_cad, j),
            "fixed_cad": torque_errors(model(fixed_cad), val_cad, j),
            "idim": torque_errors(lambda p, s: linear_columns(s) @ idim, val_idim, j),
            "lugre_cal": torque_errors(model(lugre_cal), val_cal, j),
            "fixed": torque_errors(model(fixed), val_cal, j),
            "diagnose": calibrated["joints"][str(j)], "diagnose_cad": diagnosed_cad[str(j)],
        }
        # external torque of the payload run, models fitted on its unloaded twin (the fitting run)
        sig, ref_sig, idim_sig = signals(load_cad, j), signals(load_ref, j), signals(load_idim, j)
        reference = -((ref_sig["tau_g"] + ref_sig["tau_dyn"]) - (sig["tau_g"] + sig["tau_dyn"]))
        left = estimated_external(os.path.join(fixed, f"joint_{j}.npz"), load_cal, j, work)
        ext_fixed = left + reference       # what is left beyond the declared payload, plus the payload's torque
        ext_idim = logs.external_torque(idim_sig, linear_columns(idim_sig) @ idim) + reference
        ext_linear = logs.external_torque(sig, linear_columns(sig) @ coef)
        twin = logs.external_torque(signals(fit_cal, j), predicted(os.path.join(fixed, f"joint_{j}.npz"), fit_cal, j))
        row["payload"] = {"reference_rms": rms(reference)}
        for key, est in (("fixed", ext_fixed), ("idim", ext_idim), ("linear", ext_linear)):
            err = est - reference
            row["payload"][key] = rms(err)
            row["payload"][key + "_gain"] = _gain(err, reference)
            row["payload"][key + "_above_floor"] = _above_floor(err, sig["t"])
        row["payload"]["fixed_unloaded"] = rms(twin)
        measured, covered = measured_external(sig, signals(fit_cad, j), aligned["shift"])
        row["payload"]["measured_ratio"] = rms((measured - reference)[covered]) / rms((ext_linear - reference)[covered])
        row["payload"]["measured_gain"] = _gain((measured - reference)[covered], reference[covered])
        bare, seen_sig, idim_bare = signals(load_bare, j), signals(load_seen, j), signals(load_idim_bare, j)
        ref_seen = (bare["tau_g"] + bare["tau_dyn"]) - (seen_sig["tau_g"] + seen_sig["tau_dyn"])
        t = sig["t"]
        held = t >= t[0] + SEEN_SPLIT * (t[-1] - t[0])      # the rows --until left out
        estimates = {"fixed": estimated_external(os.path.join(fixed, f"joint_{j}.npz"), load_seen, j, work) + ref_seen,
                     "idim": logs.external_torque(idim_bare, linear_columns(idim_bare) @ idim), "linear": ext_linear}
        row["payload_seen"] = {"reference_rms": rms(ref_seen[held]),
                               **{k: rms(e[held] - ref_seen[held]) for k, e in estimates.items()}}
        both = held & covered
        row["payload_seen"]["measured_ratio"] = (rms(measured[both] - ref_seen[both])
                                                 / rms(estimates["linear"][both] - ref_seen[both]))
        row["payload_series"] = {"t": sig["t"] - sig["t"][0], "reference": reference, "fixed": ext_fixed,
                                 "idim": ext_idim, "linear": ext_linear}
        result["joints"][j] = row
    result["payload_seen"] = {k: seen[k] for k in ("mass", "com", "stderr", "frame", "rows")}
    pairs = [p for p in PAIRS if set(p) <= set(val_names)]
    imported = dict(zip(val_names, val_cal))
    result["adapt"] = adapt_pairs(work, fixed, imported, joints, pairs) if adapt and pairs else None
    return result


def adapt_pairs(work: str, base: str, imported: dict[str, str], joints, pairs) -> dict:
    """Same-day adaptation (as benchmarks/ur10e_neural.py): for each day with two runs, ``adapt`` the
    fixed models on one run, scored on the other (both imported with the calibrated URDF), against the
    fixed models there: RMS over the rows in motion of the friction target minus the prediction."""
    cases = []
    for first, second in pairs:
        for on, scored in ((first, second), (second, first)):
            on_path, scored_path = imported[on], imported[scored]
            out = os.path.join(work, f"adapted-{on}")
            done = fricli("adapt", base, on_path, "--seed", "0", "-o", out, "--json", "-q", json_out=True)
            for j in joints:
                kept = done["joints"][str(j)].get("adapted", True)
                held = done["joints"][str(j)].get("held_out", {})
                errors = {}
                for key, folder in (("base", base), ("adapted", out)):
                    sig = signals(scored_path, j)
                    e = logs.friction_target(sig) - predicted(os.path.join(folder, f"joint_{j}.npz"), scored_path, j)
                    errors[key] = rms(e[metrics.in_motion(sig["qd"])])
                cases.append({"adapted_on": on, "scored_on": scored, "joint": j, "residual_kept": kept,
                              "base_error": errors["base"], "adapted_error": errors["adapted"],
                              "half_ratios": held.get("half_ratios", []), "speed_ratios": held.get("speed_ratios", []),
                              "significant": held.get("gain_mean", 0.0) > learning.SIGNIFICANCE * held.get("gain_se", np.inf),
                              "base_off_on": base_off(base, on_path, j), "base_off_scored": base_off(base, scored_path, j)})
    return {"cases": cases}


def base_off(base: str, path: str, joint: int) -> list[float]:
    """How far the base model's friction is off on a run: the coefficients of qd [Nm s/rad] and sign(qd) [Nm]
    in the least-squares fit of [qd, sign(qd), 1] to its error over the rows in motion."""
    sig = signals(path, joint)
    mv = metrics.in_motion(sig["qd"])
    e = logs.friction_target(sig) - predicted(os.path.join(base, f"joint_{joint}.npz"), path, joint)
    cols = np.column_stack([sig["qd"], np.sign(sig["qd"]), np.ones_like(e)])[mv]
    return [float(c) for c in np.linalg.lstsq(cols, e[mv], rcond=None)[0][:2]]


def twin_alignment(load: str, twin: str, joints) -> dict:
    """The time shift [s] that lays the payload run onto its unloaded twin (the same trajectory): the
    least RMS difference of q over ``joints``, searched over +-5 s (10 ms steps, then 0.5 ms)."""
    a = [signals(load, j) for j in joints]
    b = [signals(twin, j) for j in joints]
    ta, tb = a[0]["t"] - a[0]["t"][0], b[0]["t"] - b[0]["t"][0]

    def mismatch(shift: float) -> float:
        ok = (ta + shift >= tb[0]) & (ta + shift <= tb[-1])
        if ok.sum() < 0.8 * ta.size:
            return np.inf
        return rms(np.concatenate([np.interp(ta[ok] + shift, tb, y["q"]) - x["q"][ok] for x, y in zip(a, b)]))

    coarse = min(np.arange(-5.0, 5.0, 0.01), key=mismatch)
    shift = float(min(np.arange(coarse - 0.01, coarse + 0.01, 0.0005), key=mismatch))
    return {"shift": shift, "q_rms": mismatch(shift)}


def measured_external(a: dict, b: dict, shift: float) -> tuple[np.ndarray, np.ndarray]:
    """The payload's torque as one joint measured it, with no model: the unloaded twin's tau_m (``b``'s,
    interpolated onto the payload run ``a``'s times plus ``shift``) minus the payload run's, in the
    external-torque sign; and the payload run's rows the twin covers."""
    ta, tb = a["t"] - a["t"][0] + shift, b["t"] - b["t"][0]
    ok = (ta >= tb[0]) & (ta <= tb[-1])
    return np.interp(ta, tb, b["tau_m"]) - a["tau_m"], ok


def _above_floor(x: np.ndarray, t: np.ndarray) -> float:
    from scipy import signal

    sos = signal.butter(4, FLOOR_HZ, btype="high", fs=1.0 / np.median(np.diff(t)), output="sos")
    return rms(signal.sosfiltfilt(sos, x))


def _gain(error: np.ndarray, reference: np.ndarray) -> float:
    """Least-squares slope of the error on the reference: -0.2 = the estimate sees 80 % of it."""
    return float(np.dot(error, reference) / np.dot(reference, reference))


# --------------------------------------------------------------------------- document


def _fmt_effect(e: dict) -> str:
    params = ", ".join(f"{k} {v['value']:.4g} {v['unit']}".rstrip() for k, v in e["params"].items()
                       if v.get("value") is not None)
    return f"{e['name']} ({params})" if params else e["name"]


MODEL_COLUMNS = (("published", "published Fv, Fc, offset", "CAD"), ("lugre", "LuGre (identify)", "CAD"),
                 ("gms", "GMS (identify --kind gms)", "CAD"),
                 ("fixed_cad", "identify + diagnose --fix", "CAD"), ("idim", "IDIM-LS (fricli calibrate)", "calibrated"),
                 ("lugre_cal", "LuGre (identify)", "calibrated"),
                 ("fixed", "**fricli: diagnose --fix --calibrate**", "calibrated"))


def targets(r: dict) -> dict:
    """Per joint, in motion: the floor (the linear model's error above FLOOR_HZ, relative to it) and the
    target, halfway between the CAD path's ratio (identify + diagnose --fix) and the floor."""
    floor = r["linear"]["above_floor_moving"] / r["linear"]["moving"]
    cad_path = r["fixed_cad"]["moving"] / r["linear"]["moving"]
    return {"floor": floor, "target": 0.5 * (floor + cad_path)}


def tables(res: dict) -> dict[str, str]:
    head = " | ".join(f"{label} ({urdf} URDF)" for _, label, urdf in MODEL_COLUMNS)
    rows, ratios, met, goals = [], {k: [] for k, _, _ in MODEL_COLUMNS}, [], []
    for j, r in res["joints"].items():
        base = r["linear"]["moving"]
        cells = []
        for key, _, _ in MODEL_COLUMNS:
            ratio = r[key]["moving"] / base
            ratios[key].append(ratio)
            cells.append(f"**{ratio:.2f}**" if key == "fixed" else f"{ratio:.2f}")
        t = targets(r)
        goals.append(t["target"])
        ok = ratios["fixed"][-1] <= t["target"] and (j != 2 or ratios["fixed"][-1] <= ratios["idim"][-1])
        met.append(ok)
        rows.append(f"| {j} | {base:.3f} | " + " | ".join(cells) + f" | {t['floor']:.2f} | {t['target']:.2f} | "
                    f"{'yes' if ok else 'no'} | {r['fixed']['all'] / r['linear']['all']:.2f} |")
    means = {k: float(np.mean(v)) for k, v in ratios.items()}
    rows.append("| mean | | " + " | ".join(f"**{means[k]:.2f}**" if k == "fixed" else f"{means[k]:.2f}"
                                          for k, _, _ in MODEL_COLUMNS) + f" | | {TARGET_MEAN:.2f} | "
                f"{'yes' if means['fixed'] <= TARGET_MEAN else 'no'} | |")
    friction = "\n".join([
        f"| joint | linear model, in motion [Nm] | {head} | floor (above {FLOOR_HZ:g} Hz) | target | met | "
        "fricli, all rows |", "|---|---|" + "---|" * (len(MODEL_COLUMNS) + 4), *rows])

    diag_rows = []
    for j, r in res["joints"].items():
        before, after = r["diagnose_cad"], r["diagnose"]
        model_before = [e for e in before["effects"] if e.get("part") == "model"
                        and (e["name"] in before["added"] or e["name"] in before.get("suspected", []))]
        added = [e for e in after["effects"] if e["name"] in after["added"]]
        diag_rows.append(
            f"| {j} | {'; '.join(_fmt_effect(e) + (' (implausible, held back)' if e['name'] in before.get('suspected', []) else '') for e in model_before) or '–'} | "
            f"{'; '.join(_fmt_effect(e) for e in added if e.get('part') == 'model') or '–'} | "
            f"{'; '.join(_fmt_effect(e) for e in added if e.get('part') != 'model') or '–'} | "
            f"{before['mae_before']:.3f} → {after['mae_after']:.3f} |")
    diagnose = "\n".join([
        "| joint | robot-model errors with the CAD URDF | left after calibration | friction effects added | "
        "held-out MAE on the fitting run, CAD + LuGre → calibrated + fixed [Nm] |",
        "|---|---|---|---|---|", *diag_rows])

    cal = res["calibration"]
    link_rows = [f"| {name} | {v['mass_cad']:.3f} | {v['mass']:.3f} | {100 * (v['mass'] / v['mass_cad'] - 1):+.0f} % | "
                 f"{_vec(v['com_cad'])} | {_vec(v['com'])} |" for name, v in cal["links"].items()]
    arm_rows = [f"| {name} | {v['prior']:.4g} | {v['identified']:.4g} |" for name, v in cal["armature"].items()]
    fit_rows = [f"| {j} | {f['rms_before']:.3f} | {f['rms_after']:.3f} |" for j, f in cal["fit"].items()]
    parameters = "\n".join([
        "| body (link) | mass, CAD [kg] | calibrated | change | centre of mass, CAD [m] | calibrated |",
        "|---|---|---|---|---|---|", *link_rows, "",
        "| joint | armature, prior (mapping's rotor inertia) [kg m²] | calibrated |", "|---|---|---|", *arm_rows, "",
        f"| joint | fitting run: RMS of tau_m − model, CAD + {cal['friction']['kind']} friction [Nm] | "
        f"calibrated + {cal['friction']['kind']} friction |",
        "|---|---|---|", *fit_rows])

    ext_rows = []
    for j, r in res["joints"].items():
        p = r["payload"]
        ext_rows.append(f"| {j} | {p['reference_rms']:.2f} | {p['linear']:.3f} | {p['idim']:.3f} | {p['fixed']:.3f} | "
                        f"{p['idim'] / p['linear']:.2f} | **{p['fixed'] / p['linear']:.2f}** | "
                        f"{_share(p, 'linear_gain')} | {_share(p, 'idim_gain')} | {_share(p, 'fixed_gain')} | "
                        f"{p['fixed_above_floor']:.3f} | {p['fixed_unloaded']:.3f} | {p['measured_ratio']:.2f} |")
    external = "\n".join([
        "| joint | payload torque (RMS) [Nm] | linear error [Nm] | IDIM-LS error | fricli error | IDIM-LS / linear | "
        "fricli / linear | linear sees | IDIM-LS sees | fricli sees | fricli error above 2 Hz | "
        "fricli on the unloaded twin | measured difference / linear |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|", *ext_rows])
    out = {"friction": friction, "diagnose": diagnose, "parameters": parameters, "external": external,
           "means": means, "met": met, "targets": goals}
    if res.get("adapt"):
        out["adapt"] = adapt_table(res["adapt"], list(res["joints"]))
    return out


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"


def adapt_table(result: dict, joints) -> str:
    cases = result["cases"]
    lines = ["| adapted on | scored on | " + " | ".join(f"joint {j}" for j in joints) + " |",
             "|---|---|" + "---|" * len(joints)]
    for on, scored in dict.fromkeys((c["adapted_on"], c["scored_on"]) for c in cases):
        cells = [f"{c['base_error']:.3f} → {c['adapted_error']:.3f}{'' if c['residual_kept'] else ' (base kept)'}"
                 for c in cases if c["adapted_on"] == on and c["scored_on"] == scored]
        lines.append(f"| {on[3:]} | {scored[3:]} | " + " | ".join(cells) + " |")
    ratios = [c["adapted_error"] / c["base_error"] for c in cases]
    kept = sum(c["residual_kept"] for c in cases)
    worse = sum(c["adapted_error"] > c["base_error"] * (1 + 1e-9) for c in cases)
    lines += ["", f"adapted / base on the other run: {min(ratios):.3f} to {max(ratios):.3f} (mean {np.mean(ratios):.3f}); "
              f"residual kept in {kept} of {len(cases)} cases; worse than the base in {worse}"]
    off = ("The base's error in motion, fitted by qd and sign(qd), is {0[0]:+.3f} Nm s/rad and {0[1]:+.3f} Nm on the "
           "run adapted on, {1[0]:+.3f} Nm s/rad and {1[1]:+.3f} Nm on the run scored.")
    for c in cases:
        if c["adapted_error"] > c["base_error"] * (1 + 1e-9) and "base_off_on" in c:
            lines += ["", f"Worse: joint {c['joint']} adapted on {c['adapted_on'][3:]}, {c['base_error']:.3f} → "
                      f"{c['adapted_error']:.3f} Nm on {c['scored_on'][3:]}. " + off.format(c["base_off_on"], c["base_off_scored"])]
    by_speed = [c for c in cases if not c["residual_kept"] and c.get("speed_ratios") and c["significant"]
                and max(c["half_ratios"]) <= 1 - learning.MIN_GAIN]
    if by_speed:
        lines += ["", "Kept as the base by the rule in speed alone (the residual lowered the held-out RMS by "
                  f"{100 * learning.MIN_GAIN:g} % on each half in time, significantly, but not on both the slower and the faster "
                  "half of the rows): " + "; ".join(
                      f"joint {c['joint']} adapted on {c['adapted_on'][3:]} (held out: each half in time "
                      f"×{c['half_ratios'][0]:.3f}, ×{c['half_ratios'][1]:.3f}; slower, faster half ×{c['speed_ratios'][0]:.3f}, "
                      f"×{c['speed_ratios'][1]:.3f}; " + off.format(c["base_off_on"], c["base_off_scored"])[:-1].replace(
                          "The base's error in motion", "the base's error") + ")" for c in by_speed) + ".",
                  "NN_add sees the gravity torque and the direction of motion, not the speed: a residual that grows with speed "
                  "becomes one level per direction, right at the log's own speeds only."]
    return "\n".join(lines)


def _share(p: dict, key: str) -> str:
    """Share of the payload torque an estimate follows; none where the payload exerts none."""
    return f"{1 + p[key]:.0%}" if p["reference_rms"] > 0.05 else "– (no payload torque)"


def figures(res: dict, img: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    joints = list(res["joints"])
    fig, ax = plt.subplots(figsize=(7.5, 3.4))
    x = np.arange(len(joints))
    shown = (("fixed_cad", "CAD URDF: identify + diagnose --fix"), ("idim", "IDIM-LS (fricli calibrate alone)"),
             ("fixed", "fricli: diagnose --fix --calibrate"))
    for k, (key, label) in enumerate(shown):
        ratio = [res["joints"][j][key]["moving"] / res["joints"][j]["linear"]["moving"] for j in joints]
        ax.bar(x + (k - 1) * 0.27, ratio, 0.27, label=label)
    ax.plot(x, [targets(res["joints"][j])["floor"] for j in joints], "k_", ms=22, mew=2, label=f"floor (above {FLOOR_HZ:g} Hz)")
    ax.plot(x, [targets(res["joints"][j])["target"] for j in joints], "r_", ms=22, mew=1.5, label="target")
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_xticks(x, [f"joint {j}" for j in joints])
    ax.set_ylabel("RMS error / linear model's")
    ax.set_title("Error on runs of other days, in motion (baseline: CAD URDF + linear friction)")
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path = os.path.join(img, "ur10e-friction-ratio.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    shown_j = [j for j in (2, 3) if j in res["joints"]]
    if shown_j:
        fig, axes = plt.subplots(len(shown_j), 1, figsize=(7, 2.4 * len(shown_j)), sharex=True, squeeze=False)
        for ax, j in zip(axes[:, 0], shown_j):
            s = res["joints"][j]["payload_series"]
            ax.plot(s["t"], s["reference"], "k", lw=1.2, label="payload torque (URDF + 2.805 kg)")
            ax.plot(s["t"], s["fixed"], lw=0.6, label="fricli (calibrated URDF, payload declared)")
            ax.plot(s["t"], s["linear"], lw=0.6, alpha=0.7, label="linear model (CAD URDF)")
            ax.set_ylabel(f"joint {j} [Nm]")
        axes[0, 0].legend(fontsize=7, loc="upper right")
        axes[-1, 0].set_xlabel("t [s]")
        fig.suptitle("External torque of the payload run, models fitted on the unloaded twin", fontsize=9)
        fig.tight_layout()
        path = os.path.join(img, "ur10e-payload.png")
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    return written


def _to_list(x):
    return np.asarray(x).tolist()


def _from_json(saved: dict) -> tuple[dict, list[str]]:
    res = saved["result"]
    res["joints"] = {int(j): r for j, r in res["joints"].items()}
    for r in res["joints"].values():
        r["payload_series"] = {k: np.asarray(v) for k, v in r["payload_series"].items()}
    return res, saved["commands"]


def main(argv=None) -> None:
    global CUTOFF_HZ
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="folder of the UR10e recordings")
    ap.add_argument("--work", default=None, help="folder for the imported logs and models (default: temporary)")
    ap.add_argument("--out", default=ROOT, help="where docs/studies/case-study-ur10e.md and docs/studies/img/ go (default: this clone)")
    ap.add_argument("--joints", default="1,2,3,4,5,6", help="joints to study, e.g. 6")
    ap.add_argument("--runs", type=int, default=None, help="use only the first N validation runs")
    ap.add_argument("--keep-imports", action="store_true", help="reuse the logs already imported into --work")
    ap.add_argument("--no-adapt", action="store_true", help="leave out the same-day adaptation")
    ap.add_argument("--calibrate-friction", choices=("linear", "stribeck"), default=None,
                    help="diagnose --calibrate-friction for the closed loop (default: diagnose's own)")
    ap.add_argument("--cutoff", default=None,
                    help=f"import --cutoff for every run, e.g. auto (default {CUTOFF_HZ:g}; for comparison: the "
                         "document's text names the default)")
    ap.add_argument("--reuse", action="store_true",
                    help="rewrite the document from the figures of the last run in --work (no fricli commands)")
    args = ap.parse_args(argv)
    if args.cutoff is not None:
        CUTOFF_HZ = args.cutoff
    joints = [int(j) for j in args.joints.split(",")]
    docs, img = os.path.join(args.out, "docs", "studies"), os.path.join(args.out, "docs", "studies", "img")
    os.makedirs(img, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or tmp
        os.makedirs(work, exist_ok=True)
        saved = os.path.join(work, "study.json")
        if args.reuse:
            with open(saved) as fh:
                res, COMMANDS[:] = _from_json(json.load(fh))
        else:
            res = study(args.data, work, joints, args.runs, keep=args.keep_imports, adapt=not args.no_adapt,
                        calibrate_friction=args.calibrate_friction)
            atomic_write_bytes(saved, json.dumps({"result": res, "commands": COMMANDS}, default=_to_list).encode())
    pictures = figures(res, img)
    import case_study_text  # studies/ur10e/case_study_text.py: the words around the figures

    def paths(text: str) -> str:
        return text.replace(os.path.abspath(work), "WORK").replace(os.path.abspath(args.data), "DATA") \
            .replace(ROOT + os.sep, "")

    shown = [paths(c) for c in COMMANDS]
    if res.get("robot_model"):
        res["robot_model"]["summary"] = paths(res["robot_model"]["summary"])
    text = case_study_text.render(res, tables(res), shown, full=(len(res["joints"]) == 6 and res["validation_runs"] == validation_runs(args.data)))
    atomic_write_bytes(os.path.join(docs, "case-study-ur10e.md"), text.encode())
    digest = ("added", "suspected", "model_errors", "mae_before", "mae_after")
    summary = {j: {k: ({d: v.get(d) for d in digest} if k.startswith("diagnose")
                       else {e: x for e, x in v.items() if e != "run_levels" or k == "fixed"} if isinstance(v, dict)
                       else v) for k, v in r.items()
                   if k != "payload_series"} for j, r in res["joints"].items()}
    calibration = {k: v for k, v in res["calibration"].items() if k != "excitation"}
    calibration["excitation"] = {k: res["calibration"]["excitation"][k] for k in ("parameters", "base_parameters")}
    calibration["excitation"]["undetermined"] = len(res["calibration"]["excitation"]["undetermined"])
    robot = {k: v for k, v in (res.get("robot_model") or {}).items() if k in ("joints", "summary", "mae")}
    atomic_write_bytes(os.path.join(docs, "ur10e-results.json"), json.dumps(
        {"validation_runs": res["validation_runs"], "joints": summary, "calibration": calibration,
         "robot_model": robot, "adapt": res.get("adapt")}, indent=1).encode())
    print(f"wrote {os.path.join(docs, 'case-study-ur10e.md')} and {', '.join(pictures)}", file=sys.stderr)


if __name__ == "__main__":
    main()
