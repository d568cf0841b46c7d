"""Neural models on the real UR10e arm: train-base against the LuGre model on runs of other
days, and adapt on one run of a day scored on another run of the same day.

    python benchmarks/ur10e_neural.py                 # both tables (about 10 minutes on 2 cores)
    python benchmarks/ur10e_neural.py --part base     # the train-base table only
    python benchmarks/ur10e_neural.py --part adapt --json out.json
    python benchmarks/ur10e_neural.py --part base --train-base-option=--ensemble=5   # the mean of five networks
    python benchmarks/ur10e_neural.py --part base --train-base-option=--bristles=off  # no pre-sliding state
    python benchmarks/ur10e_neural.py --part base --train-base-option=--no-prior      # the network alone

Every model comes from the fricli command line (the commands are printed on stderr and listed
at the end); the script only scores: the RMS over the rows in motion (``metrics.in_motion``) of
the friction target tau_m - tau_g - tau_dyn minus the model's prediction, pooled over the runs
scored. Runs are imported as in docs/studies/case-study-ur10e.md (--cutoff 10). The base table adds, when
train-base reports it, the held-out RMS on the training log without and with the pre-sliding
state and the bristle stiffness sigma0 of the model written, and the network's share lambda of
the blend with the LuGre static curve with the held-out RMS of network, prior and blend; a second table splits the errors
into the rows within 0.1 s after a velocity reversal and the rest, with the LuGre model also
run with sigma0 x 1e6 (no pre-sliding).

- base: ``identify`` and ``train-base`` on ur-20_02_12-50sec_12harm, scored on every run of
  19_10_01, 20_02_05, 20_02_06 and 20_02_10.
- adapt: the bases (LuGre from ``identify``, NN_base from ``train-base``) fitted on
  ur-20_02_19_14harm50sec, a day of no pair; for each day with two runs, ``adapt`` on one run,
  scored on the other, both ways round, against the base on that other run.

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

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from fricli import models
from fricli.core import logs, metrics  # noqa: E402

DEFAULT_DATA = os.path.join(os.path.dirname(ROOT), "shared", "data", "ur10e")
MAPPING = os.path.join(ROOT, "docs", "ur10e-mapping.toml")
JOINTS = (1, 2, 3, 4, 5, 6)
CUTOFF_HZ = 10.0
BASE_FIT = "ur-20_02_12-50sec_12harm"
BASE_VALIDATION = ("ur-19_10_01-13_51_41", "ur-19_10_01-14_04_13", "ur-19_10_01-14_04_41",
                   "ur-20_02_05-20sec_12harm", "ur-20_02_05-20sec_8harm", "ur-20_02_06-20sec_10harm",
                   "ur-20_02_06-20sec_5harm", "ur-20_02_10-20sec_7harm", "ur-20_02_10-30sec_12harm")
ADAPT_BASE = "ur-20_02_19_14harm50sec"
PAIRS = (("ur-19_10_01-14_04_13", "ur-19_10_01-14_04_41"),
         ("ur-20_02_05-20sec_12harm", "ur-20_02_05-20sec_8harm"),
         ("ur-20_02_06-20sec_10harm", "ur-20_02_06-20sec_5harm"),
         ("ur-20_02_10-20sec_7harm", "ur-20_02_10-30sec_12harm"),
         ("ur-20_02_12-40sec_12harm", "ur-20_02_12-50sec_12harm"))

COMMANDS: list[str] = []


def fricli(*args: str, json_out: bool = False):
    """Run one fricli command as a user would; its --json output when asked."""
    shown = " ".join(args)
    COMMANDS.append(shown)
    print(f"$ fricli {shown}", file=sys.stderr, flush=True)
    done = subprocess.run([sys.executable, "-m", "fricli", *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    if done.returncode != 0:
        raise SystemExit(f"fricli {shown} failed ({done.returncode}): {done.stderr.strip()}")
    return json.loads(done.stdout) if json_out else None


def import_run(data: str, work: str, name: str) -> str:
    out = os.path.join(work, name + ".parquet")
    if not os.path.exists(out):
        fricli("import", os.path.join(data, "identification", name + ".csv"), "--mapping", MAPPING,
               "--urdf", os.path.join(data, "ur10e.urdf"), "--cutoff", str(CUTOFF_HZ), "-o", out, "-q")
    return out


def moving_error(model_dir: str, runs: list[str], joint: int) -> float:
    """RMS [Nm] over the rows in motion of target - prediction, pooled over ``runs``."""
    model = models.load(os.path.join(model_dir, f"joint_{joint}.npz"))[0]
    errs = []
    for path in runs:
        sig = logs.load_log(path, joint=str(joint)).signals
        e = logs.friction_target(sig) - model.predict(sig)[0]
        errs.append(e[metrics.in_motion(sig["qd"])])
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e * e)))


REVERSAL_WINDOW = 0.1   # [s] after a reversal of the velocity: the rows of the "reversals" figures


def since_reversal(t: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Time [s] since the last change of sign of qd (n,); from the start before the first one."""
    s = np.sign(qd)
    start = np.zeros(qd.size, dtype=int)
    turns = np.flatnonzero(s[1:] * s[:-1] < 0) + 1
    start[turns] = turns
    return t - t[np.maximum.accumulate(start)]


