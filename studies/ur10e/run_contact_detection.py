"""Contact detection and online friction adaptation on the UR10e recordings: writes
docs/studies/contact-detection.md, docs/studies/img/contact-*.png and docs/studies/contact-detection-results.json.

    PYTHONPATH=. python studies/ur10e/run_contact_detection.py --work W

The models are the UR10e case study's (docs/studies/case-study-ur10e.md: the fitting run, imported with the
CAD URDF, identify, diagnose --fix --calibrate): the script runs studies/ur10e/run_case_study.py into
W first unless W holds its results (study.json). Every replay is a fricli command, run as a user
would (listed at the end of the document); the script itself computes the figures from their
outputs: errors, false alarms, the pushes of the collision runs, and the contacts it adds to
collision-free runs (known time, joint and size) for the detection delay and the smallest
detectable torque. Data: ../shared/data/ur10e, or --data.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests"))

from fricli.applying import observer  # noqa: E402
from fricli.core import metrics  # noqa: E402
from fricli.core.atomic import atomic_write_bytes  # noqa: E402
from fricli.robot import replay  # noqa: E402

DEFAULT_DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "ur10e")
MAPPING = os.path.join(ROOT, "docs", "ur10e-mapping.toml")
FIT_RUN = "ur-20_02_19_14harm50sec"
LOAD_RUN = "ur-20_02_19_14harm50secLoad"
JOINTS = (1, 2, 3, 4, 5, 6)
SEED = 20260101           # the times of the added contacts
ADDED_PER_RUN = 6         # added contacts per joint and run
ADDED_LENGTH = 0.5        # s
HOLD = 10.0               # s: the contact held against the adaptation
DELAY_LIMIT = 0.020       # s
PUSH_LOWPASS_HZ = 2.0
COMMANDS: list[str] = []


def fricli(*args: str, json_out: bool = False):
    shown = " ".join(str(a) for a in args)
    COMMANDS.append(shown)
    print(f"$ fricli {shown}", file=sys.stderr, flush=True)
    done = subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    if done.returncode != 0:
        raise SystemExit(f"fricli {shown} failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout) if json_out else None


def case_study(work: str, data: str) -> dict:
    saved = os.path.join(work, "study.json")
    if not os.path.exists(saved):
        out = tempfile.mkdtemp()
        print("running studies/ur10e/run_case_study.py (the models) ...", file=sys.stderr, flush=True)
        subprocess.run([sys.executable, os.path.join(ROOT, "studies", "ur10e", "run_case_study.py"), "--work", work,
                        "--out", out, "--data", data, "--no-adapt"], check=True,
                       env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    with open(saved) as fh:
        return json.load(fh)["result"]


def imported(data: str, work: str, folder: str, name: str, urdf: str) -> str:
    out = os.path.join(work, f"{name}-cal.parquet")
    if not os.path.exists(out):
        fricli("import", os.path.join(data, folder, name + ".csv"), "--mapping", MAPPING, "--urdf", urdf,
               "--cutoff", "10", "-o", out, "-q")
    return out


def columns(path: str) -> dict:
    """Per joint (n, 6) arrays of a replay's output, and t (n,)."""
    import pyarrow.parquet as pq

    table = pq.read_table(path)
    joint = table.column("joint").to_numpy()
    out = {}
    for name in ("t", "qd", "tau_m", "tau_g", "tau_dyn", "tau_f_pred", "tau_ext_pred", "contact"):
        col = table.column(name).to_numpy()
        out[name] = np.column_stack([col[joint == j] for j in JOINTS])
    out["t"] = out["t"][:, 0]
    return out


def rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def errors(paths: list[str]) -> list[float]:
    """Per joint: RMS in motion of the friction target minus tau_f_pred, pooled over the runs."""
    pooled = [[] for _ in JOINTS]
    for path in paths:
        c = columns(path)
        for k in range(len(JOINTS)):
            mv = metrics.in_motion(c["qd"][:, k])
            e = c["tau_m"][:, k] - c["tau_g"][:, k] - c["tau_dyn"][:, k] - c["tau_f_pred"][:, k]
            pooled[k].append(e[mv])
    return [rms(np.concatenate(p)) for p in pooled]


