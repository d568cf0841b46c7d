"""The import rules of docs/architecture.md: a module imports only from its own layer and the
layers below it, and only the command line (fricli/cli/ and fricli/__main__.py) imports
fricli.cli (the library never reads the command line)."""

from pathlib import Path

from conftest import ROOT, imported_modules

PACKAGE = Path(ROOT) / "fricli"

# bottom to top: (layer, its folder of fricli; the cli layer also holds the top-level modules), as
# docs/architecture.md lists them: the folder tree is the layering
LAYERS = [
    ("contracts and files", {"core"}),
    ("numerics", {"numerics"}),
    ("models", {"models"}),
    ("fitting", {"fitting"}),
    ("applying", {"applying"}),
    ("robot", {"robot"}),
    ("fleet", {"fleet"}),
    ("export", {"export"}),
    ("simulation", {"sim"}),
    ("library and runs", {"estimators", "arm", "arm_diagnosis", "demo"}),
    ("cli", {"cli", "__main__"}),
]
RANK = {name: i for i, (_, names) in enumerate(LAYERS) for name in names}


def layer_of(dotted: str) -> int | None:
    """The layer of a module named relative to fricli ("core.logs", "fleet.run"): its folder's."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        if ".".join(parts[:k]) in RANK:
            return RANK[".".join(parts[:k])]
    return None


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


def package_parts() -> set[str]:
    return {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
            if (p.suffix == ".py" or (p / "__init__.py").exists()) and p.name != "__init__.py"}


def test_every_module_has_a_layer():
    assert package_parts() - set(RANK) == set(), "place the new module in LAYERS and docs/architecture.md"


def upward_imports() -> list[str]:
    """Imports of a module from a layer above its own."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).parts
        if parts == ("__init__.py",):
            continue
        me = layer_of(".".join(parts).removesuffix(".py").removesuffix(".__init__"))
        package = ".".join(path.relative_to(ROOT).parts[:-1])
        for module in imported_modules(path.read_text(), package):
            other = layer_of(module.removeprefix("fricli.")) if module.startswith("fricli.") else None
            if other is not None and other > me:
                out.append(f"fricli/{'/'.join(parts)} ({LAYERS[me][0]}) imports {module} ({LAYERS[other][0]})")
    return sorted(set(out))


def test_no_module_imports_from_a_layer_above_its_own():
    assert upward_imports() == []


def test_the_rule_sees_every_form_of_import():
    for source in ("import fricli.cli", "def f():\n    from fricli.cli.options import say\n",
                   "from fricli import cli", "from ..cli import options"):
        modules = imported_modules(source, "fricli.fleet")
        assert any(m == "fricli.cli" or m.startswith("fricli.cli.") for m in modules), source
    assert not any(m.startswith("fricli.cli") for m in imported_modules("from fricli import runs", "fricli.fleet"))