def reversal_errors(model_dirs: dict[str, str], runs: list[str], joint: int) -> dict:
    """In-motion RMS [Nm] pooled over ``runs`` within REVERSAL_WINDOW after a reversal ("near") and
    after it ("far"), for each model folder, and for the first one (LuGre) with sigma0 x 1e6 and
    no micro-damping ("lugre_rigid": no pre-sliding)."""
    loaded = {name: models.load(os.path.join(d, f"joint_{joint}.npz"))[0] for name, d in model_dirs.items()}
    first = next(iter(loaded.values()))
    loaded["lugre_rigid"] = first.replace(sigma0=first.sigma0 * 1e6, sigma1=0.0)
    errs = {name: ([], []) for name in loaded}
    for path in runs:
        sig = logs.load_log(path, joint=str(joint)).signals
        y, moving = logs.friction_target(sig), metrics.in_motion(sig["qd"])
        near = since_reversal(sig["t"], sig["qd"]) < REVERSAL_WINDOW
        for name, model in loaded.items():
            e = y - model.predict(sig)[0]
            errs[name][0].append(e[moving & near])
            errs[name][1].append(e[moving & ~near])
    return {name: {part: float(np.sqrt(np.mean(np.concatenate(pair[k]) ** 2))) for k, part in enumerate(("near", "far"))}
            for name, pair in errs.items()}


def base_part(data: str, work: str, seed: int, options: tuple[str, ...] = ()) -> dict:
    fit = import_run(data, work, BASE_FIT)
    runs = [import_run(data, work, name) for name in BASE_VALIDATION]
    lugre, nn = os.path.join(work, "base-lugre"), os.path.join(work, f"base-nn-s{seed}")
    fricli("identify", fit, "-o", lugre, "-q")
    trained = fricli("train-base", fit, "--seed", str(seed), *options, "-o", nn, "--json", "-q", json_out=True)
    rows = []
    for j in JOINTS:
        a, b = moving_error(lugre, runs, j), moving_error(nn, runs, j)
        fit_j = trained["joints"][str(j)]
        rows.append({"joint": j, "lugre": a, "nn": b, "ratio": b / a, "step": fit_j["best_step"],
                     "seconds": fit_j["seconds"], "cross_validation": fit_j.get("cross_validation"),
                     "bristles": fit_j.get("bristles"), "prior": fit_j.get("prior"),
                     "reversals": reversal_errors({"lugre": lugre, "nn": nn}, runs, j)})
    return {"fit": BASE_FIT, "validation": list(BASE_VALIDATION), "seed": seed, "train_base_options": list(options),
            "joints": rows}


def adapt_part(data: str, work: str, seed: int) -> dict:
    fit = import_run(data, work, ADAPT_BASE)
    bases = {"lugre": os.path.join(work, "adapt-base-lugre"), "nn": os.path.join(work, f"adapt-base-nn-s{seed}")}
    fricli("identify", fit, "-o", bases["lugre"], "-q")
    fricli("train-base", fit, "--seed", str(seed), "-o", bases["nn"], "-q")
    cases = []
    for first, second in PAIRS:
        for on, scored in ((first, second), (second, first)):
            on_path, scored_path = import_run(data, work, on), import_run(data, work, scored)
            for kind, base in bases.items():
                out = os.path.join(work, f"adapted-{kind}-s{seed}-{on}")
                results = fricli("adapt", base, on_path, "--seed", str(seed), "-o", out, "--json", "-q",
                                 json_out=True)
                kept = {int(j): r.get("adapted", True) for j, r in results["joints"].items()}  # no key: always adapted
                for j in JOINTS:
                    cases.append({"base": kind, "adapted_on": on, "scored_on": scored, "joint": j,
                                  "residual_kept": kept[j], "base_error": moving_error(base, [scored_path], j),
                                  "adapted_error": moving_error(out, [scored_path], j)})
    return {"base_fit": ADAPT_BASE, "cases": cases}


