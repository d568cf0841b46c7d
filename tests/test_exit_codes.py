"""Every exit code that the docs, README.md and ``--help`` texts state agrees with
``fricli.core.errors.TABLE``, and the shell recipes in the docs act on the codes as they say."""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys

import pytest
from click.testing import CliRunner

from fricli.core import errors
from fricli.cli import COMMANDS, cli

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]

# "exit 3", "exits with 11", "exit code 4", "exit codes 3 and 4", "with code 7", "code 8", and the
# numbers listed after one of them ("0, 5 or 6").
MENTION = re.compile(r"\b(?:exit(?:s|ed|ing)?(?:\s+with)?(?:\s+(?:status|codes?))?|codes?)"
                     r"(?:\s+(?:is|was|of))?\s+(\d+)((?:\s*(?:\([A-Z_]+\))?(?:\s*,|\s+or|\s+and)\s+\d+)*)")
NUMBER = re.compile(r"\d+")
# "11 (SOME_FAILED)"; "UNCHANGED (9)", "LOCKED (exit 8)", "(MODEL, exit code 4)"
NAMED = re.compile(r"\b(\d+)\s*\(([A-Z][A-Z_]+)\)")
NAME_FIRST = re.compile(r"\b([A-Z][A-Z_]+)(?:\s*\((?:exit\s+|code\s+)?|,\s+(?:exit\s+code|exit|code)\s+)(\d+)\b")
STATUS_TEST = re.compile(r"\$\?|\$rc\b")


def problems(text: str) -> list[str]:
    """What is wrong with the exit codes ``text`` mentions: a code written without its name
    (``N (NAME)``), or a number that is not the code of the name beside it."""
    found = []
    named = {}
    for m in NAMED.finditer(text):
        if m[2] in errors.BY_NAME:
            named[m.start(1)] = m
    for m in NAME_FIRST.finditer(text):
        if m[1] in errors.BY_NAME:
            named[m.start(2)] = m
    for start, m in named.items():
        name, number = (m[2], m[1]) if m.re is NAMED else (m[1], m[2])
        if errors.BY_NAME[name].code != int(number):
            found.append(f"{m[0]!r}: {name} is {errors.cite(errors.BY_NAME[name].code)}")
    for m in MENTION.finditer(text):
        starts = [m.start(1)] + [m.start(2) + n.start() for n in NUMBER.finditer(m[2])]
        for start in starts:
            if start not in named:
                number = NUMBER.match(text, start)[0]
                line = text[max(0, m.start() - 30):m.end() + 10].replace("\n", " ")
                found.append(f"exit code {number} without its name (write it as N (NAME)): ...{line}...")
    return found


def table_text(text: str) -> str:
    """The cells of Markdown table columns headed "code" (with the "name" column beside, if any)
    as sentences ``exit code CELL (NAME)``, for ``problems``."""
    out = []
    header = None
    for line in text.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if header is None:
            header = [c.lower() for c in cells]
            continue
        if set("".join(cells)) <= set("-: "):
            continue
        for i, head in enumerate(header):
            if head in ("code", "exit code") and i < len(cells) and cells[i]:
                name = cells[header.index("name")] if "name" in header else ""
                out.append(f"exit code {cells[i]} ({name})" if name else f"exit code {cells[i]}")
    return "\n".join(out)


def doc_problems(path: pathlib.Path) -> list[str]:
    """``problems`` of a Markdown file: its text (code blocks too) and its tables' code columns.
    Shell code that branches on a code (``case $? in 11)``) is run by the recipe tests below."""
    text = path.read_text(encoding="utf-8")
    return [f"{path.relative_to(ROOT)}: {p}" for p in problems(text) + problems(table_text(text))]


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_docs_state_the_codes_of_errors_py(path):
    assert doc_problems(path) == []


def help_texts() -> dict[str, str]:
    """``--help`` of ``fricli`` and of every command."""
    runner = CliRunner()
    out = {}
    for args in [[]] + [[name] for name in COMMANDS]:
        res = runner.invoke(cli, [*args, "--help"], terminal_width=100)
        assert res.exit_code == 0, res.output
        out[" ".join(["fricli", *args])] = res.output
    return out


def test_help_texts_state_the_codes_of_errors_py():
    texts = help_texts()
    found = [f"{cmd} --help: {p}" for cmd, text in texts.items() for p in problems(text)]
    assert found == []
    for row in errors.TABLE:
        assert f"{row.code} {row.name}" in texts["fricli"]
    assert errors.cite(errors.SOME_FAILED) in texts["fricli fleet"]
    assert errors.cite(errors.NOTHING_RAN) in texts["fricli fleet"]
    assert errors.cite(errors.WEAR) in texts["fricli trend"]


def test_the_table_names_its_constants_and_docs_exit_codes_md_is_current():
    assert len(errors.BY_CODE) == len(errors.BY_NAME) == len(errors.TABLE)
    for row in errors.TABLE:
        assert getattr(errors, row.name) == row.code
    sys.path.insert(0, str(ROOT / "tools" / "docs"))
    try:
        import make_exit_codes
    finally:
        sys.path.remove(str(ROOT / "tools" / "docs"))
    text = make_exit_codes.DOC.read_text(encoding="utf-8")
    assert make_exit_codes.render(text) == text, "docs/exit-codes.md is stale: run python tools/docs/make_exit_codes.py"
    assert make_exit_codes.table() in text


