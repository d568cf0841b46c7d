"""The words of docs/case-study-ur10e.md around the figures that run_case_study.py computes."""

from __future__ import annotations

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


def render(res: dict, tab: dict, commands: list[str], full: bool) -> str:
    joints = res["joints"]
    ratios = tab["ratios"]
    mean_all, mean_mov = tab["mean_all"], tab["mean_moving"]
    worst_all = max(zip(ratios["all"], joints), key=lambda p: p[0])
    met_mean, met_each = mean_all <= 0.70, worst_all[0] <= 0.85
    ext = {j: joints[j]["payload"]["fixed"] / joints[j]["payload"]["linear"] for j in (2, 3) if j in joints}
    head = [] if full else ["> **Partial run** (a subset of joints or validation runs): the figures below are "
                            "not the case study's. Run the script without options for the full study.", ""]

    floor_rows = []
    for j, r in joints.items():
        lin = r["linear"]
        floor_rows.append(
            f"| {j} | {lin['all']:.3f} | {lin['above_floor']:.3f} ({lin['above_floor'] / lin['all']:.2f}×) | "
            f"{_pct(lin['rest_share'])} | {lin['moving']:.3f} | {lin['above_floor_moving']:.3f} "
            f"({lin['above_floor_moving'] / lin['moving']:.2f}×) |")

    meaning_rows = []
    for j, r in joints.items():
        for name in r["diagnose"]["added"]:
            meaning_rows.append(f"- joint {j}, `{name}`: {MEANING.get(name, '')}.")

    short = [f"joint {j} ({ra:.2f}×)" for ra, j in zip(ratios["all"], joints) if ra > 0.85]
    ext_text = ", ".join(f"joint {j}: {v:.2f}×" for j, v in ext.items())
    cmd_list = "\n".join(f"fricli {c}" for c in commands)
    v_runs = ", ".join(f"`{n}`" for n in res["validation_runs"])

    return "\n".join(head + [
        "# Case study: friction models for a UR10e arm from its own recordings",
        "",
        "This document is written by `python docs/ur10e/run_case_study.py` (a few minutes; data at",
        "`../shared/data/ur10e`, see `../shared/data/README.md`). Every figure below comes from that run;",
        "the full list of fricli commands it ran is at the end, the numbers are also in",
        "`docs/ur10e-results.json`.",
        "",
        "The recordings: a Universal Robots UR10e in velocity control along optimised excitation",
        "trajectories (sums of harmonics below 1 Hz), about 100 Hz, joint positions, velocities and motor",
        "currents (the dynamic-calibration dataset of Innopolis University). The robot description:",
        "the manufacturer's URDF with CAD masses. Drive gains and reflected rotor inertias: the dataset",
        "authors' estimates, in `docs/ur10e-mapping.toml`.",
        "",
        "## Protocol",
        "",
        "The fitting and validation runs were chosen before any validation figure was computed; no",
        "option below was tuned on the validation runs.",
        "",
        f"- **Fitting run**: `{res['fit_run']}` (19 Feb 2020), the longest unloaded run, and the unloaded",
        "  twin of the payload run. Nothing else is used for fitting.",
        f"- **Validation runs**: every identification run recorded on another day: {v_runs}.",
        "- **Friction error**: RMS of `tau_m - tau_g - tau_dyn - tau_f_pred` (the friction target of the",
        "  [log contract](log-format.md)) pooled over the validation runs, per joint: over all rows, and over",
        "  the rows in motion (|qd| above 2 % of the run's top speed, as `fricli evaluate` counts them). At rest",
        "  friction is statically indeterminate: stiction holds whatever torque the controller left.",
        "- **Baseline**: the standard model `Fv·qd + Fc·sign(qd) + offset`, fitted by least squares on the",
        "  same target of the same fitting run.",
        "- **Published parameters**: the dataset authors' `Fv, Fc, offset` per joint (see below for what that",
        "  comparison can show).",
        "- `tau_dyn` uses `qdd` from the measured velocity, low-passed at 10 Hz (zero phase) and",
        "  differentiated: ten times the excitation's bandwidth, a fifth of the Nyquist frequency (the",
        "  default of 50 Hz would leave this 100 Hz recording unfiltered).",
        "",
        "## From CSV and URDF to six models: three commands",
        "",
        "```sh",
        "fricli import ur-20_02_19_14harm50sec.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf --cutoff 10 -o fit.parquet",
        "fricli identify fit.parquet -o lugre",
        "fricli diagnose lugre fit.parquet --fix -o fixed",
        "```",
        "",
        "`import` writes one long-format log of the six joints with `tau_g` and `tau_dyn` from the URDF.",
        "`identify` fits the extended LuGre model of every joint (`lugre/joint_1.npz` ... `joint_6.npz`);",
        "`diagnose --fix` finds what each model lacks on the same run (held-out over ten blocks of time),",
        "adds it and writes the fixed models to `fixed/` ([joints.md](joints.md)). Validation runs are",
        "imported the same way; a user predicts them with `fricli predict fixed RUN.parquet -o pred.parquet`,",
        "the script computes the same prediction in-process (`fricli.models`, the code `predict` runs).",
        "",
        "## Friction error on runs of other days",
        "",
        "RMS error [Nm]; ratio = fricli (identify + diagnose --fix) / linear model.",
        "",
        tab["friction"],
        "",
        "![friction error ratio per joint](img/ur10e-friction-ratio.png)",
        "",
        f"**Targets** (at most 0.70× the linear model's error on average over the joints, at most 0.85× on",
        f"every joint): the mean ratio is **{mean_all:.2f}** over all rows ({mean_mov:.2f} in motion): "
        f"{'met' if met_mean else 'not met'}; the worst joint is joint {worst_all[1]} at {worst_all[0]:.2f}×: "
        f"{'met' if met_each else 'not met'}" + (f" ({', '.join(short)} above 0.85×)." if short else "."),
        "",
        "### What limits the figure: noise and standstill, measured",
        "",
        "The excitation lies below 1 Hz, so whatever the linear model's error holds above 2 Hz is no friction",
        "that a model of the state (q, qd, qdd, tau_g) can follow: current noise, the velocity controller's",
        "own corrections, gear ripple. The table gives that part (zero-phase high-pass at 2 Hz of the",
        "linear model's error on the validation runs) and the share of rows at rest:",
        "",
        "| joint | linear model, all rows [Nm] | of which above 2 Hz | rows at rest | linear model, in motion | of which above 2 Hz |",
        "|---|---|---|---|---|---|",
        *floor_rows,
        "",
        "The ratio in brackets is the floor a perfect low-frequency model would reach against the linear",
        "model. Where it is close to or above 0.85× (the wrists in motion), no friction model can meet the",
        "per-joint target on this measure; over all rows the standstill rows weigh in, where the torque a",
        "held gear carries depends on how it came to rest and cannot be predicted from the state alone.",
        "",
        "## What diagnose finds, per joint",
        "",
        tab["diagnose"],
        "",
        "The gravity column gives the `gravity` candidate's estimate on every joint where the log's",
        "`tau_g` varies; only an *added* one is a finding. A figure that was not added is a least-squares",
        "slope on a small or nearly constant `tau_g` (the wrists carry a fraction of a newton-metre of",
        "gravity torque) and says nothing about the masses. Joint 1 turns about the vertical base axis and",
        "the URDF puts the last link's centre of mass on joint 6's axis, so both have no gravity torque",
        "and the candidate is not tested there.",
        "",
        "What the added effects mean:",
        "",
        *meaning_rows,
        "",
        "The largest corrections are not friction at all but errors of the robot model that the friction",
        "target holds: a gravity torque off by several per cent (the CAD masses) and inertia missing from",
        "`tau_dyn` (the dataset lists a reflected rotor inertia of 0 for joints 1 and 3, which a geared",
        "motor cannot have). `diagnose` reports them as robot-model errors and `--fix` corrects them in",
        "the model, apart from the friction terms. The linear model cannot absorb them: a gravity error",
        "depends on the pose, an inertia on the acceleration. This is why fricli's models beat the linear",
        "model most on joints 1 to 3, which carry the large masses and inertias.",
        "",
        "## The dataset authors' published parameters",
        "",
        "The published `Fv, Fc, offset` (column *published* above) give almost the same error as the",
        "least-squares fit on the fitting run: the friction levels agree (for example joint 1:",
        f"Fv {joints[1]['linear_coef'][0]:.2f} Nm s/rad and Fc {joints[1]['linear_coef'][1]:.2f} Nm fitted here, 21.26 and 12.55 published)."
        if 1 in joints else "least-squares fit on the fitting run.",
        "What this comparison can show: that the linear friction law, with either set of parameters,",
        "leaves the same error on other days, so the gain comes from what fricli adds, not from a better",
        "fit of the same law. What it cannot show: how good the authors' whole model is. They identified",
        "friction jointly with their own rigid-body parameters, so their friction parameters complement",
        "their inertial parameters, not the URDF's CAD values used here; on this target they are charged",
        "with the CAD model's gravity and inertia errors that their own model did not have.",
        "",
        "## External torque of the 2.805 kg payload run",
        "",
        "`ur-20_02_19_14harm50secLoad.csv` repeats the fitting run's trajectory with 2.805 kg at the",
        "flange. The models fitted on the unloaded twin estimate the external torque",
        "(`fricli estimate-ext fixed/joint_J.npz load.parquet --joint J`, the run imported without the",
        "payload); the reference is the payload's torque from the URDF with the payload added",
        "(`fricli import ... --payload-mass 2.805 --payload-com 0 0 0 --payload-frame tool0`), as the",
        "difference of the two imports' `tau_g + tau_dyn`. **Assumption**: the centre of mass at the",
        "flange (the `tool0` origin) as a point mass; it is not published (\"close to the flange\"). The",
        "linear model's estimate is `tau_g + tau_dyn + f_linear - tau_m` with the same logs.",
        "",
        tab["external"],
        "",
        "![payload external torque](img/ur10e-payload.png)",
        "",
        f"**Target** (at most 0.80× the linear model's error on joints 2 and 3): {ext_text}"
        + "; " + ", ".join(f"joint {j} {'met' if v <= 0.80 else 'not met'}" for j, v in ext.items()) + ".",
        "The last two columns give the least-squares share of the reference torque each estimate",
        "follows. Where both fall short of 100 % by a similar amount, the gap is common to both models",
        "(payload centre of mass, the drive gain, friction that grows with the payload's load) and no",
        "friction model fitted without the payload removes it.",
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