def hindsight(paths: list[str]) -> list[float]:
    """Per joint: RMS in motion, pooled over the runs, of the friction target minus the static replay's
    tau_f_pred refitted on each run by least squares as a tau_f_pred + b qd + c sign(qd) + d: the scale,
    the viscous and Coulomb levels and an offset of each run, known in hindsight."""
    pooled = [[] for _ in JOINTS]
    for path in paths:
        c = columns(path)
        for k in range(len(JOINTS)):
            qd = c["qd"][:, k]
            mv = metrics.in_motion(qd)
            y = c["tau_m"][:, k] - c["tau_g"][:, k] - c["tau_dyn"][:, k]
            x = np.column_stack([c["tau_f_pred"][:, k], qd, np.sign(qd), np.ones_like(qd)])[mv]
            coef = np.linalg.lstsq(x, y[mv], rcond=None)[0]
            pooled[k].append(y[mv] - x @ coef)
    return [rms(np.concatenate(p)) for p in pooled]


def pushes(c: dict) -> list[dict]:
    """The pushes of a collision run, from the measured torque alone (no friction model): per joint,
    d = tau_m - tau_g - tau_dyn low-passed at PUSH_LOWPASS_HZ (zero phase); its baseline the median
    over a sliding 5 s; a joint shows a push where |d - baseline| exceeds a quarter of the joint's
    largest |d - baseline| in the run and 6 times the measurement noise (1.4826 x the median absolute
    deviation of the unfiltered d's sample-to-sample differences, / sqrt 2). Rows of any joint merged
    into intervals (gaps below 0.3 s), intervals shorter than 0.2 s dropped."""
    from scipy import ndimage

    from fricli.core import logs

    t = c["t"]
    dt = float(np.median(np.diff(t)))
    any_row = np.zeros(len(t), dtype=bool)
    shown = np.zeros((len(t), len(JOINTS)), dtype=bool)
    for k in range(len(JOINTS)):
        raw = c["tau_m"][:, k] - c["tau_g"][:, k] - c["tau_dyn"][:, k]
        d = logs.lowpass(raw, t, PUSH_LOWPASS_HZ)
        base = ndimage.median_filter(d, size=int(round(5.0 / dt)) | 1, mode="nearest")
        e = d - base
        step = np.diff(raw)
        noise = 1.4826 * np.median(np.abs(step - np.median(step))) / np.sqrt(2.0)
        shown[:, k] = (np.abs(e) > 6 * noise) & (np.abs(e) > 0.25 * np.max(np.abs(e)))
        any_row |= shown[:, k]
    idx = np.flatnonzero(any_row)
    out = []
    if len(idx) == 0:
        return out
    groups = np.split(idx, np.flatnonzero(np.diff(t[idx]) > 0.3) + 1)
    for g in groups:
        a, b = g[0], g[-1]
        if t[b] - t[a] < 0.2:
            continue
        joints_shown = [JOINTS[k] for k in range(len(JOINTS)) if shown[a:b + 1, k].any()]
        out.append({"start": float(t[a] - t[0]), "end": float(t[b] - t[0]), "rows": (int(a), int(b)),
                    "joints": joints_shown})
    return out


def _continue(obs: observer.Observer, arm: replay.Arm, rows: range, tau_m: np.ndarray) -> np.ndarray:
    """Flags (len(rows), J) of ``obs`` (a copy) stepped over ``rows`` with motor torques ``tau_m``."""
    import copy

    obs = copy.deepcopy(obs)
    w = arm.w + arm.error     # the models' robot-model error part goes with the rigid-body terms (replay.run)
    return np.array([obs.step(float(arm.t[i]), arm.f0[i], tau_m[i], arm.p[i], w[i], arm.qd[i])[2] for i in rows])


