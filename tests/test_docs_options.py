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


COMMON = {"--help", "-h", "--debug", "-q", "--quiet", "--json", "-o", "--output"}
HEADING = re.compile(r"\n(?=#{1,6} )")


def sections() -> list[str]:
    """The sections (text from one heading to the next) of the README and docs/*.md, studies left out."""
    return [s for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
            for s in HEADING.split(path.read_text())]


def undocumented(pages: list[str]) -> list[str]:
    """'command --option' for each option of a command's --help that no section naming the command names."""
    ctx = click.Context(cli)
    missing = []
    for name in cli.list_commands(ctx):
        named = re.compile(rf"(?<![\w-]){re.escape(name)}(?![\w-])")
        about = [s for s in pages if named.search(s)]
        for param in cli.get_command(ctx, name).params:
            for option in (*getattr(param, "opts", ()), *getattr(param, "secondary_opts", ())):
                if option.startswith("-") and option not in COMMON and not any(
                        re.search(rf"{re.escape(option)}(?![\w-])", s) for s in about):
                    missing.append(f"{name} {option}")
    return missing


def test_every_option_of_a_commands_help_is_on_a_page():
    """Each option --help shows is named in a section of the README or docs/ about its command."""
    assert undocumented(sections()) == []


def test_the_check_finds_an_option_no_page_names():
    pages = sections()
    assert "thresholds --quantile" in undocumented([s.replace("--quantile", "a quantile") for s in pages])


def test_every_option_says_what_it_does():
    ctx = click.Context(cli)
    silent = [f"{name} {param.opts[0]}" for name in cli.list_commands(ctx)
              for param in cli.get_command(ctx, name).params
              if isinstance(param, click.Option) and not (param.help or "").strip()]
    assert silent == []


def test_every_page_a_help_text_names_exists():
    """The docs/ files the --help texts point to are there."""
    ctx = click.Context(cli)
    commands = [cli.get_command(ctx, name) for name in cli.list_commands(ctx)]
    texts = [cli.help] + [t for c in commands for t in (c.help, *(getattr(p, "help", "") for p in c.params))]
    named = {m.rstrip(".") for t in texts if t for m in re.findall(r"docs/[\w./-]+", t)}
    assert len(named) > 10
    assert sorted(n for n in named if not (ROOT / n).is_file()) == []
