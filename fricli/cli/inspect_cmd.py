"""fricli inspect."""

from __future__ import annotations

import click

from fricli import models
from fricli.cli import cli
from fricli.cli.options import common, emit_json


@cli.command("inspect")
@click.argument("model", type=click.Path(dir_okay=False))
@common
def inspect_model(model: str, quiet: bool) -> None:
    """Print a model file's meta (kind, units, parameters, provenance) as JSON.

    \b
    Example:
      fricli inspect lugre.npz
    """
    _, meta = models.load(model)
    emit_json(meta)
