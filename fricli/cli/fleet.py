"""fricli fleet, fricli trend."""

from __future__ import annotations


import click

from fricli.core import errors
from fricli.cli import cli
from fricli.cli.options import Number, common, emit_json, json_flag, progress_enabled, say, warn


@cli.command("fleet")
@click.argument("manifest", type=click.Path(dir_okay=False))
@click.option("--scheduler", metavar="ADDRESS", default=None,
              help="Dask scheduler to run on (e.g. tcp://10.0.0.5:8786); default a local cluster.")
@click.option("--connect-timeout", type=Number(min=0, min_open=True), default=10.0, show_default=True,
              metavar="SECONDS", help="How long to wait for the --scheduler before giving up.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Worker processes of the local cluster [default: one per core].")
@click.option("--force", is_flag=True, help="Run every job, even when its model is up to date.")
@click.option("--list", "list_only", is_flag=True, help="List the jobs and run nothing.")
@click.option("--allow-outside", is_flag=True,
              help="Trust MANIFEST: let it read logs and bases and write models and the history outside its folder.")
@json_flag
@common
@errors.cite_codes
def fleet_cmd(manifest, scheduler, connect_timeout, workers, force, list_only, allow_outside, as_json, quiet):
    """Run every job of MANIFEST (robots, logs, joints, pipeline: see docs/fleet.md) on Dask.

    A job is one (robot, joint, log): its model is refreshed unless it was made from the same log
    bytes with the same options (as --if-changed). Every job that ran adds a row to the history
    dataset. The run ends with a table of every job (ok, unchanged, or failed with its reason).
    The manifest reads and writes only under its own folder unless --allow-outside; a second run of
    the same manifest while one runs exits {LOCKED} at once. Exit code {OK} when every job is ok or
    unchanged, {SOME_FAILED} when some failed, {NOTHING_RAN} when nothing could run.

    \b
    Example:
      fricli simulate --fleet 4x6x1 -o fleet
      fricli fleet fleet/fleet.toml
      fricli fleet fleet.toml --scheduler tcp://127.0.0.1:8786
    """
    from fricli.fleet import manifest as mf
    from fricli.fleet import run

    m = mf.load(manifest, allow_outside=allow_outside)
    for line in m.unmatched:     # a robot dropping out of a nightly run must not go unnoticed
        warn(f"warning: {line}")
    if list_only:
        for job in m.jobs:
            click.echo("\t".join(errors.one_line(str(x)) for x in (job.robot, job.joint, job.date, job.pipeline,
                                                                    job.log, job.model)))
        return
    if not m.jobs:
        raise mf.ManifestError(f"{manifest}: no log matches the manifest's globs")
    bar = None
    if progress_enabled(quiet):
        from tqdm import tqdm

        bar = tqdm(total=len(m.jobs), desc="fleet", unit="job", leave=False)

    def on_done(done, total):
        if bar is not None:
            bar.update(done - bar.n)

    try:
        outcome = run.run(m, scheduler=scheduler, workers=workers, if_changed=not force, on_done=on_done,
                          connect_timeout=connect_timeout)
    finally:
        if bar is not None:
            bar.close()
    if as_json:
        emit_json({"run": outcome.run, "history": outcome.written, "exit_code": outcome.exit_code,
                   "jobs": [{"robot": j.robot, "joint": j.joint, "date": j.date, "log": j.log, "model": j.model,
                             "status": r["status"], "reason": r.get("reason", ""), "seconds": r.get("seconds"),
                             "warnings": r.get("warnings", [])}
                            for j, r in zip(outcome.jobs, outcome.results)]})
    else:
        click.echo(run.table(outcome))
    for line in outcome.warnings:
        warn(line)
    for job, res in zip(outcome.jobs, outcome.results):
        for line in res.get("warnings", []):
            warn(f"warning: {job.robot} joint {job.joint or '-'} {job.date}: {line}")
    if outcome.written:
        say(f"appended to {m.history} ({len(outcome.written)} files)", quiet)
    click.get_current_context().exit(outcome.exit_code)


