"""fricli identify: fit the extended LuGre model to a log."""

from __future__ import annotations

import os

import click

from fricli import errors, models
from fricli.cli import cli
from fricli.cli.options import (common, emit_results, fit_joints, if_changed_option, json_flag, log_reading,
                                model_job, output_option, reading_kwargs, say)
from fricli.errors import OutputError
from fricli.identify import LuGreIdentifier
from fricli.models.lugre import PARAM_INFO, unit_of


def _figures(errs: dict, unit: str) -> str:
    return f"MAE {errs['mae']:.4g} {unit}, RMSE {errs['rmse']:.4g} {unit}, max {errs['max']:.4g} {unit}"


@cli.command("identify")
@click.argument("log")
@output_option(help="Model file to write (.npz), or a folder for one model per joint (docs/joints.md).")
@log_reading
@click.option("--hold", type=click.FloatRange(min=0, min_open=True), default=0.2, show_default=True,
              help="Steady state: the velocity must have been constant for at least this long [s].")
@click.option("--travel", type=click.FloatRange(min=0), default=0.002, show_default=True,
              help="Steady state: ... and over at least this distance [rad or m] (longer holds at slow speeds).")
@click.option("--samples", type=click.Choice(["auto", "steady", "settled"]), default="auto", show_default=True,
              help="Rows for the static curve: constant-velocity holds, every row --settle past a reversal "
                   "(continuous excitation), or settled when holds cover under half of the motion and the log has tau_dyn.")
@click.option("--settle", type=click.FloatRange(min=0), default=0.01, show_default=True,
              help="Settled rows: travel since the last velocity reversal [rad or m].")
@click.option("--refine", is_flag=True, help="Finally fit all parameters jointly on the whole log.")
@click.option("--kind", type=click.Choice(["lugre", "linear", "linear-asymmetric"]), default="lugre", show_default=True,
              help="lugre, or the linear model Fv*qd + Fc*sign(qd) + offset (linear-asymmetric: Fv, Fc per "
                   "direction) fitted by least squares on the rows in motion (docs/tutorial.md).")
@click.option("--coupling", is_flag=True,
              help="Fit each group of joints that share motors (the log's transmission, docs/drives.md) as one "
                   "model of friction per motor (kind coupled); the other joints as before.")
@click.option("--motor-stribeck", is_flag=True,
              help="With --coupling: each motor's friction with the Stribeck curve (fs, vs) as well.")
@if_changed_option
@json_flag
@common
def identify_cmd(log: str, output: str, joint, kt, cutoff, drop_invalid, hold: float, travel: float,
                 samples: str, settle: float, refine: bool, kind: str, coupling: bool, motor_stribeck: bool,
                 if_changed: bool, as_json: bool, quiet: bool) -> None:
    """Fit the extended LuGre friction model to LOG (- for stdin) and write it to a model file.

    Static parameters (Fc, Fs, vs, delta, Fv and the load slopes kc, ks) are fitted on the
    steady-state samples, then the bristle parameters sigma0, sigma1 by simulating the whole
    log (see docs/lugre.md). With --kind linear, the model Fv*qd + Fc*sign(qd) + offset by least
    squares on the rows in motion instead. Parameters and fit errors go to stderr, or as JSON to stdout with
    --json. On failure the previous model file is left untouched.

    A log of several joints without --joint gives one model per joint in the folder -o DIR
    (DIR/joint_<name>.npz; docs/joints.md).

    \b
    Example:
      fricli identify sample_data/joint2_base.parquet -o lugre.npz
      fricli identify emps.parquet -o emps.npz --cutoff 100 --json
      fricli identify nightly.parquet -o lugre.npz --if-changed   # cron: exit 9 (UNCHANGED) when up to date
      fricli identify arm.parquet -o lugre-arm/                    # every joint of the arm
    """
    if output == "-":
        raise click.UsageError("identify writes a model file: give -o FILE.npz (or a folder), not -")
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):
        raise OutputError(f"cannot write {output}: folder {folder} does not exist")

    def fit_one(data, out, job, _model):
        if kind != "lugre":
            return _fit_linear(data, out, job, kind == "linear-asymmetric", quiet)
        idf = LuGreIdentifier(hold=hold, travel=travel, refine=refine, samples=samples,
                              settle=settle).fit(data.signals, units=data.units,
                                                                           axis=data.axis)
        model, fit = idf.model_, idf.fit_
        models.save_for_log(out, model, data, rows_used=len(data), fit=fit, job=job)
        _report(data, model, fit, out, quiet)
        params = model.parameters()
        return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis,
                "units": data.units, "parameters": params,
                "parameter_units": {k: unit_of(k, data.axis) for k in params}, "fit": fit}

    if motor_stribeck and not coupling:
        raise click.UsageError("--motor-stribeck applies to --coupling")
    reading = reading_kwargs(joint, kt, cutoff, drop_invalid)
    if coupling:
        results, folder_run = _fit_coupled(log, output, joint, reading, fit_one, if_changed=if_changed, quiet=quiet,
                                           stribeck=motor_stribeck)
    else:
        results, folder_run = fit_joints(log, output, joint, reading, fit_one, if_changed=if_changed, quiet=quiet)
    if as_json:
        emit_results(results, folder_run)


