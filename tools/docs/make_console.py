"""Rerun the commands of the ```console blocks in Markdown files and write their output back.

    python tools/docs/make_console.py README.md docs/tutorial.md

Each block holds commands (lines starting with ``$ ``, continued with a trailing ``\\``), each
followed by its output (stdout and stderr as a terminal shows them). The commands run in order,
in a scratch folder that sees the repository's ``sample_data`` and ``benchmarks``, with ``fricli`` on the PATH as
``python -m fricli`` of this checkout and ``python`` as the Python that runs this script; a command
that fails stops the script and changes nothing.
"""

from __future__ import annotations

import os
import pathlib
import re
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]
BLOCK = re.compile(r"```console\n(.*?)```", re.S)


def commands(block: str) -> list[str]:
    """The commands of a console block, continuation lines joined."""
    out, current = [], None
    for line in block.splitlines():
        if current is not None:
            current += "\n" + line
            if not line.endswith("\\"):
                out.append(current)
                current = None
        elif line.startswith("$ "):
            if line.endswith("\\"):
                current = line[2:]
            else:
                out.append(line[2:])
    return out


def run(command: str, cwd: pathlib.Path, env: dict) -> str:
    """stdout and stderr in the order a terminal shows them, the scratch folder's path left out."""
    proc = subprocess.run(["bash", "-o", "pipefail", "-c", command], cwd=cwd, env=env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True)
    if proc.returncode != 0:
        sys.exit(f"make_console: {command.splitlines()[0]!r} exited {proc.returncode}:\n{proc.stdout}")
    return proc.stdout.replace(f"{cwd}{os.sep}", "")


def rewrite(text: str, cwd: pathlib.Path, env: dict) -> str:
    def block(match: re.Match) -> str:
        parts = []
        for command in commands(match.group(1)):
            print(f"$ {command.splitlines()[0]}", file=sys.stderr)
            output = run(command, cwd, env).rstrip("\n")
            parts.append(f"$ {command}" + (f"\n{output}" if output else ""))
        return "```console\n" + "\n\n".join(parts) + "\n```"

    return BLOCK.sub(block, text)


def main(paths: list[str]) -> None:
    with tempfile.TemporaryDirectory(prefix="fricli-console-") as tmp:
        work, bin_dir = pathlib.Path(tmp), pathlib.Path(tmp, ".bin")
        for shared in ("sample_data", "benchmarks"):
            (work / shared).symlink_to(ROOT / shared)
        bin_dir.mkdir()
        for name, command in (("fricli", f'"{sys.executable}" -m fricli'), ("python", f'"{sys.executable}"')):
            shim = bin_dir / name
            shim.write_text(f'#!/bin/sh\nexec {command} "$@"\n')
            shim.chmod(0o755)
        env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}", COLUMNS="100", PYTHONUNBUFFERED="1",
                   PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
        new = {path: rewrite(pathlib.Path(path).read_text(), work, env) for path in paths}
    for path, text in new.items():
        pathlib.Path(path).write_text(text)
        print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1:] or [str(ROOT / "README.md")])
