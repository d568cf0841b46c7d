"""The import rule of docs/architecture.md: only the command line (fricli/cli/ and
fricli/__main__.py) imports fricli.cli; the library never reads the command line."""

import ast
from pathlib import Path

from conftest import ROOT

PACKAGE = Path(ROOT) / "fricli"


def imported_modules(source: str, package: str) -> set[str]:
    """Every module ``source`` (a module of ``package``) imports: absolute names, relative
    imports resolved, imports inside functions included."""
    tree = ast.parse(source)
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{alias.name}" for alias in node.names)
    return found


def cli_importers() -> list[str]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("fricli/cli/") or rel == "fricli/__main__.py":
            continue
        package = ".".join(path.relative_to(ROOT).parts[:-1])
        if any(m == "fricli.cli" or m.startswith("fricli.cli.") for m in imported_modules(path.read_text(), package)):
            out.append(rel)
    return out


def test_only_the_command_line_imports_fricli_cli():
    assert cli_importers() == []


def test_the_rule_sees_every_form_of_import():
    for source in ("import fricli.cli", "def f():\n    from fricli.cli.options import say\n",
                   "from fricli import cli", "from ..cli import options"):
        modules = imported_modules(source, "fricli.fleet")
        assert any(m == "fricli.cli" or m.startswith("fricli.cli.") for m in modules), source
    assert not any(m.startswith("fricli.cli") for m in imported_modules("from fricli import runs", "fricli.fleet"))
