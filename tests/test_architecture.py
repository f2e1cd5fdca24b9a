"""The package layout keeps its promises: imports run one way, down the layers of
docs/architecture.md (no circle among modules, counting imports inside functions and those made
only for type checking; the core imports only the navigation toolbox and the base layer; no layer
that knows no sensor imports a plugin) and no module grows past the size a reader takes in at once."""

from __future__ import annotations

from pathlib import Path

import pytest

from bodyfusion.testing.imports import LAYERS, ImportGraph

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "bodyfusion"
MAX_LINES = 600
SENSOR_FREE = ("base", "core", "nav", "io", "evaluation", "results", "outputs", "runner")
"""Packages that know no sensor: none of them may import :mod:`bodyfusion.plugins`."""
CORE_MAY_IMPORT = ("core", "nav", "base")
"""The core is the layout and the fuser: it reads no file, scores nothing, knows no sensor."""
IMPORTS = ImportGraph(PACKAGE)
MODULES = IMPORTS.modules
GRAPH = IMPORTS.graph(everywhere=False)
ALL_IMPORTS = IMPORTS.graph(everywhere=True)
_layer = IMPORTS.layer


@pytest.mark.parametrize("graph", [GRAPH, ALL_IMPORTS], ids=["module_level", "anywhere"])
def test_no_import_circle_among_modules(graph):
    """Depth-first search for a back edge in the import graph: of what importing a module runs,
    and of every import anywhere in it (inside functions, for type checking only)."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for name in sorted(graph):
        if name not in state:
            cycle = visit(name)
            assert cycle is None, " -> ".join(cycle)


@pytest.mark.parametrize("layer", SENSOR_FREE)
def test_layers_that_know_no_sensor_import_no_plugin(layer):
    offenders = {name: sorted(m for m in imports if m.startswith("bodyfusion.plugins"))
                 for name, imports in ALL_IMPORTS.items() if name.startswith(f"bodyfusion.{layer}")}
    assert not {k: v for k, v in offenders.items() if v}


def test_the_core_imports_only_the_navigation_toolbox_and_the_base_layer():
    offenders = {name: sorted(m for m in imports if _layer(m) not in CORE_MAY_IMPORT)
                 for name, imports in ALL_IMPORTS.items() if _layer(name) == "core"}
    assert not {k: v for k, v in offenders.items() if v}


def test_every_package_imports_only_the_layers_below_it():
    assert {_layer(m) for m in MODULES} - {None} <= set(LAYERS) | {"__main__"}  # every package has its layer
    upward = sorted(f"{name} -> {m}" for name, imports in ALL_IMPORTS.items() for m in imports
                    if _layer(name) in LAYERS and _layer(m) in LAYERS
                    and LAYERS.index(_layer(m)) < LAYERS.index(_layer(name)))
    assert not upward, upward


MAX_POSITIONAL = 10
"""The most positional parameters a function or kernel takes: more travel as named records."""


def test_no_function_takes_more_than_ten_positional_parameters():
    import ast

    many = {}
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = [*node.args.posonlyargs, *node.args.args]
                count = len(args) - (1 if args and args[0].arg in ("self", "cls") else 0)
                if count > MAX_POSITIONAL:
                    many[f"{name}.{node.name}"] = count
    assert not many, many


def test_no_module_over_six_hundred_lines():
    long = {name: n for name, path in MODULES.items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_the_graph_sees_imports():
    """The checks above are not vacuous: known edges are found, those inside functions and under
    ``if TYPE_CHECKING`` only in the graph of every import, and ``from package import module``."""
    assert "bodyfusion.nav.error_state" in GRAPH["bodyfusion.plugins.foot_ins.kernels"]
    assert "bodyfusion.core.layout" in GRAPH["bodyfusion.plugins.foot_ins.config"]
    assert "bodyfusion.results.frames" not in GRAPH["bodyfusion.results.run_result"]  # inside methods
    assert "bodyfusion.results.frames" in ALL_IMPORTS["bodyfusion.results.run_result"]
    assert "bodyfusion.core.registry" in GRAPH["bodyfusion.core.layout"]  # from bodyfusion.core import registry


def _layer_map() -> list[str]:
    """The code block under "## Layers" in docs/architecture.md: the package map."""
    text = (PACKAGE.parents[1] / "docs" / "architecture.md").read_text()
    section = text.split("## Layers", 1)[1]
    return section.split("```", 2)[1].splitlines()[1:]


def _package_text(lines: list[str], package: str) -> str:
    """The map's lines for ``package`` (``foot_ins/``): its own line and those indented below it."""
    for k, line in enumerate(lines):
        if line.strip().split(" ")[0] == package:
            indent = len(line) - len(line.lstrip())
            out = [line]
            for nxt in lines[k + 1:]:
                if nxt.strip() and len(nxt) - len(nxt.lstrip()) <= indent:
                    break
                out.append(nxt)
            return "\n".join(out)
    return ""


def test_the_module_map_names_every_module():
    """docs/architecture.md's map names every module under its own package's entry."""
    import re

    lines = _layer_map()
    missing = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.name in ("__init__.py", "__main__.py"):
            continue
        where = _package_text(lines, rel.parts[-2] + "/") if len(rel.parts) > 1 else "\n".join(lines)
        if not re.search(rf"\b{re.escape(rel.stem)}\b", where):
            missing.append(str(rel))
    assert not missing, missing
