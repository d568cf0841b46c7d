"""fricli demo."""

from __future__ import annotations

import os

import click

from fricli.cli import cli
from fricli.cli.options import Folder, common, say


@cli.command("demo")
@click.option("-o", "--output", default="demo-out", show_default=True, type=Folder(),
              help="Folder for the models, tables and report.")
@click.option("--data", default="sample_data", show_default=True, type=click.Path(file_okay=False),
              help="Folder with the sample logs; missing logs are simulated (same seeds, same data).")
@click.option("--joint", type=click.Choice(["2", "4"]), default="2", show_default=True,
              help="Which joint's sample logs (joint2_*.parquet or joint4_*.parquet).")
@click.option("--steps", type=click.IntRange(min=1), default=None,
              help="Adam steps for each base network [default: train-base's, with a cosine learning rate].")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of every network's training (train-base, adapt).")
@common
def demo_cmd(output, data, joint, steps, seed, quiet):
    """The whole method on the sample data: identify LuGre, train NN_base and the Selmic and
    NNACM baselines, adapt NN_base with NN_add on under a minute of load-free data, evaluate
    friction and external torque on the extended logs, and write a report page (report/index.html:
    the comparison table, the fitted models' curves and the adapted model's figures, captioned).

    Prints the comparison in the layout of the paper's Table 2 on stdout.

    \b
    Example:
      fricli demo -o demo-out
      fricli demo --joint 4 --steps 50000
    """
    from fricli.demo import run_demo  # loads matplotlib, scipy.optimize: only when run

    result = run_demo(output, data=data, joint=int(joint), steps=steps, seed=seed, say=lambda s: say(s, quiet))
    click.echo(result.table())
    say(f"models, results.json, table.md and report/ are in {os.path.abspath(output)}", quiet)