def test_the_checks_find_a_wrong_or_unnamed_code():
    """The checks above fail on the mistakes they are for (a planted wrong number)."""
    assert problems("Exit code 0 (OK) when every job is ok, 10 (SOME_FAILED) when some failed.")
    assert problems("without Dask it exits with 11.")
    assert problems("a model of another joint is refused (MODEL, exit code 3).")
    assert problems("refused (exit 3, with the line)")
    assert problems(table_text("| command | exit code | meaning |\n|---|---|---|\n| trend | 12 | wear |"))
    assert problems(table_text("| code | name | meaning |\n|---|---|---|\n| 12 | WEAR | wear |"))
    assert problems(table_text("| input | code |\n|---|---|\n| absurd | 0, 5 (FIT) or 6 (DATA) |"))
    assert not problems("refused (INPUT, exit 3); 9 (UNCHANGED); exits with code 5 (FIT); LOCKED (exit 8)")
    assert not problems(table_text("| input | code |\n|---|---|\n| absurd | 0 (OK), 5 (FIT) or 6 (DATA) |"))


# Shell recipes in the docs that act on an exit code, each run below with stand-in commands.
RECIPES = {("fleet.md", "fricli fleet fleet.toml"), ("reliability.md", "fricli train-base")}


def shell_blocks(doc: str, marker: str) -> list[str]:
    text = (ROOT / "docs" / doc).read_text(encoding="utf-8")
    return [b for b in re.findall(r"^```sh\n(.*?)^```", text, re.M | re.S) if marker in b]


def test_every_recipe_that_acts_on_an_exit_code_is_run_by_a_test():
    acting = {(path.name, block) for path in DOCS
              for block in re.findall(r"^```.*?\n(.*?)^```", path.read_text(encoding="utf-8"), re.M | re.S)
              if STATUS_TEST.search(block)}
    tested = set()
    for doc, marker in RECIPES:
        [block] = shell_blocks(doc, marker)
        tested.add((doc, block))
    assert acting == tested


def stand_in(folder: pathlib.Path, name: str, body: str) -> None:
    path = folder / name
    path.write_text("#!/bin/sh\n" + body)
    path.chmod(0o755)


def run_recipe(tmp_path, script: str, codes: dict[str, int]) -> subprocess.CompletedProcess:
    """Run ``script`` with ``sh`` in ``tmp_path``, with a ``fricli`` that prints a line and exits
    with ``codes[COMMAND]`` (0 when absent) and ``mail``/``systemctl`` that append their arguments
    and input to ``calls``."""
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    stand_in(bin_, "fricli", 'echo "output of fricli $1"\ncase $1 in\n'
             + "".join(f"  {cmd}) exit {code} ;;\n" for cmd, code in codes.items()) + "esac\nexit 0\n")
    for tool in ("mail", "systemctl"):
        stand_in(bin_, tool, f'echo "{tool} $*" >> calls\n' + ('cat >> calls\n' if tool == "mail" else ""))
    env = {**os.environ, "PATH": f"{bin_}{os.pathsep}{os.environ['PATH']}"}
    res = subprocess.run(["sh", "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=30)
    assert res.stderr == "", res.stderr
    return res


def calls(tmp_path) -> list[str]:
    path = tmp_path / "calls"
    return path.read_text().splitlines() if path.exists() else []


MAIL = "mail -s fricli: "


@pytest.mark.parametrize("fleet, trend, mails", [
    (errors.OK, errors.OK, []),
    (errors.USAGE, errors.OK, ["the nightly fleet run did not run"]),
    (errors.SOME_FAILED, errors.OK, ["some joints failed"]),
    (errors.NOTHING_RAN, errors.OK, ["the nightly fleet run did not run"]),
    (errors.FAILURE, errors.OK, ["the nightly fleet run did not run"]),
    (errors.OK, errors.WEAR, ["joints wearing"]),
    (errors.SOME_FAILED, errors.WEAR, ["some joints failed", "joints wearing"]),
    (errors.NOTHING_RAN, errors.WEAR, ["the nightly fleet run did not run", "joints wearing"]),
    (errors.OK, errors.INPUT, ["the wear trend failed"]),
], ids=lambda v: errors.BY_CODE[v].name if isinstance(v, int) else None)
def test_the_nightly_fleet_recipe_mails_what_its_codes_mean(tmp_path, fleet, trend, mails):
    [script] = shell_blocks("fleet.md", "fricli fleet fleet.toml")
    run_recipe(tmp_path, script, {"fleet": fleet, "trend": trend})
    sent = [c[len(MAIL):].removesuffix(" maint@example.com") for c in calls(tmp_path) if c.startswith(MAIL)]
    assert sent == mails
    lines = calls(tmp_path)
    for subject in mails:  # each mail carries the output of the command it is about
        body = lines[lines.index(f"{MAIL}{subject} maint@example.com") + 1]
        assert body == ("output of fricli trend" if "wear" in subject else "output of fricli fleet")


@pytest.mark.parametrize("code, says, reloads", [
    (errors.OK, "", True),
    (errors.UNCHANGED, "", False),
    (errors.LOCKED, "another job is writing the model", False),
    (errors.INPUT, "bad or too short log: kept the previous model", False),
    (errors.DATA, "bad or too short log: kept the previous model", False),
    (errors.FIT, "failed: kept the previous model", False),
    (errors.FAILURE, "failed: kept the previous model", False),
], ids=lambda v: errors.BY_CODE[v].name if isinstance(v, int) and not isinstance(v, bool) else None)
def test_the_retraining_recipe_acts_on_each_code(tmp_path, code, says, reloads):
    [script] = shell_blocks("reliability.md", "fricli train-base")
    res = run_recipe(tmp_path, script, {"train-base": code})
    assert res.stdout == f"output of fricli train-base\n{says}\n".replace("\n\n", "\n")
    assert calls(tmp_path) == (["systemctl reload robot-controller"] if reloads else [])
