"""The README's set-up commands: CI runs the test command as written, and the two commands use
environments of their own (the second is fresh even after the first)."""

import re

from conftest import ROOT


def setup_commands() -> list[str]:
    block = re.search(r"```sh\n(.*?)```", (ROOT / "README.md").read_text(), re.S).group(1)
    return [line for line in block.splitlines() if line.startswith("python3 -m venv")]


def test_ci_runs_the_readmes_test_command():
    test = [c for c in setup_commands() if "pytest" in c]
    assert len(test) == 1 and test[0] in (ROOT / ".ci" / "run").read_text()


def test_the_readmes_commands_use_distinct_environments():
    envs = [re.match(r"python3 -m venv (\S+)", c).group(1) for c in setup_commands()]
    assert len(envs) == 2 and len(set(envs)) == 2
