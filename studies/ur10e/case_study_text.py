"""The words of docs/studies/case-study-ur10e.md around the figures that run_case_study.py computes."""

from __future__ import annotations

import numpy as np

# what an added effect means physically on a robot arm
MEANING = {
    "gravity": "the URDF's gravity torque is off by a factor: CAD link masses or centres of mass that differ "
               "from the real arm's (a robot-model error, not friction)",
    "acceleration": "inertia missing from tau_dyn, most likely the motor and gear inertia reflected to the joint, "
                    "which the URDF does not hold (a robot-model error)",
    "velocity": "the friction-velocity curve has another shape than the identified one (Stribeck region, "
                "viscous bend at speed)",
    "load": "friction grows with the load the gear carries (|tau_g|, the teeth's normal force)",
    "quadrant": "friction differs when the motor drives the joint and when gravity drives it (the gear's "
                "efficiency depends on the direction of power flow)",
    "offset": "a constant torque: a current-sensor offset or a cable's spring",
    "level": "the friction level differs (temperature, lubrication)",
    "direction": "friction differs by direction of motion",
    "position": "a torque periodic in the joint position (gear or motor ripple)",
    "drift": "friction changing over the run (warming up)",
}


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def _joints(js: list[str]) -> str:
    return ("Joint " if len(js) == 1 else "Joints ") + ", ".join(js)


def _verb(js: list[str], one: str, many: str) -> str:
    return one if len(js) == 1 else many


def _level_lines(res: dict, missed: list[int]) -> list[str]:
    """Per validation run, the friction level fricli's model is off by on the joints that miss their
    target (the residual's own Fv, Fc fitted on that run), with the controller's clock at the run's start."""
    if not missed:
        return []
    runs = res["validation_runs"]
    levels = {j: res["joints"][j]["fixed"]["run_levels"] for j in missed}
    head = " | ".join(f"joint {j}: ΔFv [Nm s/rad] | joint {j}: ΔFc [Nm]" for j in missed)
    rows = [f"| {name[3:]} | {levels[missed[0]][i]['start']:.0f} | "
            + " | ".join(f"{levels[j][i]['Fv']:+.3f} | {levels[j][i]['Fc']:+.3f}" for j in missed) + " |"
            for i, name in enumerate(runs)]
    said = []
    for j in missed:
        fv = np.array([lv["Fv"] for lv in levels[j]])
        scale = res["joints"][j]["linear_coef"][0]
        later = lower = 0
        for i, a in enumerate(runs):            # consecutive runs of one day, by the controller's clock
            same = sorted((levels[j][k]["start"], k) for k, b in enumerate(runs) if b[3:11] == a[3:11])
            if same and same[0][1] == i:
                for (_, k0), (_, k1) in zip(same, same[1:]):
                    later += 1
                    lower += bool(fv[k1] < fv[k0])
        said.append(f"- joint {j}: ΔFv above zero on {int(np.sum(fv > 0))} of {fv.size} runs, median "
                    f"{np.median(fv):+.3f} Nm s/rad ({100 * np.median(fv) / scale:+.0f} % of the fitting run's "
                    f"linear Fv, {scale:.3f}); of two runs of a day, the later one's lower in {lower} of {later} pairs.")
    return [
        "The level each validation run's friction differs by from fricli's model, in motion (ΔFv, ΔFc: the",
        "residual's own `Fv·qd + Fc·sign(qd) + offset` on that run), for the joints that miss their target;",
        "clock: the controller's time at the run's start [s] as the recording holds it.",
        "",
        f"| run | clock [s] | {head} |",
        "|---|---|" + "---|---|" * len(missed),
        *rows,
        "",
        *said,
        "",
        "The fitting day's friction is not the other days', and it moves within a day as well. Nothing in these",
        "recordings (they hold no joint temperature) tells a model fitted on one day the level of another.",
        "",
    ]


