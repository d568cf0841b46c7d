"""The command line starts without the heavy libraries: commands load lazily, and scipy,
pandas, matplotlib and pyarrow are imported only by the commands that use them."""

import json
import subprocess
import sys

import click
import pytest

from conftest import ROOT
from fricli.cli import COMMANDS, cli

HEAVY = ("scipy", "pandas", "matplotlib", "pyarrow")

_PROBE = """
import json, sys
from fricli.cli import cli
for args in {runs!r}:
    try:
        cli.main(args, prog_name="fricli", standalone_mode=False)
    except SystemExit:
        pass
print(json.dumps(sorted({{m.split(".")[0] for m in sys.modules}} & set({heavy!r}))))
"""


def heavy_imports_after(runs: list[list[str]]) -> list[str]:
    """Heavy top-level packages imported by a fresh interpreter that runs the fricli CLI with
    each argument list in ``runs`` (output of --help/--version goes to /dev/null)."""
    code = _PROBE.format(runs=runs, heavy=HEAVY)
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_importing_the_cli_imports_no_heavy_library():
    assert heavy_imports_after([]) == []


def test_version_and_every_help_import_no_heavy_library():
    runs = [["--version"], ["--help"]] + [[name, "--help"] for name in COMMANDS]
    assert heavy_imports_after(runs) == []


def test_the_probe_sees_a_heavy_import(tmp_path):
    # the checks above can fail: a command that writes a log imports pyarrow
    out = tmp_path / "adapt.parquet"
    assert "pyarrow" in heavy_imports_after([["simulate", "--scenario", "adapt", "-o", str(out), "-q"]])
    assert out.exists()


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_registered_command_loads_under_its_name(name):
    command = cli.get_command(None, name)
    assert isinstance(command, click.Command) and command.name == name


def test_unknown_command_is_a_usage_error():
    from click.testing import CliRunner

    res = CliRunner().invoke(cli, ["no-such-command"])
    assert res.exit_code == 2 and "No such command" in res.output
