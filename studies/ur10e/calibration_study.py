"""Measure `fricli calibrate` on the UR10e recordings: the arm's rigid-body model and linear friction
identified together on one run, validated on the runs of other days, against the URDF's CAD model
with linear friction fitted on the same run; and the external torque of the 2.805 kg payload run.

    python studies/ur10e/calibration_study.py --work /tmp/cal-study        # about a minute on 2 cores
    python studies/ur10e/calibration_study.py --work /tmp/cal-study --keep # reuse imported logs

Prints the tables of docs/calibration.md and writes WORK/calibration-study.json. Every log, URDF
and friction set comes from the fricli command line (the commands are printed); the script only
computes the error figures, the baseline's least-squares friction and, for comparison, the
calibration's unconstrained linear estimate (library call, ``enforce=False``).
Data: ../shared/data/ur10e (see ../shared/data/README.md), or --data.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

from fricli.core import logs, metrics  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from run_case_study import CUTOFF_HZ, DEFAULT_DATA, JOINTS, MAPPING  # noqa: E402  (the case study's settings)

FIT_RUN = "ur-20_02_12-50sec_12harm"
TWIN_RUN = "ur-20_02_19_14harm50sec"         # the payload run's unloaded twin (same trajectory, same day)
LOAD_RUN = "ur-20_02_19_14harm50secLoad"
PAYLOAD = {"mass": 2.805, "com": (0.0, 0.0, 0.0), "frame": "tool0"}
FLOOR_HZ = 2.0
# per joint, in motion: the ratios of fricli's per-joint models (docs/studies/case-study-ur10e.md) and the floor
PATCHED = (0.68, 0.62, 0.66, 0.82, 0.86, 0.93)
FLOOR = (0.50, 0.37, 0.61, 0.56, 0.80, 0.89)

COMMANDS: list[str] = []


def fricli(*args: str, skip: bool = False) -> None:
    shown = " ".join(args)
    COMMANDS.append(shown)
    if skip:
        return
    print(f"$ fricli {shown}", file=sys.stderr, flush=True)
    done = subprocess.run([sys.executable, "-m", "fricli", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    if done.returncode != 0:
        raise SystemExit(f"fricli {shown} failed ({done.returncode}): {done.stderr.strip()}")


def import_run(data, work, name, urdf, tag, keep, payload=False) -> str:
    out = os.path.join(work, f"{name}-{tag}{'-payload' if payload else ''}.parquet")
    args = ["import", os.path.join(data, "identification", name + ".csv"), "--mapping", MAPPING, "--urdf", urdf,
            "--cutoff", str(CUTOFF_HZ), "-o", out, "-q"]
    if payload:
        args += ["--payload-mass", str(PAYLOAD["mass"]), "--payload-com", *map(str, PAYLOAD["com"]),
                 "--payload-frame", PAYLOAD["frame"]]
    fricli(*args, skip=keep and os.path.exists(out))
    return out


def calibrate(log, cad, work, tag, keep, *extra) -> tuple[str, dict]:
    out = os.path.join(work, f"{tag}.urdf")
    fricli("calibrate", log, "--urdf", cad, "-o", out, "-q", *extra, skip=keep and os.path.exists(out))
    with open(out[:-5] + ".calibration.json", encoding="utf-8") as fh:
        return out, json.load(fh)


def sig(path, joint):
    return logs.load_log(path, joint=str(joint)).signals


def lin(s, coef):
    return np.column_stack([s["qd"], np.sign(s["qd"]), np.ones_like(s["qd"])]) @ np.asarray(coef)


def friction(s, fr):
    """The calibration's friction of one joint (report entry ``fr``) at the log's velocities."""
    qd = s["qd"]
    out = fr["Fv"] * qd + fr["Fc"] * np.sign(qd) + fr["offset"]
    if "Fs" in fr:
        out += (fr["Fs"] - fr["Fc"]) * np.sign(qd) * np.exp(-np.abs(qd / fr["vs"]) ** fr["delta"])
    return out


def rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def residuals(paths, joint, predict) -> dict:
    """tau_m minus the model's torque on every run, in motion and over all rows; and the part above
    FLOOR_HZ (zero-phase high-pass), per run then pooled."""
    from scipy import signal

    out = {"all": [], "moving": [], "hf_moving": [], "hf_all": []}
    for path in paths:
        s = sig(path, joint)
        e = s["tau_m"] - predict(path, s)
        sos = signal.butter(4, FLOOR_HZ, btype="high", fs=1.0 / np.median(np.diff(s["t"])), output="sos")
        hf = signal.sosfiltfilt(sos, e)
        mv = metrics.in_motion(s["qd"])
        out["all"].append(e)
        out["moving"].append(e[mv])
        out["hf_all"].append(hf)
        out["hf_moving"].append(hf[mv])
    return {k: rms(np.concatenate(v)) for k, v in out.items()}


def unconstrained(fit_log, cad, prior="auto"):
    """The calibration's linear (maximum a posteriori) estimate without the consistency step, and the
    robot model to predict with it."""
    from fricli.core.logs import read_table
    from fricli.robot import calibration as cb
    from fricli.robot.dynamics import load_model
    from fricli.robot.mapping import Mapping

    robot = load_model(cad, Mapping(time=None, joints=[]))
    motion = cb.read_motion(read_table(fit_log)[0], fit_log, robot, match=None)
    return robot, cb.calibrate(robot, motion, enforce=False, prior=prior if prior == "auto" else float(prior))


def study(data, work, keep, fit_run=FIT_RUN, prior="auto") -> dict:
    cad = os.path.join(data, "ur10e.urdf")
    names = sorted(f[:-4] for f in os.listdir(os.path.join(data, "identification")) if f.endswith(".csv"))
    val_names = [n for n in names if not n.startswith(fit_run[:11]) and n != LOAD_RUN]
    fit_cad = import_run(data, work, fit_run, cad, "cad", keep)
    cal_urdf, report = calibrate(fit_cad, cad, work, "cal", keep, "--prior", prior)
    val_cad = [import_run(data, work, n, cad, "cad", keep) for n in val_names]
    val_cal = [import_run(data, work, n, cal_urdf, "cal", keep) for n in val_names]
    str_urdf, str_report = calibrate(fit_cad, cad, work, "cal-stribeck", keep, "--friction", "stribeck",
                                     "--prior", prior)
    val_str = [import_run(data, work, n, str_urdf, "cal-stribeck", keep) for n in val_names]
    robot, free = unconstrained(fit_cad, cad, prior)
    nj = len(JOINTS)

    def free_pred(path, s, j, _cache={}):
        if path not in _cache:
            from fricli.robot import calibration as cb

            m = cb.read_motion(logs.read_table(path)[0], path, robot, match=None)
            _cache[path] = (cb.regressor(robot, m.q, m.qd, m.qdd) @ free.x).reshape(len(m.t), nj)
        return _cache[path][:, j - 1]

    result = {"fit_run": fit_run, "validation_runs": val_names, "calibration": report,
              "calibration_stribeck": str_report, "joints": {}}
    for j in JOINTS:
        fs = sig(fit_cad, j)
        coef = np.linalg.lstsq(np.column_stack([fs["qd"], np.sign(fs["qd"]), np.ones_like(fs["qd"])]),
                               fs["tau_m"] - fs["tau_g"] - fs["tau_dyn"], rcond=None)[0]
        fr = report["friction"]["joints"][str(j)]
        base = residuals(val_cad, j, lambda p, s: s["tau_g"] + s["tau_dyn"] + lin(s, coef))
        cal = residuals(val_cal, j, lambda p, s: s["tau_g"] + s["tau_dyn"] + lin(s, [fr["Fv"], fr["Fc"], fr["offset"]]))
        unc = residuals(val_cad, j, lambda p, s: free_pred(p, s, j))
        frs = str_report["friction"]["joints"][str(j)]
        stri = residuals(val_str, j, lambda p, s: s["tau_g"] + s["tau_dyn"] + friction(s, frs))
        result["joints"][j] = {"baseline": base, "calibrated": cal, "unconstrained": unc, "stribeck": stri,
                               "baseline_friction": coef.tolist()}

    # payload run: models fitted on the unloaded twin
    twin_cad = import_run(data, work, TWIN_RUN, cad, "cad", keep)
    twin_urdf, twin_report = calibrate(twin_cad, cad, work, "cal-twin", keep)
    load_cad = import_run(data, work, LOAD_RUN, cad, "cad", keep)
    load_ref = import_run(data, work, LOAD_RUN, cad, "cad", keep, payload=True)
    load_cal = import_run(data, work, LOAD_RUN, twin_urdf, "cal-twin", keep)
    twin_str_urdf, twin_str = calibrate(twin_cad, cad, work, "cal-twin-stribeck", keep, "--friction", "stribeck")
    load_str = import_run(data, work, LOAD_RUN, twin_str_urdf, "cal-twin-stribeck", keep)
    result["payload"] = {}
    for j in JOINTS:
        ts = sig(twin_cad, j)
        coef = np.linalg.lstsq(np.column_stack([ts["qd"], np.sign(ts["qd"]), np.ones_like(ts["qd"])]),
                               ts["tau_m"] - ts["tau_g"] - ts["tau_dyn"], rcond=None)[0]
        s, r, c, cs = sig(load_cad, j), sig(load_ref, j), sig(load_cal, j), sig(load_str, j)
        reference = -((r["tau_g"] + r["tau_dyn"]) - (s["tau_g"] + s["tau_dyn"]))
        fr = twin_report["friction"]["joints"][str(j)]
        ext_lin = logs.external_torque(s, lin(s, coef))
        ext_cal = logs.external_torque(c, lin(c, [fr["Fv"], fr["Fc"], fr["offset"]]))
        ext_str = logs.external_torque(cs, friction(cs, twin_str["friction"]["joints"][str(j)]))
        mv = metrics.in_motion(s["qd"])
        result["payload"][j] = {
            "reference_rms": rms(reference), "linear": rms(ext_lin - reference), "calibrated": rms(ext_cal - reference),
            "stribeck": rms(ext_str - reference), "stribeck_moving": rms((ext_str - reference)[mv]),
            "stribeck_gain": float(np.dot(ext_str - reference, reference) / np.dot(reference, reference)),
            "linear_moving": rms((ext_lin - reference)[mv]), "calibrated_moving": rms((ext_cal - reference)[mv]),
            "linear_gain": float(np.dot(ext_lin - reference, reference) / np.dot(reference, reference)),
            "calibrated_gain": float(np.dot(ext_cal - reference, reference) / np.dot(reference, reference)),
        }
    result["twin_calibration"] = twin_report
    result["commands"] = COMMANDS
    return result


def tables(res) -> str:
    lines = ["| joint | baseline in motion [Nm] | calibrated | ratio | unconstrained ratio | with Stribeck | floor (above 2 Hz) | "
             "target (halfway) | ratio, all rows | with Stribeck, all rows |", "|---|---|---|---|---|---|---|---|---|---|"]
    ratios, str_ratios = [], []
    for j, r in res["joints"].items():
        b, c, u = r["baseline"], r["calibrated"], r["unconstrained"]
        ratio = c["moving"] / b["moving"]
        ratios.append(ratio)
        floor = b["hf_moving"] / b["moving"]
        target = 0.5 * (PATCHED[int(j) - 1] + FLOOR[int(j) - 1])
        st = r["stribeck"]
        str_ratios.append(st["moving"] / b["moving"])
        lines.append(f"| {j} | {b['moving']:.3f} | {c['moving']:.3f} | **{ratio:.2f}** | {u['moving'] / b['moving']:.2f} | "
                     f"{str_ratios[-1]:.2f} | {floor:.2f} | {target:.3f} | {c['all'] / b['all']:.2f} | "
                     f"{st['all'] / b['all']:.2f} |")
    lines.append(f"| mean | | | **{np.mean(ratios):.2f}** | | {np.mean(str_ratios):.2f} | | 0.66 | | |")
    lines += ["", "| joint | payload torque RMS [Nm] | linear error | calibrated error | ratio | ratio in motion | "
              "linear sees | calibrated sees | with Stribeck: ratio | sees |", "|---|---|---|---|---|---|---|---|---|---|"]
    for j, p in res["payload"].items():
        has = p["reference_rms"] > 0.01
        seen = (f"{100 * (1 + p['linear_gain']):.0f} % | {100 * (1 + p['calibrated_gain']):.0f} %"
                if has else "– (no payload torque) | –")
        stribeck_seen = f"{100 * (1 + p['stribeck_gain']):.0f} %" if has else "–"
        lines.append(f"| {j} | {p['reference_rms']:.2f} | {p['linear']:.3f} | {p['calibrated']:.3f} | "
                     f"**{p['calibrated'] / p['linear']:.2f}** | {p['calibrated_moving'] / p['linear_moving']:.2f} | {seen} | "
                     f"{p['stribeck'] / p['linear']:.2f} | {stribeck_seen} |")
    for kind in ("calibrated", "stribeck"):
        two = [res["payload"][j][kind] / res["payload"][j]["linear"] for j in (2, 3)]
        lines.append(f"\n{kind}: joints 2 and 3, mean ratio {np.mean(two):.2f}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--work", required=True, help="working folder (logs, URDFs, reports)")
    ap.add_argument("--keep", action="store_true", help="reuse outputs already in --work")
    ap.add_argument("--fit-run", default=FIT_RUN, help=f"the calibration run (default {FIT_RUN}); validation: "
                    "the identification runs of other days")
    ap.add_argument("--prior", default="auto", help="fricli calibrate's --prior (default auto)")
    args = ap.parse_args()
    if not os.path.isdir(os.path.join(args.data, "identification")):
        raise SystemExit(f"{args.data}: no UR10e recordings (see ../shared/data/README.md)")
    os.makedirs(args.work, exist_ok=True)
    res = study(args.data, args.work, args.keep, args.fit_run, args.prior)
    with open(os.path.join(args.work, "calibration-study.json"), "w", encoding="utf-8") as fh:
        json.dump(res, fh, indent=2, default=float)
    print(tables(res))


if __name__ == "__main__":
    main()
