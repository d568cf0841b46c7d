"""fricli inspect."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import common, emit_json


@cli.command("inspect")
@click.argument("model", type=click.Path())
@common
def inspect_model(model: str, quiet: bool) -> None:
    """Print a model file's meta (kind, units, parameters, provenance) as JSON.

    MODEL may be a model folder (one model per joint, docs/joints.md): then
    {"joints": {joint: meta}}, in the folder's order.

    \b
    Example:
      fricli inspect lugre.npz
      fricli inspect lugre-arm/
    """
    from fricli.estimators.reporting import inspect_models

    emit_json(inspect_models(model))
