"""Rerun the UR10e case study: CSV recordings + URDF -> fricli models for the six joints,
validated on runs of other days; writes docs/case-study-ur10e.md and docs/img/ur10e-*.png.

    python docs/ur10e/run_case_study.py                      # the whole study (a few minutes)
    python docs/ur10e/run_case_study.py --joints 6 --runs 1 --out /tmp/x   # a small part

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

from fricli.core import logs, metrics  # noqa: E402
from fricli.core.atomic import atomic_write_bytes  # noqa: E402

DEFAULT_DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "ur10e")
MAPPING = os.path.join(ROOT, "docs", "ur10e-mapping.toml")
JOINTS = (1, 2, 3, 4, 5, 6)
CUTOFF_HZ = 10.0  # qdd for the robot model: zero-phase low-pass, far above the excitation (< 1 Hz)
FIT_RUN = "ur-20_02_19_14harm50sec"          # the fitting run (19 Feb 2020)
LOAD_RUN = "ur-20_02_19_14harm50secLoad"     # the same trajectory with the payload, same day
PAYLOAD = {"mass": 2.805, "com": (0.0, 0.0, 0.0), "frame": "tool0"}  # kg, m in the flange frame
PUBLISHED = {1: (21.26, 12.55, 0.196), 2: (20.22, 13.27, -0.754), 3: (10.38, 4.99, 0.198),
             4: (3.58, 2.00, 0.055), 5: (2.49, 2.69, -0.010), 6: (3.03, 2.30, 0.043)}  # Fv, Fc, offset
FLOOR_HZ = 2.0  # the error above this frequency is not friction a model of the state can follow
TARGET_MEAN, TARGET_EACH, TARGET_EXT = 0.70, 0.85, 0.80

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


def import_run(data: str, work: str, name: str, payload: bool = False, keep: bool = False) -> str:
    out = os.path.join(work, name + ("-payload" if payload else "") + ".parquet")
    args = ["import", os.path.join(data, "identification", name + ".csv"), "--mapping", MAPPING,
            "--urdf", os.path.join(data, "ur10e.urdf"), "--cutoff", str(CUTOFF_HZ), "-o", out, "-q"]
    if payload:
        args += ["--payload-mass", str(PAYLOAD["mass"]), "--payload-com", *map(str, PAYLOAD["com"]),
                 "--payload-frame", PAYLOAD["frame"]]
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


def friction_errors(pred_of, val_logs: list[str], joint: int) -> dict[str, float]:
    """RMS of (friction target - prediction) over all validation rows, over the rows in motion
    and over those at rest; and the RMS of the error's part above FLOOR_HZ (zero-phase high-pass),
    which no model of q, qd, qdd and tau_g follows: the excitation lies below 1 Hz."""
    from scipy import signal

    every, moving, fast, fast_moving = [], [], [], []
    for path in val_logs:
        sig = signals(path, joint)
        e = logs.friction_target(sig) - pred_of(path, sig)
        mv = metrics.in_motion(sig["qd"])
        sos = signal.butter(4, FLOOR_HZ, btype="high", fs=1.0 / np.median(np.diff(sig["t"])), output="sos")
        hf = signal.sosfiltfilt(sos, e)
        every.append(e)
        moving.append(e[mv])
        fast.append(hf)
        fast_moving.append(hf[mv])
    every, moving = np.concatenate(every), np.concatenate(moving)
    return {"all": rms(every), "moving": rms(moving), "rest_share": 1.0 - moving.size / every.size,
            "above_floor": rms(np.concatenate(fast)), "above_floor_moving": rms(np.concatenate(fast_moving))}


def predicted(model: str, path: str, joint: int) -> np.ndarray:
    """tau_f_pred of ``model`` on one joint of a log: what ``fricli predict`` writes (same code,
    called in-process: the validation takes 6 x 11 predictions)."""
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


def study(data: str, work: str, joints, runs: int | None, keep: bool = False) -> dict:
    val_names = validation_runs(data)[:runs] if runs else validation_runs(data)
    fit_log = import_run(data, work, FIT_RUN, keep=keep)
    val_logs = [import_run(data, work, n, keep=keep) for n in val_names]
    load_log = import_run(data, work, LOAD_RUN, keep=keep)
    load_ref_log = import_run(data, work, LOAD_RUN, payload=True, keep=keep)

    result = {"fit_run": FIT_RUN, "validation_runs": val_names, "joints": {}}
    # the whole arm at once: one model per joint in a folder (docs/joints.md)
    lugre_dir, fixed_dir = os.path.join(work, "lugre"), os.path.join(work, "fixed")
    fricli("identify", fit_log, "-o", lugre_dir, "-q")
    diagnosed = fricli("diagnose", lugre_dir, fit_log, "--fix", "-o", fixed_dir, "--json", json_out=True)["joints"]
    for j in joints:
        lugre = os.path.join(lugre_dir, f"joint_{j}.npz")
        fixed = os.path.join(fixed_dir, f"joint_{j}.npz")
        diag = diagnosed[str(j)]

        fit_sig = signals(fit_log, j)
        coef = np.linalg.lstsq(linear_columns(fit_sig), logs.friction_target(fit_sig), rcond=None)[0]
        published = np.asarray(PUBLISHED[j])
        row = {
            "linear_coef": coef.tolist(),
            "linear": friction_errors(lambda p, s: linear_columns(s) @ coef, val_logs, j),
            "published": friction_errors(lambda p, s: linear_columns(s) @ published, val_logs, j),
            "lugre": friction_errors(lambda p, s: predicted(lugre, p, j), val_logs, j),
            "fixed": friction_errors(lambda p, s: predicted(fixed, p, j), val_logs, j),
            "diagnose": diag,
        }
        # external torque of the payload run, models fitted on its unloaded twin
        sig = signals(load_log, j)
        ref_sig = signals(load_ref_log, j)
        reference = -((ref_sig["tau_g"] + ref_sig["tau_dyn"]) - (sig["tau_g"] + sig["tau_dyn"]))
        ext_fixed = estimated_external(fixed, load_log, j, work)
        ext_linear = logs.external_torque(sig, linear_columns(sig) @ coef)
        row["payload"] = {"reference_rms": rms(reference), "fixed": rms(ext_fixed - reference),
                          "linear": rms(ext_linear - reference),
                          "fixed_gain": _gain(ext_fixed - reference, reference),
                          "linear_gain": _gain(ext_linear - reference, reference)}
        row["payload_series"] = {"t": sig["t"] - sig["t"][0], "reference": reference, "fixed": ext_fixed,
                                 "linear": ext_linear}
        result["joints"][j] = row
    return result


def _gain(error: np.ndarray, reference: np.ndarray) -> float:
    """Least-squares slope of the error on the reference: -0.2 = the estimate sees 80 % of it."""
    return float(np.dot(error, reference) / np.dot(reference, reference))


# --------------------------------------------------------------------------- document


def _fmt_effect(e: dict) -> str:
    params = ", ".join(f"{k} {v['value']:.4g} {v['unit']}".rstrip() for k, v in e["params"].items()
                       if v.get("value") is not None)
    return f"{e['name']} ({params})" if params else e["name"]


def tables(res: dict) -> dict[str, str]:
    rows, ratios = [], {"all": [], "moving": []}
    for j, r in res["joints"].items():
        ra, rm = r["fixed"]["all"] / r["linear"]["all"], r["fixed"]["moving"] / r["linear"]["moving"]
        ratios["all"].append(ra)
        ratios["moving"].append(rm)
        rows.append(f"| {j} | {r['fixed']['all']:.3f} | {r['lugre']['all']:.3f} | {r['linear']['all']:.3f} | "
                    f"{r['published']['all']:.3f} | **{ra:.2f}** | {r['fixed']['moving']:.3f} | "
                    f"{r['linear']['moving']:.3f} | {r['published']['moving']:.3f} | **{rm:.2f}** |")
    mean_all, mean_mov = float(np.mean(ratios["all"])), float(np.mean(ratios["moving"]))
    rows.append(f"| mean | | | | | **{mean_all:.2f}** | | | | **{mean_mov:.2f}** |")
    friction = "\n".join([
        "| joint | fricli (identify + diagnose --fix) | LuGre alone | linear model | published | ratio | "
        "fricli, in motion | linear, in motion | published, in motion | ratio, in motion |",
        "|---|---|---|---|---|---|---|---|---|---|", *rows])

    diag_rows = []
    for j, r in res["joints"].items():
        d = r["diagnose"]
        added = [e for e in d["effects"] if e["name"] in d["added"]]
        model_err = [_fmt_effect(e) for e in added if e.get("part") == "model"]
        fric = [_fmt_effect(e) for e in added if e.get("part") != "model"]
        unexplained = d.get("unexplained_share")
        gravity = next((e for e in d["effects"] if e["name"] == "gravity"), None)
        if gravity is None or gravity.get("params", {}).get("error", {}).get("value") is None:
            grav = "not tested"
        else:
            grav = (f"{gravity['params']['error']['value']:+.1f} % "
                    f"({'added' if 'gravity' in d['added'] else 'not added'}, gain {gravity['gain']:.0%})")
        diag_rows.append(f"| {j} | {grav} | {'; '.join(model_err) or '–'} | {'; '.join(fric) or '–'} | "
                         f"{d['mae_before']:.3f} → {d['mae_after']:.3f} | "
                         f"{'' if unexplained is None else f'{unexplained:.0%}'} | "
                         f"{r['lugre']['all']:.3f} → {r['fixed']['all']:.3f} |")
    diagnose = "\n".join([
        "| joint | gravity-model error (logged vs true) | robot-model errors added | friction effects added | held-out MAE on the fitting run [Nm] | "
        "unexplained share left | RMS on other days, before → after [Nm] |",
        "|---|---|---|---|---|---|---|", *diag_rows])

    ext_rows = []
    for j, r in res["joints"].items():
        p = r["payload"]
        ext_rows.append(f"| {j} | {p['reference_rms']:.2f} | {p['fixed']:.3f} | {p['linear']:.3f} | "
                        f"**{p['fixed'] / p['linear']:.2f}** | {_share(p, 'fixed_gain')} | {_share(p, 'linear_gain')} |")
    external = "\n".join([
        "| joint | payload torque (RMS) [Nm] | fricli error [Nm] | linear error [Nm] | ratio | "
        "share of the payload torque fricli sees | linear sees |",
        "|---|---|---|---|---|---|---|", *ext_rows])
    return {"friction": friction, "diagnose": diagnose, "external": external,
            "mean_all": mean_all, "mean_moving": mean_mov, "ratios": ratios}


def _share(p: dict, key: str) -> str:
    """Share of the payload torque an estimate follows; none where the payload exerts none."""
    return f"{1 + p[key]:.0%}" if p["reference_rms"] > 0.05 else "– (no payload torque)"


def figures(res: dict, img: str) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written = []
    joints = list(res["joints"])
    fig, ax = plt.subplots(figsize=(7, 3.2))
    x = np.arange(len(joints))
    for k, (key, label) in enumerate((("fixed", "fricli: identify + diagnose --fix"), ("lugre", "fricli: LuGre alone"),
                                       ("published", "published parameters"))):
        ratio = [res["joints"][j][key]["all"] / res["joints"][j]["linear"]["all"] for j in joints]
        ax.bar(x + (k - 1) * 0.27, ratio, 0.27, label=label)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhline(TARGET_EACH, color="r", lw=0.8, ls="--", label=f"target per joint ({TARGET_EACH})")
    ax.set_xticks(x, [f"joint {j}" for j in joints])
    ax.set_ylabel("RMS error / linear model's")
    ax.set_title("Friction error on runs of other days (all rows)")
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path = os.path.join(img, "ur10e-friction-ratio.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    written.append(path)

    shown = [j for j in (2, 3) if j in res["joints"]]
    if shown:
        fig, axes = plt.subplots(len(shown), 1, figsize=(7, 2.4 * len(shown)), sharex=True, squeeze=False)
        for ax, j in zip(axes[:, 0], shown):
            s = res["joints"][j]["payload_series"]
            ax.plot(s["t"], s["reference"], "k", lw=1.2, label="payload torque (URDF + 2.805 kg)")
            ax.plot(s["t"], s["fixed"], lw=0.6, label="fricli estimate")
            ax.plot(s["t"], s["linear"], lw=0.6, alpha=0.7, label="linear-model estimate")
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
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA, help="folder of the UR10e recordings")
    ap.add_argument("--work", default=None, help="folder for the imported logs and models (default: temporary)")
    ap.add_argument("--out", default=ROOT, help="where docs/case-study-ur10e.md and docs/img/ go (default: this clone)")
    ap.add_argument("--joints", default="1,2,3,4,5,6", help="joints to study, e.g. 6")
    ap.add_argument("--runs", type=int, default=None, help="use only the first N validation runs")
    ap.add_argument("--keep-imports", action="store_true", help="reuse the logs already imported into --work")
    ap.add_argument("--reuse", action="store_true",
                    help="rewrite the document from the figures of the last run in --work (no fricli commands)")
    args = ap.parse_args(argv)
    joints = [int(j) for j in args.joints.split(",")]
    docs, img = os.path.join(args.out, "docs"), os.path.join(args.out, "docs", "img")
    os.makedirs(img, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or tmp
        os.makedirs(work, exist_ok=True)
        saved = os.path.join(work, "study.json")
        if args.reuse:
            with open(saved) as fh:
                res, COMMANDS[:] = _from_json(json.load(fh))
        else:
            res = study(args.data, work, joints, args.runs, keep=args.keep_imports)
            atomic_write_bytes(saved, json.dumps({"result": res, "commands": COMMANDS}, default=_to_list).encode())
    pictures = figures(res, img)
    import case_study_text  # docs/ur10e/case_study_text.py: the words around the figures

    shown = [c.replace(os.path.abspath(work), "WORK").replace(os.path.abspath(args.data), "DATA")
             .replace(ROOT + os.sep, "") for c in COMMANDS]
    text = case_study_text.render(res, tables(res), shown, full=(len(res["joints"]) == 6 and res["validation_runs"] == validation_runs(args.data)))
    atomic_write_bytes(os.path.join(docs, "case-study-ur10e.md"), text.encode())
    summary = {j: {k: r[k] for k in ("linear_coef", "linear", "published", "lugre", "fixed", "payload", "diagnose")}
               for j, r in res["joints"].items()}
    atomic_write_bytes(os.path.join(docs, "ur10e-results.json"),
                       json.dumps({"validation_runs": res["validation_runs"], "joints": summary}, indent=1).encode())
    print(f"wrote {os.path.join(docs, 'case-study-ur10e.md')} and {', '.join(pictures)}", file=sys.stderr)


if __name__ == "__main__":
    main()
