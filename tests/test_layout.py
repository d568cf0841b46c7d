"""The package's layout (docs/architecture.md): no module over MAX_LINES lines, no circle of
imports among fricli's modules, and one registered name per effect in every layer that knows
effects (``fricli.core.effectnames``)."""

from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, imported_modules
from fricli.core import effectnames
from fricli.fitting.diagnosis import driver, fix
from fricli.fitting.diagnosis import effects as diagnosis_effects
from fricli.models.augmented import AugmentedModel
from fricli.models.linear import LinearFriction
from fricli.sim import effects as sim_effects

PACKAGE = Path(ROOT) / "fricli"
MAX_LINES = 600


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def test_no_module_is_longer_than_the_limit():
    long = {name: n for name, path in MODULES.items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}, f"split these modules by concern (at most {MAX_LINES} lines each)"


def imports_of(name: str, path: Path, top_level: bool) -> set[str]:
    """fricli's modules that ``path`` (module ``name``) imports: at its top level (in module-level
    if/try blocks too), or anywhere, in functions as well. ``from P import X`` counts as P.X when
    that is a module, else as P; a module's own packages (imported with it anyway) do not count."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = {m if m in MODULES else m.rpartition(".")[0] for m in imported_modules(path.read_text(), package, top_level)}
    return {m for m in found if m in MODULES and m != name and not name.startswith(m + ".")}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def strong(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while not comp or comp[-1] != v:
                comp.append(stack.pop())
                on.discard(comp[-1])
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_circles_are_found():
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert circles({"a": {"b"}, "b": set()}) == []


@pytest.mark.parametrize("top_level", [True, False], ids=["top-level imports", "function-level imports too"])
def test_no_import_circle(top_level):
    graph = {name: imports_of(name, path, top_level) for name, path in MODULES.items()}
    assert any(graph.values())   # the graph sees the imports at all
    assert circles(graph) == []


def test_the_registry_names_every_effect_once():
    assert all(name == name.strip().lower() and " " not in name for name in effectnames.EFFECTS)
    assert not set(effectnames.ALIASES) & set(effectnames.EFFECTS)
    assert set(effectnames.ALIASES.values()) <= set(effectnames.EFFECTS)
    assert effectnames.registered("column:humidity") and not effectnames.registered("column:")
    assert not effectnames.registered("inertia") and effectnames.canonical("inertia") == "acceleration"


def test_the_simulator_uses_registered_names():
    for name, effect in sim_effects.EFFECTS.items():
        assert effectnames.registered(name) and effect.name == name
        assert type(effect).__name__.lower() == name          # class Position for "position", not Ripple
    assert sim_effects.ALIASES == effectnames.ALIASES
    for old, new in effectnames.ALIASES.items():
        assert sim_effects.parse(old) == (new, None)


def test_the_diagnosis_uses_registered_names():
    library = diagnosis_effects.library({"humidity": np.zeros(3)})
    assert "column:humidity" in [e.name for e in library]
    for effect in library:
        assert effectnames.registered(effect.name), effect.name
        assert type(effect).__name__.lower() == effect.name.partition(":")[0]
        assert all(effectnames.registered(r) for combo in effect.rivals for r in combo)
    assert set(diagnosis_effects.NAMES) <= set(effectnames.EFFECTS)
    known = [*fix.CARRIABLE, *fix.SHARING, *fix.CARRIED_PARAMS, *driver.CALIBRATED_EFFECTS, *sum(driver.TWINS, ())]
    assert all(effectnames.registered(name) for name in known), known
    for old, new in effectnames.ALIASES.items():
        assert [e.name for e in diagnosis_effects.library({}, [old])] == [new]


def test_the_simulator_and_the_diagnosis_share_the_names_of_the_effects_both_know():
    both = set(sim_effects.EFFECTS) & set(diagnosis_effects.NAMES)
    assert both >= {"position", "direction", "acceleration", "temperature", "drift", "gravity", "load"}


def test_a_model_file_with_an_earlier_effect_name_reads_as_the_registered_one():
    base = LinearFriction(fc=1.0, fv=0.5)
    stored = AugmentedModel(base, [{"name": "qdd", "factors": [{"f": "signal", "name": "qdd"}]}], [0.1],
                            effects=["inertia", "ripple"], params={"inertia": {}, "level": {}}, errors=["inertia"])
    params, arrays, children = stored.get_params(), stored.get_arrays(), stored.children()
    back = AugmentedModel.from_parts(params, arrays, children)
    assert back.effects == ["acceleration", "position"] and back.errors == ["acceleration"]
    assert set(back.params) == {"acceleration", "level"}
    assert all(effectnames.registered(name) for name in back.effects + back.errors + list(back.params))