def _fit_linear(data, out, job, asymmetric: bool, quiet: bool) -> dict:
    from fricli.models import linear

    model, fit = linear.fit(data.signals, asymmetric=asymmetric, axis=data.axis)
    models.save_for_log(out, model, data, rows_used=fit["moving"]["n"], fit=fit, job=job)
    unit, params = data.units["tau"], model.parameters()
    say(f"{model.describe()}\nfit error, all rows: {_figures(fit, unit)}\n"
        f"fit error, {fit['moving_rows']:,} rows in motion: {_figures(fit['moving'], unit)}\nwrote {out}", quiet)
    return {"model": out, "log": data.name, "joint": data.joint, "axis": data.axis, "units": data.units,
            "parameters": params, "parameter_units": {k: linear.unit_of(k, data.axis) for k in params}, "fit": fit}


def _report(data, model, fit, output, quiet) -> None:
    if quiet:
        return
    unit = data.units["tau"]
    where = f"joint {data.joint}, " if data.joint is not None else ""
    say(f"identified the extended LuGre model on {data.name} ({where}{len(data):,} rows, "
        f"{fit['steady_rows']:,} steady-state)")
    for name, value in model.parameters().items():
        say(f"  {name:<7} {value:>12.6g} {unit_of(name, data.axis):<9} {PARAM_INFO[name][2]}")
    say(f"fit error, all rows:          {_figures(fit, unit)}")
    say(f"fit error, steady-state rows: {_figures(fit['steady'], unit)}")
    for note in fit["notes"]:
        say(f"note: {note}")
    say(f"wrote {output}")


def _fit_coupled(log: str, output: str, joint, reading: dict, fit_one, *, if_changed: bool,
                 quiet: bool, stribeck: bool = False) -> tuple[dict, bool]:
    """``fit_joints`` for identify --coupling: a joint of a coupled group of the log's transmission
    brings its whole group into one model (DIR/joints_<a>_<b>.npz); the other joints get theirs."""
    from fricli import joints, logs, modelset
    from fricli.errors import LogError
    from fricli.models import coupled
    from fricli.robot import transmission

    table, digest = logs.read_table(log)
    name = "stdin" if log == "-" else log
    logs.require_robot_model(table.schema, name, reading.get("zero", ()))
    try:
        tr = transmission.of_schema(table.schema.metadata)
    except ValueError as exc:
        raise LogError(f"{name}: {exc}") from None
    if tr is None:
        raise LogError(f"{name}: --coupling needs the log's transmission (written by fricli import from a mapping "
                       "with a transmission, docs/drives.md); the log records none")
    log_joints = logs.joints_of(table, name)
    covered = joints.select(log_joints, joint, name)
    groups = [tr.sub(g) for g in tr.coupled_groups()]
    units, seen = [], set()
    for j in covered:
        group = next((g for g in groups if any(joints.same(j, x) for x in g.joints)), None)
        key = tuple(map(str, group.joints)) if group else (str(j),)
        if key not in seen:
            seen.add(key)
            units.append((j, group))
    labels = {j: (", ".join(map(str, g.joints)) if g else j) for j, g in units}
    folder = modelset.output_folder(output, [j for j, _ in units], log_joints, name)   # a group alone: one file
    reading = {k: v for k, v in reading.items() if k != "joint"}
    results: dict = {}

    def work(label):
        j, group = next(u for u in units if labels[u[0]] == label)
        if group is None:
            data = logs.from_table(table, name=name, sha256=digest, joint=j, **reading)
            out = modelset.path_for(folder, j) if folder else output
            with model_job(out, data, if_changed=if_changed, quiet=quiet, exit_unchanged=folder is None) as job:
                if job is not None:
                    results[j] = fit_one(data, out, job, None)
            return
        missing = [x for x in group.joints if not any(joints.same(x, y) for y in log_joints)]
        if missing:
            raise LogError(f"{name}: joint {j} shares motors with joints {joints.listed(missing)}, which the log "
                           "does not hold: the coupled group needs every joint's rows")
        _, datas = coupled.group_rows(table, list(group.joints), name, sha256=digest, **reading)
        out = os.path.join(folder, modelset.group_file_name(group.joints)) if folder else output
        with model_job(out, datas[0], if_changed=if_changed, quiet=quiet, exit_unchanged=folder is None) as job:
            if job is not None:
                model, fit = coupled.fit_group(datas, group, stribeck=stribeck)
                coupled.save_group(out, model, datas[0], fit=fit, job=job)
                if not quiet:
                    unit = datas[0].units["tau"]
                    say(f"identified the coupled friction of joints {labels[j]} on {name} ({len(datas[0]):,} rows "
                        "per joint), per motor:")
                    say("\n".join(model.describe().splitlines()[1:]))
                    for x, errs in fit["joints"].items():
                        say(f"fit error, joint {x}: {_figures(errs, unit)}")
                    say(f"wrote {out}")
                results[labels[j]] = {"model": out, "log": name, "joints": list(group.joints), "kind": "coupled",
                                      "parameters": {k: getattr(model, k).tolist() for k in model.names()},
                                      "ratio": model.ratio.tolist(), "fit": fit}

    modelset.each_joint([labels[j] for j, _ in units], work)
    if folder and not results:
        click.get_current_context().exit(errors.UNCHANGED)
    return results, folder is not None