@cli.command("trend")
@click.argument("history", type=click.Path(file_okay=False))
@click.option("--param", "params", multiple=True, default=("fc", "fv"), show_default=True,
              help="Parameter to watch (repeatable): fc, fs, fv, ...")
@click.option("--baseline-days", type=click.IntRange(min=1), default=7, show_default=True,
              help="The first days of a joint's data that set its baseline.")
@click.option("--window-days", type=click.IntRange(min=2), default=14, show_default=True,
              help="Days over which the growth is measured (the latest ones).")
@click.option("--max-level", type=Number(min=0, min_open=True), default=0.15, show_default=True,
              help="Flag a parameter above its baseline by more than this share.")
@click.option("--max-growth", type=Number(min=0, min_open=True), default=0.01, show_default=True,
              help="Flag a parameter growing faster than this share of its baseline per day.")
@click.option("--figures", metavar="DIR", default=None,
              help="Write a PNG per flagged joint into DIR (created when missing).")
@json_flag
@common
@errors.cite_codes
def trend_cmd(history, params, baseline_days, window_days, max_level, max_growth, figures, as_json, quiet):
    """Friction of every joint over time from a fleet HISTORY, and wear flags.

    A joint is flagged when a watched parameter has risen beyond --max-level over its own first
    --baseline-days days, or grows faster than --max-growth per day (see docs/fleet.md).
    Exit code {OK} when no joint is flagged, {WEAR} when at least one is (for alerting).

    \b
    Example:
      fricli trend fleet/history
      fricli trend fleet/history --json --figures wear/
    """
    from fricli.fleet import history as hist
    from fricli.fleet import trend

    allowed = set(hist.PARAMETERS)
    bad = [p for p in params if p not in allowed]
    if bad:
        raise click.BadParameter(f"unknown parameter {bad[0]!r} (choose from {', '.join(hist.PARAMETERS)})",
                                 param_hint="--param")
    rule = trend.WearRule(params=tuple(params), baseline_days=baseline_days, window_days=window_days,
                          max_level=max_level, max_growth=max_growth)
    result = trend.trends(hist.read(history), rule)
    flagged = [t for t in result if t.flagged]
    if figures:
        trend.figures(result, rule, figures)
    if as_json:
        emit_json({"rule": {k: list(v) if isinstance(v, tuple) else v for k, v in vars(rule).items()},
                   "flagged": [f"{t.robot}/{t.joint}" for t in flagged],
                   "joints": [t.as_dict() for t in result]})
    else:
        click.echo(trend_table(result, rule))
    say(f"{len(flagged)} of {len(result)} joints flagged for wear", quiet)
    click.get_current_context().exit(errors.WEAR if flagged else errors.OK)


def trend_table(result, rule) -> str:
    name = lambda x: errors.one_line(str(x))   # noqa: E731 - names quoted from the manifest, one line each
    rw = max([12] + [len(name(t.robot)) for t in result])
    jw = max([6] + [len(name(t.joint)) for t in result])
    head = f"{'robot':<{rw}} {'joint':<{jw}} {'days':>4}  " + "  ".join(f"{p + ' level':>9} {p + ' /day':>8}"
                                                                   for p in rule.params) + "  flag"
    lines = [head]
    for t in result:
        cells = []
        for p in rule.params:
            lv, gr = t.level.get(p), t.growth.get(p)
            cells.append(f"{'-' if lv is None else f'{100 * lv:+.1f}%':>9} "
                         f"{'-' if gr is None or gr != gr else f'{100 * gr:+.2f}%':>8}")
        flag = "WEAR: " + "; ".join(t.reasons) if t.flagged else t.note
        lines.append(f"{name(t.robot):<{rw}} {name(t.joint):<{jw}} {len(t.dates):>4}  " + "  ".join(cells)
                     + f"  {name(flag)}".rstrip())
    return "\n".join(lines)
