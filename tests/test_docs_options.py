"""Every option the README and docs/*.md give a fricli command exists on that command."""

import re

import click

from conftest import ROOT
from fricli.cli import cli

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
# a command and what follows it up to the end of its code span, table cell, quote or line
USE = re.compile(r"fricli ([a-z][a-z-]*)([^`|'\"\n]*)")
OPTION = re.compile(r"(?<![\w-])(--?[a-zA-Z][\w-]*)(?![\w*-])")


def options(command) -> set[str]:
    names = {"--help", "-h"}
    for param in command.params:
        names.update(getattr(param, "opts", ()))
        names.update(getattr(param, "secondary_opts", ()))
    if isinstance(command, click.Group):
        for sub in command.commands.values():
            names |= options(sub)
    return names


def uses():
    ctx = click.Context(cli)
    commands = {name: cli.get_command(ctx, name) for name in cli.list_commands(ctx)}
    for path in DOCS:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for match in USE.finditer(line):
                if match.group(1) in commands:
                    for option in OPTION.findall(match.group(2)):
                        yield f"{path.relative_to(ROOT)}:{number}", match.group(1), option, options(commands[match.group(1)])


def test_every_documented_option_exists():
    found = list(uses())
    assert len(found) > 200          # the pattern still finds the commands the docs show
    wrong = [f"{where}: fricli {command} has no option {option}" for where, command, option, known in found
             if option not in known]
    assert not wrong, "\n".join(wrong)