def added_contacts(arm: replay.Arm, thr: observer.Thresholds, rng: np.random.Generator, adapt) -> dict:
    """Contacts added to the motor torque of a collision-free run (tau_m - T from the onset for
    ADDED_LENGTH: the recorded path kept, the motor taking the push), one at a time, at times where
    its joint moves: per joint the delays at 2x the threshold and which sizes of a grid are flagged
    (a flag within the contact that the run without it does not raise). Sizes are multiples of the
    threshold in force just before the onset (in motion: base + share x |tau_f_pred|, filtered)."""
    import copy

    t = arm.t
    sizes = [round(float(x), 2) for x in np.arange(0.5, 3.01, 0.25)]
    plan = []
    for k, j in enumerate(arm.joints):
        moving = np.flatnonzero((np.abs(arm.qd[:, k]) > thr.moving_speed) & (t > t[0] + 2.0)
                                & (t < t[-1] - 1.5))
        for i in (rng.choice(moving, size=min(ADDED_PER_RUN, len(moving)), replace=False) if len(moving) else []):
            plan.append((int(i), k, 1.0 if rng.random() < 0.5 else -1.0))
    snapshots = {}
    w = arm.w + arm.error
    obs = observer.Observer(len(arm.joints), thr.gain, thr, adapt)
    wanted = sorted({i for i, _, _ in plan})
    for i in range(len(t)):
        if wanted and i == wanted[0]:
            snapshots[i] = copy.deepcopy(obs)
            wanted.pop(0)
            if not wanted:
                break
        obs.step(float(t[i]), arm.f0[i], arm.tau_m[i], arm.p[i], w[i], arm.qd[i])
    out = {str(j): {"delays": [], "seen": {str(s): 0 for s in sizes}, "trials": 0, "limits": []}
           for j in arm.joints}
    for i, k, sign in plan:
        rows = range(i, int(np.searchsorted(t, t[i] + ADDED_LENGTH)))
        free = _continue(snapshots[i], arm, rows, arm.tau_m)
        fig = out[str(arm.joints[k])]
        fig["trials"] += 1
        limit = float(snapshots[i].threshold[k])
        fig["limits"].append(limit)
        for s in sizes:
            tau_m = arm.tau_m.copy()
            tau_m[rows.start:rows.stop, k] -= sign * s * limit
            hit = np.flatnonzero(_continue(snapshots[i], arm, rows, tau_m)[:, k] & ~free[:, k])
            if len(hit):
                fig["seen"][str(s)] += 1
            if s == 2.0:
                fig["delays"].append(float(t[i + hit[0]] - t[i]) if len(hit) else float("inf"))
    return out


def held_contact(arm: replay.Arm, thr: observer.Thresholds, adapt) -> dict:
    """A contact of 2x the largest threshold in force (over the hold, in the run without it) held for
    HOLD seconds on each joint alone, from 5 s into the run: the adapted scale before the onset and at
    the release."""
    t = arm.t
    out = {}
    onset = np.searchsorted(t, t[0] + 5.0)
    end = np.searchsorted(t, t[onset] + HOLD)
    if end >= len(t):
        return out
    w = arm.w + arm.error
    free = observer.replay(t, arm.f0, arm.tau_m, arm.p, w, arm.qd, thr.gain, thr, adapt)
    for k, j in enumerate(arm.joints):
        tau_m = arm.tau_m.copy()
        limit = float(np.max(free.threshold[onset:end, k]))
        tau_m[onset:end, k] -= 2.0 * limit
        res = observer.replay(t, arm.f0, tau_m, arm.p, w, arm.qd, thr.gain, thr, adapt)
        out[str(j)] = {"before": float(res.scale[onset, k]), "after": float(res.scale[end, k]), "size": 2.0 * limit,
                       "free_after": float(free.scale[end, k]),
                       "flagged_share": float(res.contact[onset:end, k].mean())}
    return out


def c_check(work: str, fixed: str, thresholds: str, runs: list) -> dict:
    """The arm header with adaptation, compiled (C99 and C++), over every run of ``runs`` ((name, arm,
    replayed) with ``--adapt``): the largest difference to the replay, and the time per step."""
    import shutil

    import observer_check

    if shutil.which("cc") is None or shutil.which("g++") is None:
        return {}
    header = os.path.join(work, "arm.h")
    fricli("export", fixed, "--observer", "--thresholds", thresholds, "--adapt", "--prefix", "arm", "-o", header)
    paths = [os.path.join(fixed, f"joint_{j}.npz") for j in runs[0][1].joints]
    n = len(paths)
    out = {"runs": [name for name, _, _ in runs], "rows": 0}
    for cxx in (False, True):
        exe = observer_check.build(header, "arm", paths, work, cxx=cxx)
        worst = {"tau_f": 0.0, "tau_ext": 0.0, "contact": 0}
        for _, arm, replayed in runs:
            got = observer_check.run(exe, observer_check.rows(arm, paths), n, work)
            worst["tau_f"] = max(worst["tau_f"], float(np.max(np.abs(got[:, :n] - replayed.tau_f))))
            worst["tau_ext"] = max(worst["tau_ext"], float(np.max(np.abs(got[:, n:2 * n] - replayed.tau_ext))))
            worst["contact"] += int(np.sum(got[:, 2 * n:].astype(bool) != replayed.contact))
            out["rows"] += len(arm.t) if not cxx else 0
        out["cxx" if cxx else "c"] = worst
    exe = observer_check.build(header, "arm", paths, work)
    out["ns_per_step"] = observer_check.bench(exe, observer_check.rows(runs[0][1], paths), work, 2.0)
    out["load"] = os.getloadavg()[0]
    out["cpus"] = os.cpu_count()
    return out