def base_table(result: dict) -> str:
    """The train-base table; with the pre-sliding state checked (train-base --json "bristles"), the
    held-out RMS on the training log without and with it, and sigma0 where the model has it; with
    the prior ("prior"), the network's share lambda and the held-out RMS of network, prior and blend."""
    state = any(r.get("bristles") and "static_rmse" in r["bristles"] for r in result["joints"])
    prior = any(r.get("prior") and "prior_rmse" in r["prior"] for r in result["joints"])
    head = "| joint | LuGre [Nm] | NN_base [Nm] | NN / LuGre | step kept |"
    lines = [head + (" held out: static → state [Nm] | sigma0 [Nm/rad] |" if state else "")
             + (" lambda | held out: network, prior → blend [Nm] |" if prior else ""),
             "|---|---:|---:|---:|---:|" + ("---:|---:|" if state else "") + ("---:|---:|" if prior else "")]
    for r in result["joints"]:
        line = f"| {r['joint']} | {r['lugre']:.3f} | {r['nn']:.3f} | {r['ratio']:.2f} | {r['step']:,} |"
        if state:
            b = r.get("bristles") or {}
            held = f" {b['static_rmse']:.3f} → {b['bristles_rmse']:.3f} |" if "static_rmse" in b else " - |"
            line += held + (f" {b['sigma0']:.3g} |" if b.get("sigma0") else " - |")
        if prior:
            p = r.get("prior") or {}
            line += (f" {p['blend']:.2f} | {p['network_rmse']:.3f}, {p['prior_rmse']:.3f} → {p['blend_rmse']:.3f} |"
                     if "prior_rmse" in p else " - | - |")
        lines.append(line)
    return "\n".join(lines)


def reversal_table(result: dict) -> str:
    """Where the errors of the base table sit: near the reversals or not."""
    lines = [f"| joint | LuGre ≤ {REVERSAL_WINDOW:g} s after a reversal | LuGre, sigma0 × 1e6 | NN_base | "
             "LuGre later | LuGre, sigma0 × 1e6 | NN_base |", "|---|---:|---:|---:|---:|---:|---:|"]
    for r in result["joints"]:
        e = r["reversals"]
        cells = [f"{e[m][part]:.3f}" for part in ("near", "far") for m in ("lugre", "lugre_rigid", "nn")]
        lines.append(f"| {r['joint']} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def adapt_table(result: dict, kind: str) -> str:
    lines = ["| adapted on | scored on | " + " | ".join(f"joint {j}" for j in JOINTS) + " |",
             "|---|---|" + "---|" * len(JOINTS)]
    cases = [c for c in result["cases"] if c["base"] == kind]
    for on, scored in dict.fromkeys((c["adapted_on"], c["scored_on"]) for c in cases):
        cells = []
        for c in (c for c in cases if c["adapted_on"] == on and c["scored_on"] == scored):
            mark = "" if c["residual_kept"] else " (base kept)"
            cells.append(f"{c['base_error']:.3f} → {c['adapted_error']:.3f}{mark}")
        lines.append(f"| {on[3:]} | {scored[3:]} | " + " | ".join(cells) + " |")
    worse = [c for c in cases if c["adapted_error"] > c["base_error"]]
    ratios = [c["adapted_error"] / c["base_error"] for c in cases]
    lines.append("")
    lines.append(f"adapted / base on the other run: {min(ratios):.3f} to {max(ratios):.3f}; "
                 f"worse than the base in {len(worse)} of {len(cases)} cases")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=DEFAULT_DATA)
    parser.add_argument("--work", default=None, help="working folder (default: a temporary one)")
    parser.add_argument("--part", choices=("base", "adapt", "both"), default="both")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None, help="also write the figures to this file")
    parser.add_argument("--train-base-option", action="append", default=[], metavar="OPT",
                        help="add OPT to the base part's train-base command (repeatable), e.g. "
                             "--train-base-option=--ensemble=5")
    args = parser.parse_args()
    if not os.path.isdir(os.path.join(args.data, "identification")):
        raise SystemExit(f"no UR10e data at {args.data}")
    with tempfile.TemporaryDirectory() as scratch:
        work = args.work or scratch
        os.makedirs(work, exist_ok=True)
        out = {}
        if args.part in ("base", "both"):
            out["base"] = base_part(args.data, work, args.seed, tuple(args.train_base_option))
            print(f"## train-base on {BASE_FIT}, in-motion RMS on the runs of other days\n")
            print(base_table(out["base"]) + "\n")
            print(f"In-motion RMS [Nm] up to {REVERSAL_WINDOW:g} s after a reversal of the velocity and after that:\n")
            print(reversal_table(out["base"]) + "\n")
        if args.part in ("adapt", "both"):
            out["adapt"] = adapt_part(args.data, work, args.seed)
            for kind, label in (("lugre", "LuGre"), ("nn", "NN_base")):
                print(f"## adapt {label} (fitted on {ADAPT_BASE}): base → adapted, in-motion RMS [Nm] "
                      "on the other run of the day\n")
                print(adapt_table(out["adapt"], kind) + "\n")
        print("Commands run (WORK is the working folder):\n")
        for command in COMMANDS:
            print("    fricli " + command.replace(work, "WORK").replace(args.data, "DATA").replace(ROOT + os.sep, ""))
        if args.json:
            with open(args.json, "w") as fh:
                json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
