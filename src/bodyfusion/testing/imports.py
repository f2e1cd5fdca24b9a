"""The import graph of a package, read from its source: which module imports which, when it is
imported or anywhere in it (inside functions, for type checking only). The project's
architecture tests check its layers with it (``tests/test_architecture.py``); a plugin package
can check its own (that it imports only the contract of :mod:`bodyfusion.core`, say)."""

from __future__ import annotations

import ast
from pathlib import Path

LAYERS = ("cli", "api", "reproduce", "study", "testing", "examples", "live", "runner", "outputs", "results",
          "evaluation", "plugins", "sim", "io", "core", "nav", "base")
"""bodyfusion's packages from the top down (docs/architecture.md, "Layers"): a package imports
only those below it."""

class ImportGraph:
    """The modules of the package in folder ``root`` (``.../src/bodyfusion``) and their imports
    of one another. ``modules``: dotted name → file."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.package = self.root.name
        self.modules = {self._module_name(p): p for p in sorted(self.root.rglob("*.py"))}

    def _module_name(self, path: Path) -> str:
        parts = path.relative_to(self.root.parent).with_suffix("").parts
        return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)

    def imports(self, module: str, everywhere: bool = False) -> set[str]:
        """The package's modules ``module`` imports when it is imported (module level and class
        bodies; not inside functions, not under ``if TYPE_CHECKING``) or, ``everywhere``,
        anywhere in it. ``from package import name`` counts as importing the module
        ``package.name`` where that is one."""
        path = self.modules[module]
        tree = ast.parse(path.read_text(), str(path))
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        out: set[str] = set()

        def visit(nodes: list[ast.stmt]) -> None:
            for node in nodes:
                if isinstance(node, ast.Import):
                    out.update(a.name for a in node.names if a.name.startswith(self.package))
                elif isinstance(node, ast.ImportFrom):
                    base = node.module or ""
                    if node.level:
                        up = package.split(".")[: len(package.split(".")) - node.level + 1]
                        base = ".".join(up + ([node.module] if node.module else []))
                    if base.startswith(self.package):
                        out.add(base)
                        out.update(f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in self.modules)
                elif isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test) and not everywhere:
                    continue
                elif everywhere and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.With, ast.For,
                                                      ast.While)):
                    visit(node.body)
                    visit(getattr(node, "orelse", []))
                elif isinstance(node, (ast.If, ast.Try, ast.ClassDef)):
                    visit(node.body)
                    for extra in getattr(node, "orelse", []), getattr(node, "finalbody", []):
                        visit(extra)
                    for handler in getattr(node, "handlers", []):
                        visit(handler.body)

        visit(tree.body)
        return {m for m in out if m in self.modules and m != module and not module.startswith(m + ".")}

    def graph(self, everywhere: bool = False) -> dict[str, set[str]]:
        """Module → the modules it imports (:meth:`imports`), less its own parent packages (a
        module's import runs its package's ``__init__`` first; that is no edge of the flow)."""
        return {name: self.imports(name, everywhere) for name in self.modules}

    @staticmethod
    def layer(module: str) -> str | None:
        """The top-level package (or module) of the package a module belongs to: its layer."""
        parts = module.split(".")
        return parts[1] if len(parts) > 1 else None
