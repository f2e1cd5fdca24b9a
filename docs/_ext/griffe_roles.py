"""Griffe extension for the API reference: the docstrings' Sphinx roles as cross-references.

The docstrings write ``:func:`load_layout```, ``:class:`~bodyfusion.results.run_result.RunResult```,
``:meth:`SensorSystem.advance```... Markdown knows no roles, so each becomes a code span linked
to the object's entry in the reference: the name is resolved in the docstring's own scope (its
module's imports, its class's members) as Sphinx would, and the link is an optional
cross-reference (a name the reference does not render stays plain code, without a warning).
A trailing ``::`` (a reStructuredText literal block follows) becomes ``:``; the indented block
after it is already a Markdown code block.
"""

from __future__ import annotations

import html
import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?:mod|func|class|meth|data|attr|exc|obj|const):`(~?)([^`<>]+?)(?:\(\))?`")
LITERAL_BLOCK = re.compile(r"(\S)::$", re.MULTILINE)


def _target(obj: griffe.Object, name: str, by_name: dict[str, list[str]]) -> str | None:
    """The full path of ``name`` as seen from ``obj``'s docstring, or None.

    A name the docstring's scope does not know (the package root's lazily loaded names) is
    taken as the one object of the package with that name, if there is exactly one."""
    head, _, tail = name.partition(".")
    if head == obj.package.name:
        return name
    try:
        path = obj.resolve(head)
    except (griffe.NameResolutionError, ValueError):
        paths = by_name.get(head, [])
        if len(paths) != 1:
            return None
        path = paths[0]
    return f"{path}.{tail}" if tail else path


def rewrite(obj: griffe.Object, text: str, by_name: dict[str, list[str]]) -> str:
    """``text`` with its roles as linked code spans and ``::`` literal-block markers as ``:``."""

    def link(match: re.Match[str]) -> str:
        short, name = match.group(1) == "~", match.group(2).strip()
        title = name.rsplit(".", 1)[-1] if short else name
        target = _target(obj, name, by_name)
        code = f"<code>{html.escape(title)}</code>"
        if target is None:
            return code
        return f'<autoref identifier="{html.escape(target)}" optional>{code}</autoref>'

    return LITERAL_BLOCK.sub(r"\1:", ROLE.sub(link, text))


class SphinxRoles(griffe.Extension):
    """Rewrites every docstring of a loaded package once the whole package is known."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        objects: list[griffe.Object] = []
        self._collect(pkg, objects)
        by_name: dict[str, list[str]] = {}
        for obj in objects:
            by_name.setdefault(obj.name, []).append(obj.path)
        for obj in objects:
            if obj.docstring is not None:
                obj.docstring.value = rewrite(obj, obj.docstring.value, by_name)

    def _collect(self, obj: griffe.Object, objects: list[griffe.Object]) -> None:
        objects.append(obj)
        for member in obj.members.values():
            if not member.is_alias:
                self._collect(member, objects)
