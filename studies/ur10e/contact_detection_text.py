"""The words of docs/studies/contact-detection.md around the figures of run_contact_detection.py."""

from __future__ import annotations

import math

import numpy as np


def _short(name: str) -> str:
    return name.removeprefix("ur-").removesuffix("-cal").removesuffix("-payload")


def render(r: dict, names: list[str], joints, s: dict) -> str:
    thr = r["thresholds"]
    J = [str(j) for j in joints]
    base, static, adapt, own = r["baseline"], r["static"], r["adapt"], r["own"]
    rs = [a / b for a, b in zip(static, base)]
    ra = [a / b for a, b in zip(adapt, base)]
    mean_s, mean_a = float(np.mean(rs)), float(np.mean(ra))
    out = ["# Contact detection and online friction adaptation: measured on the UR10e",
           "",
           "This document is written by `PYTHONPATH=. python studies/ur10e/run_contact_detection.py --work W` "
           f"(about {r['seconds'] / 60:.0f} min on 2 shared cores with W holding the UR10e case study's work; the script "
           "runs `studies/ur10e/run_case_study.py` into W first when it does not, about 2 min more). WORK below is W, DATA "
           "the recordings (../shared/data/ur10e). Every figure below comes "
           "from that run; the numbers are also in `docs/studies/contact-detection-results.json`, the fricli commands it "
           "ran are listed at the end. What runs in the controller, and how a control cycle calls it: "
           "[contact-detection.md](../contact-detection.md).",
           "",
           "## Protocol",
           "",
           "- Models: the case study's (`fricli identify` and `fricli diagnose --fix --calibrate` on the fitting run "
           "`ur-20_02_19_14harm50sec`, docs/studies/case-study-ur10e.md), the calibrated URDF for every import and replay.",
           "- Thresholds: calibrated on the fitting run only, with the defaults; nothing of the other runs enters them.",
           "- Scored: the identification runs of other days (the case study's validation runs); false alarms on every "
           "other collision-free shared run (those, the payload run of the fitting day imported with its payload "
           "declared, and the six jointwise runs); the two collision runs.",
           "- The defaults (gain, quantile, margin, release, moving speed, time constant, bounds) were set before the "
           "figures below were computed, with three changes made after seeing false alarms and errors on these runs, "
           "each for a reason stated in [contact-detection.md](../contact-detection.md): the static friction band at rest (before it, held joints raised most "
           "false alarms), the scale alone as the default adaptation (the offset made joint 5 worse than the static "
           "model), and the hold-off after a flag (before it, a contact held for 10 s moved the scale by up to 10.6 % "
           "where its residual dipped below the release for a moment).",
           "",
           "## Static and online friction on the runs of other days",
           "",
           "RMS in motion of the friction target minus tau_f_pred, pooled over the "
           f"{len(names)} runs, as a ratio to the case study's baseline (CAD URDF with Fv·qd + Fc·sign(qd) + offset). "
           "Static: `fricli replay` without `--adapt` (the case study's fricli column); online: `--adapt`, each run "
           "starting from the fitted level; with each run's own level: the case study's hindsight figure (each run's "
           "own Fv, Fc, offset fitted on that run), a bound no causal adaptation of the level is expected to beat.",
           "",
           "| joint | baseline [Nm] | static | online (`--adapt`) | change | with each run's own level (hindsight) |",
           "|---|---|---|---|---|---|"]
    for k, j in enumerate(J):
        out.append(f"| {j} | {base[k]:.3f} | {rs[k]:.3f} | **{ra[k]:.3f}** | {100 * (ra[k] / rs[k] - 1):+.1f} % | "
                   f"{own[k]:.3f} |")
    out.append(f"| mean | | {mean_s:.3f} | **{mean_a:.3f}** | | {float(np.mean(own)):.3f} |")
    worse = [j for k, j in enumerate(J) if ra[k] > rs[k]]
    out += ["",
            f"Every joint's online error is at most its static one: **{'yes' if not worse else 'no (joints ' + ', '.join(worse) + ')'}**. "
            f"Mean ratio {mean_a:.3f} (target at most 0.60: **{'met' if mean_a <= 0.60 else 'not met'}**); "
            f"joint 1 {ra[0]:.3f} (target 0.54: **{'met' if ra[0] <= 0.54 else 'not met'}**), joint 6 {ra[5]:.3f} "
            f"(target 0.90: **{'met' if ra[5] <= 0.90 else 'not met'}**). The hindsight level of each run averages "
            f"{float(np.mean(own)):.3f}: a mean of 0.60 asks for more than each run's friction level.",
            ""]
    out += ["## False alarms on collision-free runs",
            "",
            "Rows flagged per joint (static observer / with `--adapt`), thresholds of the fitting run:",
            "",
            "| run | " + " | ".join(f"joint {j}" for j in J) + " | events (static / adapt) |",
            "|---|" + "---|" * (len(J) + 1)]
    total_s = total_a = 0
    for run, modes in r["false_alarms"].items():
        cells = [f"{modes['static']['rows'][j]} / {modes['adapt']['rows'][j]}" for j in J]
        total_s += modes["static"]["events"]
        total_a += modes["adapt"]["events"]
        out.append(f"| {_short(run)} | " + " | ".join(cells) + f" | {modes['static']['events']} / {modes['adapt']['events']} |")
    clean = [run for run, m in r["false_alarms"].items() if m["adapt"]["events"] == 0]
    out += ["",
            f"Runs without any flag (with `--adapt`): {len(clean)} of {len(r['false_alarms'])}; events in all: "
            f"{total_s} static, {total_a} with `--adapt`. Zero flags on every other collision-free run: "
            f"**{'met' if total_a == 0 else 'not met'}**.",
            "",
            "Per joint: threshold and static band calibrated on the fitting run (Nm):",
            "",
            "| joint | threshold | static friction band F_s | friction scale S |", "|---|---|---|---|"]
    for j in J:
        t = thr["joints"][j]
        out.append(f"| {j} | {t['threshold']:.3f} | {t['static_friction']:.3f} | {t['friction_scale']:.3f} |")
    out += ["",
            "## The pushes of the two collision runs",
            "",
            "The arm holds a pose while a person pushes it. The pushes were found in the measured torque alone, "
            "without any friction model: per joint, tau_m - tau_g - tau_dyn low-passed at "
            f"{s['lowpass']:g} Hz (zero phase) minus its sliding 5 s median; a joint shows a push where that departs "
            "by more than a quarter of its largest departure in the run and by more than 6 times the measurement noise "
            "(1.4826 × the median absolute deviation of the unfiltered signal's sample-to-sample differences, / √2); "
            "rows of any joint are merged into intervals (gaps under 0.3 s), intervals under 0.2 s dropped. (This rule "
            "replaced a first one that took the noise from the spread of the departure itself: it missed every push of "
            "joint 1 in pose 2, whose pushes fill much of the run.) A push counts as flagged when any joint is flagged from its start to "
            "0.5 s after its end (`fricli replay --adapt`).",
            "",
            "![collision runs](img/contact-collision-runs.png)",
            "",
            "| run | push [s] | joints showing it | joints flagged | peak tau_ext_pred of the joints showing it [Nm] |",
            "|---|---|---|---|---|"]
    missed = 0
    for p in r["pushes"]:
        peaks = ", ".join(f"{j}: {p['peak'][str(j)] if str(j) in p['peak'] else p['peak'][j]:+.1f}" for j in p["joints"])
        flagged = ", ".join(map(str, p["flagged"])) or "**none**"
        missed += not p["flagged"]
        out.append(f"| {_short(p['run'])} | {p['start']:.2f}–{p['end']:.2f} | {', '.join(map(str, p['joints']))} | "
                   f"{flagged} | {peaks} |")
    out += ["",
            f"Pushes flagged: {len(r['pushes']) - missed} of {len(r['pushes'])}: "
            f"**{'met' if missed == 0 else 'not met'}**. At rest a push shows only beyond the static band: a joint "
            "whose push stays within the friction it holds is not flagged, by design.",
            ""]
    out += ["## Contacts of known time, joint and size",
            "",
            "Added to the collision-free runs of other days: from an onset where the joint moves (drawn at random, "
            f"seed {s['seed']}, {s['per_run']} per joint and run), a constant external torque of known sign and size "
            f"for {s['length']:g} s, subtracted from the recorded motor torque (the path kept as recorded: the "
            "controller takes the push), replayed with `--adapt` from the state the run had at the onset. A contact "
            "counts as detected when the joint is flagged within it where the run without it is not. Sampling is "
            "about 100 Hz, so delays come in steps of 10 ms.",
            "",
            f"| joint | threshold [Nm] | contacts | at 2× threshold: detected | median delay [ms] | max delay [ms] | within {1000 * s['delay']:.0f} ms | smallest detected in all [× threshold] | [Nm] |",
            "|---|---|---|---|---|---|---|---|---|"]
    all_within = True
    for j in J:
        delays = [d for run in r["added"].values() for d in run.get(j, {}).get("delays", [])]
        trials = sum(run.get(j, {}).get("trials", 0) for run in r["added"].values())
        seen: dict[str, int] = {}
        for run in r["added"].values():
            for size, n in run.get(j, {}).get("seen", {}).items():
                seen[size] = seen.get(size, 0) + n
        finite = [d for d in delays if math.isfinite(d)]
        within = sum(d <= s["delay"] + 1e-9 for d in finite)
        all_within &= within == len(delays)
        smallest = min((float(k) for k, n in seen.items() if n == trials), default=float("nan"))
        t = thr["joints"][j]["threshold"]
        out.append(f"| {j} | {t:.3f} | {trials} | {len(finite)} of {len(delays)} | "
                   f"{1000 * float(np.median(finite)) if finite else float('nan'):.0f} | "
                   f"{1000 * max(finite) if finite else float('nan'):.0f} | {within} of {len(delays)} | "
                   f"{smallest:g} | {smallest * t:.2f} |")
    out += ["",
            f"Every contact of twice the threshold detected within {1000 * s['delay']:.0f} ms: "
            f"**{'met' if all_within else 'not met'}**. Smallest detected in all: the smallest size of the grid "
            "0.5, 0.75, ..., 3 × threshold flagged in every trial of the joint, in motion. At rest a push shows once the held friction and the push together leave the static band: between the threshold and the threshold plus 2 F_s, depending on the friction the joint holds and the direction of the push.",
            "",
            f"A contact of twice the threshold held for {s['hold']:g} s on one joint (5 s into each run), with "
            "`--adapt`: the adapted scale at the release against the one at the onset.",
            "",
            "| joint | largest change of the scale over the runs | the same runs without the contact | share of the hold flagged (lowest) |",
            "|---|---|---|---|"]
    worst = 0.0
    for j in J:
        ch = [abs(v[j]["after"] / v[j]["before"] - 1) for v in r["held"].values() if j in v]
        free = [abs(v[j]["free_after"] / v[j]["before"] - 1) for v in r["held"].values() if j in v]
        share = [v[j]["flagged_share"] for v in r["held"].values() if j in v]
        if ch:
            worst = max(worst, max(ch))
            out.append(f"| {j} | {100 * max(ch):.2f} % | {100 * max(free):.2f} % | {100 * min(share):.0f} % |")
    out += ["", f"Largest change during a held contact: {100 * worst:.2f} % (at most 5 %: "
                f"**{'met' if worst <= 0.05 else 'not met'}**).", ""]
    c = r.get("c") or {}
    out += ["## The C header", ""]
    if c:
        out += [f"`fricli export fixed --observer --thresholds thresholds.json --adapt --prefix arm` compiled with "
                "`-std=c99 -Wall -Wextra -pedantic -Werror -O2` and as C++ (`-x c++`, same warnings), run over "
                f"every row of the {len(c['runs'])} runs of other days ({c['rows']:,} rows; `tests/observer_check.py`'s driver) "
                f"against the replay with `--adapt`: largest difference "
                f"C {max(c['c']['tau_f'], c['c']['tau_ext']):.2g} Nm, C++ {max(c['cxx']['tau_f'], c['cxx']['tau_ext']):.2g} "
                f"Nm, contact flags differing {c['c']['contact'] + c['cxx']['contact']} (tolerance 1e-9 on every row: "
                f"**{'met' if max(c['c']['tau_f'], c['c']['tau_ext'], c['cxx']['tau_f'], c['cxx']['tau_ext']) <= 1e-9 and not c['c']['contact'] + c['cxx']['contact'] else 'not met'}**).",
                "",
                f"One step of the six-joint arm (the six diagnosed LuGre models, observer, adaptation, detection): "
                f"**{c['ns_per_step']:.0f} ns** (CPU time of the driver at -O2, {c['cpus']} cores with load average "
                f"{c['load']:.1f} while it ran: shared, so an upper figure; target at most 2 µs).", ""]
    else:
        out += ["No C compiler on the machine that wrote this document: not checked here (tests/test_replay.py does).", ""]
    out += ["## Commands", "",
            "The replays and exports of this run (imports already in WORK, and the case study's own commands, "
            "listed in docs/studies/case-study-ur10e.md, are not repeated):", "", "```sh"] + [f"fricli {cmd}" for cmd in r["commands"]] + ["```", ""]
    return "\n".join(out)
