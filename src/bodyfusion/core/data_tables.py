"""The tables a layout reads, by the dotted key of their section: every
:class:`~bodyfusion.base.sections.TableSection` of the layout (the truth, each system's data
sections), in-memory tables bound to them, and the sections left with neither a file nor a table."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import TableSection


def table_sections(layout: BaseModel, system_configs: Mapping[str, BaseModel]) -> dict[str, TableSection]:
    """Dotted key → table section, for the layout's truth and every system's sections."""
    found: dict[str, TableSection] = {}

    def walk(node: Any, key: str) -> None:
        if isinstance(node, TableSection):
            found[key] = node
        if isinstance(node, BaseModel):
            for name in type(node).model_fields:
                walk(getattr(node, name), f"{key}.{name}")

    walk(getattr(layout, "truth", None), "truth")
    for name, cfg in system_configs.items():
        walk(cfg, f"systems.{name}")
    return found


def bind_tables(layout: BaseModel, system_configs: Mapping[str, BaseModel], tables: Mapping[str, Any],
                path: Path | None) -> None:
    """Bind each in-memory table to the section its dotted key names (an error names a key that
    is no table section, and the keys there are)."""
    sections = table_sections(layout, system_configs)
    for key, table in tables.items():
        if key not in sections:
            raise ConfigError(key, f"no table section here to take an in-memory table (the layout's: "
                                   f"{', '.join(sections) or 'none'})", path)
        sections[key].bind(table, key)


def require_data(layout: BaseModel, system_configs: Mapping[str, BaseModel], path: Path | None) -> None:
    """Refuse a section that reads data but names no file and has no in-memory table."""
    for key, section in table_sections(layout, system_configs).items():
        if section.needs_data() and section.path is None and section.table is None:
            raise ConfigError(f"{key}.path", "Field required: a file, or the table in memory "
                                             "(bodyfusion.run(..., data=...))", path)