def halves(replayed: tuple) -> dict:
    """Rows flagged per joint and events in the first and the second half (in time) of a replay
    (its output path and --json figures)."""
    c = columns(replayed[0])
    middle = 0.5 * (c["t"][0] + c["t"][-1])
    first = c["t"] < middle
    out = {}
    for part, rows in (("first", first), ("second", ~first)):
        out[part] = {"rows": {str(j): int(c["contact"][rows, k].sum()) for k, j in enumerate(JOINTS)},
                     "events": int(sum(bool(e["start"] < middle) == (part == "first") for e in replayed[1]["events"]))}
    return out


def plot_pushes(runs: dict, thr: observer.Thresholds, path: str) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 2.0 * len(JOINTS)), constrained_layout=True)
    axes = fig.subplots(len(JOINTS), len(runs), sharex="col", squeeze=False)
    for col, (name, (c, found)) in enumerate(runs.items()):
        t = c["t"] - c["t"][0]
        for k, j in enumerate(JOINTS):
            ax = axes[k][col]
            d = c["tau_m"][:, k] - c["tau_g"][:, k] - c["tau_dyn"][:, k]
            ax.plot(t, d - np.median(d), lw=0.6, color="0.6", label="measured: tau_m - tau_g - tau_dyn (minus median)")
            ax.plot(t, c["tau_ext_pred"][:, k], lw=0.8, color="C0", label="tau_ext_pred (observer)")
            ax.axhline(thr.threshold[k], color="C3", lw=0.5, ls="--")
            ax.axhline(-thr.threshold[k], color="C3", lw=0.5, ls="--", label="threshold")
            flag = c["contact"][:, k].astype(bool)
            ax.fill_between(t, 0, 1, where=flag, transform=ax.get_xaxis_transform(), color="C3", alpha=0.15,
                            label="contact flagged")
            for p in found:
                ax.axvspan(p["start"], p["end"], ymin=0.0, ymax=0.05, color="k")
            ax.set_ylabel(f"joint {j} [Nm]")
        axes[0][col].set_title(name)
        axes[-1][col].set_xlabel("time [s] (black bars: pushes in the measured torque)")
    axes[0][0].legend(loc="upper left", fontsize=6)
    fig.savefig(path, dpi=90)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=DEFAULT_DATA)
    ap.add_argument("--work", default=None, help="folder of the case study's work (made when absent)")
    ap.add_argument("--out", default=ROOT, help="where docs/ goes (default: this clone)")
    ap.add_argument("--gain", type=float, help="the observer's gain [1/s] for both thresholds files (default: thresholds' own)")
    args = ap.parse_args(argv)
    gain = [] if args.gain is None else ["--gain", f"{args.gain:g}"]
    started = time.time()
    work = args.work or tempfile.mkdtemp()
    os.makedirs(work, exist_ok=True)
    study = case_study(work, args.data)
    fixed, cal = os.path.join(work, "fixed"), os.path.join(work, "ur10e-cal.urdf")
    fit = os.path.join(work, f"{FIT_RUN}-cal.parquet")
    validation = [os.path.join(work, f"{n}-cal.parquet") for n in study["validation_runs"]]
    load = os.path.join(work, f"{LOAD_RUN}-cal-payload.parquet")
    # the payload run with the payload the joints carry, identified on its first half (the case study's)
    seen = os.path.join(work, f"{LOAD_RUN}-cal-seen.parquet")
    loads = [load] + ([seen] if os.path.exists(seen) else [])
    jointwise = [imported(args.data, work, "jointwise_motion", f"ur-20_01_22-joint_{j}", cal) for j in JOINTS]
    collision = [imported(args.data, work, "collision", f"ur-20_01_22-push_pose_{k}", cal) for k in (1, 2)]
    thresholds = os.path.join(work, "thresholds.json")
    fricli("thresholds", fixed, fit, "--urdf", cal, *gain, "-o", thresholds, "-q")
    thr = observer.Thresholds.read(thresholds)
    # the constant thresholds of before (a flag on the first sample beyond, no share of the friction)
    constant = os.path.join(work, "thresholds-constant.json")
    fricli("thresholds", fixed, fit, "--urdf", cal, *gain, "--persistence", "1", "--no-level-share", "-o", constant, "-q")
    replays: dict[str, dict] = {}
    for path in validation + loads + jointwise + collision:
        name = os.path.basename(path).removesuffix(".parquet")
        replays[name] = {}
        modes = [("static", thresholds, []), ("adapt", thresholds, ["--adapt"])]
        if "push_pose" not in name:
            modes.append(("constant", constant, ["--adapt"]))
        for mode, limits, extra in modes:
            out = os.path.join(work, f"replay-{mode}-{name}.parquet")
            replays[name][mode] = (out, fricli("replay", fixed, path, "--urdf", cal, "--thresholds", limits,
                                               *extra, "-o", out, "--json", "-q", json_out=True))
    names = [os.path.basename(p).removesuffix(".parquet") for p in validation]
    base = [study["joints"][str(j)]["linear"]["moving"] for j in JOINTS]
    own = [study["joints"][str(j)]["fixed"]["own_friction_moving"] / study["joints"][str(j)]["linear"]["moving"]
           for j in JOINTS]
    static_err = errors([replays[n]["static"][0] for n in names])
    adapt_err = errors([replays[n]["adapt"][0] for n in names])
    four = hindsight([replays[n]["static"][0] for n in names])
    # collision runs: pushes from the measured torque, flags of the adapted replay
    push_runs, push_rows = {}, []
    for path in collision:
        name = os.path.basename(path).removesuffix(".parquet")
        c = columns(replays[name]["adapt"][0])
        found = pushes(c)
        push_runs[name.removesuffix("-cal")] = (c, found)
        for p in found:
            a, b = p["rows"]
            stop = min(len(c["t"]) - 1, b + int(round(0.5 / np.median(np.diff(c["t"])))))
            flagged = [JOINTS[k] for k in range(len(JOINTS)) if c["contact"][a:stop + 1, k].any()]
            peak = {JOINTS[k]: float(c["tau_ext_pred"][a:stop + 1, k][np.argmax(np.abs(c["tau_ext_pred"][a:stop + 1, k]))])
                    for k in range(len(JOINTS))}
            push_rows.append({"run": name.removesuffix("-cal"), **{k: v for k, v in p.items() if k != "rows"},
                              "flagged": flagged, "peak": peak})
    img = os.path.join(args.out, "docs", "studies", "img")
    os.makedirs(img, exist_ok=True)
    plot_pushes(push_runs, thr, os.path.join(img, "contact-collision-runs.png"))
    # added contacts (known time, joint, size) on the collision-free runs of other days
    rng = np.random.default_rng(SEED)
    adaptation = observer.Adaptation()
    added, held, compared = {}, {}, []
    for path in validation:
        arm = replay.read_arm(fixed, path, cal)
        name = os.path.basename(path).removesuffix("-cal.parquet")
        added[name] = added_contacts(arm, thr, rng, adaptation)
        held[name] = held_contact(arm, thr, adaptation)
        compared.append((name, arm, replay.run(arm, thr.gain, thr, adaptation)))
    c_figures = c_check(work, fixed, thresholds, compared)
    def shown(text: str) -> str:
        return text.replace(os.path.abspath(work), "WORK").replace(os.path.abspath(args.data), "DATA") \
            .replace(ROOT + os.sep, "")

    result = {"thresholds": thr.as_json(), "constant": observer.Thresholds.read(constant).as_json(),
              "load_run": os.path.basename(load).removesuffix(".parquet"), "baseline": base, "static": static_err, "adapt": adapt_err, "own": own,
              "hindsight_four": [f / b for f, b in zip(four, base)],
              "fixed_case_study": [study["joints"][str(j)]["fixed"]["moving"] for j in JOINTS],
              "false_alarms": {n: {m: {"rows": {j: v["contact_rows"] for j, v in r[1]["joints"].items()},
                                       "events": len(r[1]["events"])} for m, r in modes.items()}
                               for n, modes in replays.items() if "push_pose" not in n and LOAD_RUN not in n},
              "payload": {n: {m: halves(r) for m, r in modes.items()} for n, modes in replays.items() if LOAD_RUN in n},
              "pushes": push_rows, "added": added, "held": held, "c": c_figures,
              "commands": [shown(c) for c in COMMANDS], "seconds": time.time() - started}
    atomic_write_bytes(os.path.join(args.out, "docs", "studies", "contact-detection-results.json"),
                       json.dumps(result, indent=1, default=float).encode())
    text = document(result, names)
    atomic_write_bytes(os.path.join(args.out, "docs", "studies", "contact-detection.md"), text.encode())
    print(f"wrote {os.path.join(args.out, 'docs', 'studies', 'contact-detection.md')} ({time.time() - started:.0f} s)",
          file=sys.stderr)


def document(r: dict, names: list[str]) -> str:
    import contact_detection_text

    return contact_detection_text.render(r, names, JOINTS, dict(seed=SEED, per_run=ADDED_PER_RUN,
                                                                  length=ADDED_LENGTH, hold=HOLD,
                                                                  delay=DELAY_LIMIT, lowpass=PUSH_LOWPASS_HZ))


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    main()
