"""fricli fleet, fricli trend."""

from __future__ import annotations


import click

from fricli.core import errors
from fricli.cli import cli
from fricli.cli.options import Number, bad_parameter, common, emit_json, json_flag, progress_enabled, say, warn


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
    from fricli.fleet.run import run_fleet

    bar = None

    def on_done(done, total):
        nonlocal bar
        if bar is None and progress_enabled(quiet):
            from tqdm import tqdm

            bar = tqdm(total=total, desc="fleet", unit="job", leave=False)
        if bar is not None:
            bar.update(done - bar.n)

    try:
        result = run_fleet(manifest, scheduler=scheduler, connect_timeout=connect_timeout, workers=workers,
                           force=force, list_only=list_only, allow_outside=allow_outside, warn=warn, on_done=on_done)
    finally:
        if bar is not None:
            bar.close()
    if list_only:
        if as_json:
            emit_json(result.as_json())
        elif result.jobs:
            click.echo(result.listing())
        return
    if as_json:
        emit_json(result.as_json())
    else:
        click.echo(result.table())
    for line in result.run_warnings:
        warn(line)
    if result.outcome.written:
        say(f"appended to {result.manifest.history} ({len(result.outcome.written)} files)", quiet)
    click.get_current_context().exit(result.exit_code)


@cli.command("trend")
@click.argument("history", type=click.Path(file_okay=False))
@click.option("--param", "params", multiple=True, default=("fc", "fv"), show_default=True,
              help="Parameter to watch (repeatable): fc, fs, fv, ...")
@click.option("--baseline-days", type=click.IntRange(min=3), default=7, show_default=True,   # trend.MIN_BASELINE_DAYS
              help="The first days of a joint's data that set its baseline (a median of one value a day: 3 at least).")
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
    from fricli.fitting.optionspec import OptionError
    from fricli.fleet.trend import fleet_trend

    try:
        result = fleet_trend(history, params=params, baseline_days=baseline_days, window_days=window_days,
                             max_level=max_level, max_growth=max_growth, figures=figures)
    except OptionError as exc:
        if exc.option != "params":
            raise
        raise bad_parameter(exc, {"params": "--param"}) from None
    if as_json:
        emit_json(result.as_json())
    else:
        click.echo(result.table())
    say(f"{len(result.flagged)} of {len(result.joints)} joints flagged for wear", quiet)
    click.get_current_context().exit(result.exit_code)