def render(res: dict, tab: dict, commands: list[str], full: bool) -> str:
    joints = res["joints"]
    means = tab["means"]
    head = [] if full else ["> **Partial run** (a subset of joints or validation runs): the figures below are "
                            "not the case study's. Run the script without options for the full study.", ""]
    missed = [j for j, ok in zip(joints, tab["met"]) if not ok]
    met_mean = means["fixed"] <= 0.66

    floor_rows = []
    for j, r in joints.items():
        lin = r["linear"]
        floor_rows.append(
            f"| {j} | {lin['moving']:.3f} | {lin['above_floor_moving']:.3f} "
            f"({lin['above_floor_moving'] / lin['moving']:.2f}×) | {_pct(lin['rest_share'])} | "
            f"{r['fixed']['moving']:.3f} | {r['fixed']['above_floor_moving']:.3f} |")

    own_rows, day, beyond = [], [], []
    for (j, r), target in zip(joints.items(), tab["targets"]):
        ratio, own = r["fixed"]["moving"] / r["linear"]["moving"], r["fixed"]["own_friction_moving"] / r["linear"]["moving"]
        own_rows.append(f"| {j} | {ratio:.3f} | {own:.3f} | {target:.3f} |")
        if ratio > target:
            (day if own <= target else beyond).append(str(j))
    own_text = " ".join(filter(None, [
        f"{_joints(day)} {_verb(day, 'misses', 'miss')} {_verb(day, 'its', 'their')} target and would meet it with "
        "each day's friction level known: what the error misses there is the change of friction between days, "
        "which only data of that day can tell (`fricli adapt`, below)." if day else "",
        f"{_joints(beyond)} {_verb(beyond, 'stays', 'stay')} above {_verb(beyond, 'its', 'their')} target even with "
        "each day's friction level known." if beyond else "",
        "Every joint meets its target." if not day and not beyond else ""]))

    level_lines = _level_lines(res, [int(j) for j in day + beyond])

    meaning_rows = []
    for j, r in joints.items():
        for name in r["diagnose"]["added"]:
            meaning_rows.append(f"- joint {j}, `{name}`: {MEANING.get(name, '')}.")

    ext = {j: joints[j]["payload"]["fixed"] / joints[j]["payload"]["linear"] for j in (2, 3) if j in joints}
    ext_idim = {j: joints[j]["payload"]["idim"] / joints[j]["payload"]["linear"] for j in (2, 3) if j in joints}
    ext_text = ", ".join(f"joint {j}: {v:.2f}× (IDIM-LS {ext_idim[j]:.2f}×)" for j, v in ext.items())
    ext_mean = sum(ext.values()) / len(ext) if ext else float("nan")
    limit = []
    if 3 in joints:
        p3 = joints[3]["payload"]
        extra = max(p3["fixed"] ** 2 - p3["fixed_unloaded"] ** 2, 0.0) ** 0.5
        measured = {j: joints[j]["payload"]["measured_ratio"] for j in (2, 3) if j in joints}
        measured_mean = sum(measured.values()) / len(measured)
        al = res["twin_alignment"]
        limit = [
            f"What limits joint 3, measured: fricli's error on the payload run is {p3['fixed']:.3f} Nm; on the unloaded",
            f"twin (the same trajectory without the payload) the same models leave {p3['fixed_unloaded']:.3f} Nm, so the",
            f"payload adds {extra:.3f} Nm (root of the difference of squares), and only {p3['fixed_above_floor']:.3f} Nm of the",
            "error lies above 2 Hz. That added error follows the reference itself: the estimate follows",
            f"{_pct(1 + p3['fixed_gain'])} of it (least-squares slope).",
            "",
            "What limits it is the reference, not the model. The two runs follow the same trajectory: shifted",
            f"by {al['shift']:.4f} s, their joint positions agree to {al['q_rms']:.1e} rad RMS. The unloaded twin's `tau_m`",
            "minus the payload run's is then the payload's torque as each joint measured it, with no model at",
            "all (plus the load's change of friction and both runs' noise). Scored like the models, against",
            "the point-mass reference and on the rows both runs cover, this measured torque gives "
            + ", ".join(f"joint {j} {v:.2f}×" for j, v in measured.items()) + f" (mean {measured_mean:.3f}; last column):",
            f"on joint 3 it follows {_pct(1 + p3['measured_gain'])} of the reference, as fricli's estimate does.",
            "An estimate exact to the torque the joints carry, in the units of `tau_m`, scores about that: no",
            "model of the unloaded arm meets the target line against this reference. The next section",
            "identifies the payload the joints carry.",
        ]
    seen = []
    if res.get("payload_seen") and all("payload_seen" in joints[j] for j in joints):
        ps = res["payload_seen"]
        com = ", ".join(f"{c:.3f}" for c in ps["com"])
        err = ", ".join(f"{c:.2g}" for c in ps["stderr"]["com"])
        rows = []
        for j, r in joints.items():
            p = r["payload_seen"]
            rows.append(f"| {j} | {p['reference_rms']:.2f} | {p['linear']:.3f} | {p['idim']:.3f} | {p['fixed']:.3f} | "
                        f"{p['idim'] / p['linear']:.2f} | **{p['fixed'] / p['linear']:.2f}** | {r['payload']['fixed_unloaded']:.3f} | "
                        f"{p['measured_ratio']:.2f} |")
        seen_ext = {j: joints[j]["payload_seen"]["fixed"] / joints[j]["payload_seen"]["linear"] for j in (2, 3) if j in joints}
        seen_mean = sum(seen_ext.values()) / len(seen_ext) if seen_ext else float("nan")
        six = joints.get(6, {}).get("payload_seen")
        seen = [
            "### The payload the joints carry",
            "",
            "`fricli payload load.parquet --frame tool0 --until 50%` fits a point mass and its centre of mass",
            "at `tool0` to what the calibrated robot model and each joint's linear friction leave of `tau_m`",
            f"on the first half of the payload run ({ps['rows']:,} rows). The joints carry **{ps['mass']:.3f} kg**",
            f"(standard error {ps['stderr']['mass']:.2g}) at **({com}) m** in `tool0`'s frame (standard errors {err}):",
            "not a point at the flange. A mass on the flange's axis exerts no torque on joint 6"
            + (f", which carries {six['reference_rms']:.2f} Nm RMS of this one" if six else "") + ";",
            "the assumed reference above misses that on every wrist joint and part of it on joint 3.",
            "",
            "Declared at import as identified (`--payload-mass ... --payload-com ... --payload-frame tool0`,",
            "the line `fricli payload` prints), with the same models fitted on the unloaded twin, the external",
            "torque on the second half of the run (rows the payload was not identified on), against that",
            "payload's torque:",
            "",
            "| joint | payload torque (RMS) [Nm] | linear error [Nm] | IDIM-LS error | fricli error | IDIM-LS / linear | "
            "fricli / linear | fricli on the unloaded twin | measured difference / linear |",
            "|---|---|---|---|---|---|---|---|---|", *rows,
            "",
            "Joints 2 and 3: " + ", ".join(f"joint {j} {v:.2f}×" for j, v in seen_ext.items())
            + f", mean {seen_mean:.3f} (at most 0.65: {'met' if seen_mean <= 0.65 else 'not met'}). The reference",
            "here is itself identified from the same recording's other half with the calibrated robot model, so",
            "it favours the calibrated models; with the point-mass assumption above the figure is the one of the",
            "target line. The measured difference of the two runs (last column), which uses no model, checks it:",
            "against this payload it scores "
            + ", ".join(f"joint {j} {joints[j]['payload_seen']['measured_ratio']:.2f}×" for j in (2, 3) if j in joints)
            + ", against the point mass above "
            + ", ".join(f"joint {j} {joints[j]['payload']['measured_ratio']:.2f}×" for j in (2, 3) if j in joints) + ".",
            "What limits joint 3 is the payload's unknown centre of mass, measured, not the friction",
            "model: once the payload is known, fricli's error on joint 3"
            + (f" ({joints[3]['payload_seen']['fixed']:.3f} Nm) is close to what the same models leave on the unloaded"
               f" twin ({joints[3]['payload']['fixed_unloaded']:.3f} Nm)" if 3 in joints else "")
            + "; on the other joints part of the payload's effect remains.",
        ]

    cal = res["calibration"]
    suspicious = [f"- {line}" for line in cal["suspicious"]] or ["- none"]
    robot_line = (res.get("robot_model") or {}).get("summary", "")
    adapt = []
    if tab.get("adapt"):
        adapt = [
            "## Same-day adaptation",
            "",
            "For each day with two runs, `fricli adapt fixed RUN.parquet -o adapted` (the fixed models as the",
            "base, a residual network trained on one run of the day, both runs imported with the calibrated",
            "URDF) is scored on the other run of the same day, against the fixed models there: RMS over the",
            "rows in motion [Nm], base → adapted. `adapt` keeps the base when its held-out rows do not show",
            "the residual helping (\"base kept\"); the pairs are those of `benchmarks/ur10e_neural.py`.",
            "",
            tab["adapt"],
            "",
        ]
    cmd_list = "\n".join(f"fricli {c}" for c in commands)
    v_runs = ", ".join(f"`{n}`" for n in res["validation_runs"])
    cols = ", ".join(f"{label.strip('*')} with the {urdf} URDF" for label, urdf in
                     (("published Fv, Fc, offset", "CAD"), ("LuGre", "CAD"), ("identify + diagnose --fix", "CAD")))

    return "\n".join(head + [
        "# Case study: the robot model and the friction of a UR10e arm from its own recordings",
        "",
        "This document is written by `python studies/ur10e/run_case_study.py` (about 70 s on 2 cores; data at",
        "`../shared/data/ur10e`, see `../shared/data/README.md`). Every figure below comes from that run;",
        "the full list of fricli commands it ran is at the end, the numbers are also in",
        "`docs/studies/ur10e-results.json`.",
        "",
        "The recordings: a Universal Robots UR10e in velocity control along optimised excitation",
        "trajectories (sums of harmonics below 1 Hz), about 100 Hz, joint positions, velocities and motor",
        "currents (the dynamic-calibration dataset of Innopolis University). The robot description:",
        "the manufacturer's URDF with CAD masses. Drive gains and reflected rotor inertias: the dataset",
        "authors' estimates, in `docs/ur10e-mapping.toml`.",
        "",
        "On a real arm the largest error is often not friction but the robot model: CAD masses and centres",
        "of mass, and rotor inertia the URDF does not hold. fricli corrects it where it lives, in the URDF",
        "([calibration.md](../calibration.md)), and then models each joint's friction on the corrected",
        "torques.",
        "",
        "## Protocol",
        "",
        "The fitting and validation runs were chosen before any validation figure was computed; no",
        "option below was tuned on the validation runs.",
        "",
        f"- **Fitting run**: `{res['fit_run']}` (19 Feb 2020), the longest unloaded run, and the unloaded",
        "  twin of the payload run. Nothing else is used for fitting: not the friction, not the robot model.",
        f"- **Validation runs**: every identification run recorded on another day: {v_runs}.",
        "- **Error**: RMS of `tau_m − tau_g − tau_dyn − tau_f_pred` pooled over the validation runs, per",
        "  joint, over the rows in motion (|qd| above 2 % of the run's top speed, as `fricli evaluate` counts",
        "  them; at rest friction is statically indeterminate). `tau_g` and `tau_dyn` come from the URDF the",
        "  model uses (the CAD one or the calibrated one), so this is the error of the whole model of the",
        "  measured torque, comparable across robot models.",
        "- **Baseline**: the CAD URDF with the standard model `Fv·qd + Fc·sign(qd) + offset`, fitted by least",
        "  squares on the fitting run. Ratios below are to its error.",
        "- **Floor**: the part of the baseline's error above 2 Hz (zero-phase high-pass): the excitation lies",
        "  below 1 Hz, so no model of the state (q, qd, qdd, tau_g) follows it.",
        "- **Target** per joint: halfway between the CAD path's ratio (identify + diagnose --fix with the",
        "  CAD URDF) and the floor; for joint 2 also at most IDIM-LS's ratio; the mean at most 0.66.",
        "- `tau_dyn` uses `qdd` from the measured velocity, low-passed at 10 Hz (zero phase) and",
        "  differentiated: ten times the excitation's bandwidth, a fifth of the Nyquist frequency.",
        "",
        "## From CSV and URDF to calibrated dynamics and friction: three commands",
        "",
        "```sh",
        "fricli import ur-20_02_19_14harm50sec.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf --cutoff 10 -o fit.parquet",
        "fricli identify fit.parquet -o lugre",
        "fricli diagnose lugre fit.parquet --fix --calibrate ur10e-cal.urdf -o fixed",
        "```",
        "",
        "`import` writes one long-format log of the six joints with `tau_g` and `tau_dyn` from the CAD URDF.",
        "`identify` fits the extended LuGre model of every joint. `diagnose` finds what each model lacks",
        "(held-out over ten blocks of time); the gravity and inertia errors of several joints are the robot",
        "model's, so `--calibrate` identifies the robot model (masses, centres of mass, inertias, armature",
        f"and {res['calibration']['friction']['kind']} friction together, with a prior at CAD, as `fricli calibrate "
        f"--friction {res['calibration']['friction']['kind']}`), writes",
        "`ur10e-cal.urdf`, recomputes `tau_g` and `tau_dyn` from it, refits each joint's LuGre model on",
        "the recomputed torques and diagnoses and fixes them there (`fixed/joint_1.npz` ... `joint_6.npz`).",
        "Other runs are imported with the calibrated URDF (`fricli import RUN.csv ... --urdf",
        "ur10e-cal.urdf`) and predicted with `fricli predict fixed RUN.parquet -o PRED.parquet`; the script computes the",
        "same prediction in-process (`fricli.models`, the code `predict` runs).",
        "",
        "What `diagnose --fix --calibrate` reports on the fitting run (the robot-model errors it found",
        "with the CAD URDF, what the calibration changed in-sample, and the held-out MAE before and after):",
        "",
        "```text",
        robot_line,
        "```",
        "",
        "## Error on runs of other days",
        "",
        "Ratio to the baseline's error, in motion. Columns: " + cols + "; IDIM-LS: `fricli calibrate --friction",
        "linear` alone (its calibrated URDF with the linear friction it identifies with it); GMS: `identify",
        "--kind gms` (the Generalized Maxwell-slip model, friction with memory: docs/gms.md) on the fitting run",
        "imported with the CAD URDF, beside the LuGre model of the same import; LuGre with the",
        "calibrated URDF (`identify` on the fitting run imported with the closed loop's URDF); fricli: the",
        "three commands above.",
        "",
        tab["friction"],
        "",
        "![error ratio per joint](img/ur10e-friction-ratio.png)",
        "",
        f"**Targets**: the mean ratio is **{means['fixed']:.3f}** (target 0.66: {'met' if met_mean else 'not met'});",
        ("every joint meets its target." if not missed else
         f"joint{'s' if len(missed) > 1 else ''} {', '.join(str(j) for j in missed)} "
         f"{'miss' if len(missed) > 1 else 'misses'} {'their' if len(missed) > 1 else 'its'} target (column *met*)."),
        f"IDIM-LS alone averages {means['idim']:.2f}, the CAD path {means['fixed_cad']:.2f}: the calibration",
        "removes the robot-model error on the large joints, the LuGre models and diagnose the friction",
        "error the linear law leaves on every joint.",
        "",
        "### What limits the figure: noise, measured",
        "",
        "| joint | baseline, in motion [Nm] | of which above 2 Hz | rows at rest | fricli, in motion | of which above 2 Hz |",
        "|---|---|---|---|---|---|",
        *floor_rows,
        "",
        "Whatever the error holds above 2 Hz is no friction a model of the state can follow: current noise,",
        "the velocity controller's own corrections, gear ripple. On the wrists it is most of the error.",
        "",
        "### What limits the figure: each day's friction, measured",
        "",
        "The friction of a joint changes from day to day (temperature, lubricant), and a model fitted on one",
        "day cannot know another's. How much of the error that is: each validation run's residual with its",
        "own `Fv·qd + Fc·sign(qd) + offset` added, fitted by least squares on that run's rows in motion",
        "(knowledge of the run being scored, which no model fitted on another day has), pooled as above.",
        "",
        "| joint | fricli | with each run's own friction level | target |",
        "|---|---|---|---|",
        *own_rows,
        "",
        own_text,
        "",
        *level_lines,
        "## What diagnose finds, per joint",
        "",
        tab["diagnose"],
        "",
        "Effects marked implausible were chosen with parameters beyond ±30 % (a gravity scale, an inertia):",
        "they are held back as suspicions, since a drive gain, a cable or a counterbalance spring would do",
        "the same; the calibration's own report flags such changes the same way (below).",
        "",
        "What the added effects mean:",
        "",
        *(meaning_rows or ["- nothing was added after the calibration."]),
        "",
        "## The calibrated robot model next to the CAD one",
        "",
        *_prior_lines(cal),
        "The fitting run",
        f"determines {cal['excitation']['base_parameters']} base parameters of {cal['excitation']['parameters']},"
        f" {len(cal['excitation']['undetermined'])} directions stay near CAD.",
        "",
        tab["parameters"],
        "",
        "Changes the calibration flags (beyond ±30 % of CAD or of the prior armature), with the other causes",
        "that fit the same data, or what the data do not determine:",
        "",
        *suspicious,
        "",
        "The dataset lists a reflected rotor inertia of 0 for joints 1 and 3, which a geared motor cannot",
        "have; the calibration finds one. A body's mass is rarely what the joint torques see of it: masses",
        "of bodies that the same joints carry trade against each other and against their first moments,",
        "so the table's masses are the prior's split of what the data determine together (the report's",
        "`excitation.masses_not_determined_alone`), and the torques of the calibrated model are what to trust.",
        "",
        "## External torque of the 2.805 kg payload run",
        "",
        "`ur-20_02_19_14harm50secLoad.csv` repeats the fitting run's trajectory with 2.805 kg at the",
        "flange. The models are those fitted on the unloaded twin (the fitting run). The payload enters",
        "as a controller knows it: declared at import (`--payload-mass 2.805 --payload-com 0 0 0",
        "--payload-frame tool0` with the calibrated URDF), so `tau_g` holds it and the LuGre models' load",
        "terms see it; `fricli estimate-ext fixed/joint_J.npz load.parquet --joint J -o EXT.parquet` then estimates what",
        "is left, which should be nothing. Its error against the reference, and the estimate of the",
        "payload torque it implies (the declared payload's torque plus what is left), are what the table",
        "gives. Reference: the payload's torque from the URDF with the payload added, as the difference of",
        "two imports' `tau_g + tau_dyn` (**assumption**: a point mass at the `tool0` origin; the centre",
        "of mass is not published). The linear model (CAD URDF, no payload declared; its friction does not",
        "depend on the load, so declaring it changes nothing for it) estimates",
        "`tau_g + tau_dyn + f_linear − tau_m`.",
        "",
        tab["external"],
        "",
        "![payload external torque](img/ur10e-payload.png)",
        "",
        f"**Target** (at most 0.65× the linear model's error on average over joints 2 and 3): {ext_text};"
        f" mean {ext_mean:.3f}: {'met' if ext_mean <= 0.65 else 'not met'}.",
        "",
        *limit,
        "",
        *seen,
        "",
        *adapt,
        "## The dataset authors' published parameters",
        "",
        "The published `Fv, Fc, offset` give about the same error as the least-squares fit on the fitting",
        "run with the CAD URDF. They were identified jointly with the authors' own rigid-body parameters,",
        "so on the CAD model's torques they carry its gravity and inertia errors; the comparison shows",
        "that the linear law leaves the same error on other days with either set, not how good the",
        "authors' whole model is.",
        "",
        "## Commands run",
        "",
        "`DATA` is the recordings' folder, `WORK` the script's working folder (`--work`).",
        "",
        "```",
        cmd_list,
        "```",
        "",
    ])


def _prior_lines(cal: dict) -> list[str]:
    """How strong the calibration's prior at CAD was and how it was chosen ([calibration.md])."""
    choice = cal.get("prior_choice")
    if not choice:
        return [f"Prior: {cal['prior']:g} times each parameter's scale ([calibration.md](../calibration.md)).", ""]
    held = ", ".join(f"{k}: {v:.4f}" for k, v in sorted(choice["held_out_rms"].items(), key=lambda kv: float(kv[0])))
    lines = [f"Prior: chosen by {choice['folds']}-fold cross-validation over blocks of time of the fitting run",
             "(`--prior auto`, [calibration.md](../calibration.md)); nothing of the validation runs enters it. One",
             f"strength for all parameters: **{choice['chosen']:g}** times each parameter's scale (held-out",
             f"weighted RMS per strength, 1 = the noise level: {held})."]
    if choice.get("per_group"):
        per = ", ".join(f"{b} {v:g}" for b, v in choice["per_group"].items())
        lines += [f"Then each body's inertial parameters and each joint's armature on their own: {per}",
                  f"(held-out weighted RMS {choice['held_out_rms_per_group']:.4f})."]
    return lines + [""]
