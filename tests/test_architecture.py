"""The package layout keeps its promises: imports run one way (no circle among modules, the core,
the navigation toolbox, I/O and the base layer never import a plugin) and no module grows
past the size a reader takes in at once."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "bodyfusion"
MAX_LINES = 600
SENSOR_FREE = ("base", "core", "nav", "io", "evaluation")
"""Packages that know no sensor: none of them may import :mod:`bodyfusion.plugins`."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _top_level_imports(path: Path) -> set[str]:
    """The bodyfusion modules a module imports when it is imported (module level and class
    bodies; not inside functions, not under ``if TYPE_CHECKING``)."""
    tree = ast.parse(path.read_text(), str(path))
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()

    def visit(nodes: list[ast.stmt]) -> None:
        for node in nodes:
            if isinstance(node, ast.Import):
                out.update(a.name for a in node.names if a.name.startswith("bodyfusion"))
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                if base.startswith("bodyfusion"):
                    out.add(base)
            elif isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                continue
            elif isinstance(node, (ast.If, ast.Try, ast.ClassDef)):
                visit(node.body)
                for extra in getattr(node, "orelse", []), getattr(node, "finalbody", []):
                    visit(extra)
                for handler in getattr(node, "handlers", []):
                    visit(handler.body)

    visit(tree.body)
    return out


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
GRAPH = {name: {m for m in _top_level_imports(path) if m in MODULES and m != name} for name, path in MODULES.items()}


def test_no_import_circle_among_modules():
    """Depth-first search for a back edge in the module-level import graph."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(GRAPH[node]):
            if state.get(nxt) == 1:
                return [*stack[stack.index(nxt):], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for name in sorted(GRAPH):
        if name not in state:
            cycle = visit(name)
            assert cycle is None, " -> ".join(cycle)


@pytest.mark.parametrize("layer", SENSOR_FREE)
def test_layers_that_know_no_sensor_import_no_plugin(layer):
    offenders = {name: sorted(m for m in imports if m.startswith("bodyfusion.plugins"))
                 for name, imports in GRAPH.items() if name.startswith(f"bodyfusion.{layer}")}
    assert not {k: v for k, v in offenders.items() if v}


def test_no_module_over_six_hundred_lines():
    long = {name: n for name, path in MODULES.items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_the_graph_sees_imports():
    """The checks above are not vacuous: known edges are found."""
    assert "bodyfusion.nav.error_state" in GRAPH["bodyfusion.plugins.foot_ins.kernels"]
    assert "bodyfusion.core.layout" in GRAPH["bodyfusion.plugins.foot_ins.config"]


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
