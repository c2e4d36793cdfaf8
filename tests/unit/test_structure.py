"""The package's structure: no import cycles, and every code default equal to the schema's."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

import lidarfield
from lidarfield.analysis.stopping_rule import ExplainSettings
from lidarfield.defaults import default, section
from lidarfield.field.grid import CartesianGrid, FieldSettings, SphericalGrid
from lidarfield.plots.settings import STAGE_FIGURES, PlotSettings

PACKAGE = Path(lidarfield.__file__).parent


def module_name(path: Path) -> str:
    parts = ["lidarfield", *path.relative_to(PACKAGE).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, modules_of_package: set[str]) -> set[str]:
    """The package's modules that ``path`` imports, at its top or inside a function. ``from
    package import module`` imports the module: its package is loaded before, as the parent of
    every module in it, so it is no edge."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    modules = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module or ""
            for alias in node.names:
                submodule = f"{target}.{alias.name}"
                modules.add(submodule if submodule in modules_of_package else target)
        elif isinstance(node, ast.Import):
            modules.update(alias.name for alias in node.names)
    return {m for m in modules if m.startswith("lidarfield")}


def import_graph() -> dict[str, set[str]]:
    paths = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    return {name: {m for m in imports(path, set(paths)) if m in paths and m != name} for name, path in paths.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` (as the list of its nodes, first repeated last), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node], _ = 1, path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        state[node], _ = 2, path.pop()
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def package_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The graph between the package's parts: its subpackages, and its top-level modules."""

    def part(module: str) -> str:
        return ".".join(module.split(".")[:2])

    parts: dict[str, set[str]] = {}
    for module, targets in graph.items():
        if module == "lidarfield":  # the flat API imports everything, lazily: not a part
            continue
        parts.setdefault(part(module), set()).update(part(t) for t in targets if part(t) != part(module))
    parts = {p: {t for t in targets if t != "lidarfield"} for p, targets in parts.items()}
    return parts


def test_the_cycle_finder_finds_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_module_of_the_package_imports_itself_back():
    """Lazy imports count: a function-level import that closes a cycle is a cycle too."""
    assert find_cycle(import_graph()) is None


def test_the_parts_of_the_package_import_each_other_in_one_direction():
    """Between subpackages too (``field`` below ``analysis``, ``study`` below ``report``...)."""
    assert find_cycle(package_graph(import_graph())) is None


def test_no_test_scaffolding_in_the_package():
    assert not [p for p in PACKAGE.rglob("*.py") if "synthetic" in p.name or p.name.startswith("test")]


def code_defaults(cls) -> dict:
    return {
        f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING and f.name != "grid"
    }


@pytest.mark.parametrize(
    ("cls", "schema_section"),
    [
        (SphericalGrid, "grid"),
        (CartesianGrid, "grid"),
        (FieldSettings, "grid"),
        (PlotSettings, "plots"),
        (ExplainSettings, "explain"),
    ],
)
def test_every_code_default_is_the_schema_default(cls, schema_section):
    properties = section(schema_section)["properties"]
    for name, value in code_defaults(cls).items():
        expected = properties[name]["default"]
        as_schema = list(value) if isinstance(value, tuple) else value
        assert as_schema == expected and type(as_schema) in (type(expected), float), (
            f"{cls.__name__}.{name} defaults to {value!r}, the schema's grid/plots section says {expected!r}"
        )


def test_the_grid_and_plot_settings_cover_every_key_of_their_schema_sections():
    grid_keys = set(section("grid")["properties"]) - {"kind"}
    covered = {f.name for cls in (SphericalGrid, CartesianGrid, FieldSettings) for f in dataclasses.fields(cls)} - {
        "grid"
    }
    assert grid_keys == covered
    plot_keys = set(section("plots")["properties"]) - {"pairs"}  # pairs: the workflow's choice, not a figure's
    assert plot_keys == {f.name for f in dataclasses.fields(PlotSettings)}
    assert list(STAGE_FIGURES) == default("plots", "figures")


def test_a_cartesian_field_from_the_command_line_bins_on_the_schema_cell():
    """`lidarfield field --kind cartesian` and a study took 1.0 m and 2.0 m cells before."""
    from lidarfield.field.grid import field_settings_from_config

    assert CartesianGrid().cell_m == default("grid", "cell_m") == 2.0
    assert field_settings_from_config({"kind": "cartesian"}).grid == CartesianGrid()


def test_the_loose_top_level_modules_are_the_base_layer():
    """A new module goes into a part (docs/development.md lists them), not beside these."""
    loose = {p.stem for p in PACKAGE.glob("*.py")} - {"__init__", "__main__"}
    assert loose == {"errors", "checks", "defaults", "yaml_file", "threads", "poses", "scan", "pair"}
