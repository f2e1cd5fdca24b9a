"""Inputs for a plugin's conformance test: a layout context, and configs with one value changed."""

from __future__ import annotations

import copy
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bodyfusion.core.system import LayoutContext


def default_context(base_dir: str | Path = ".", seed: int = 0) -> LayoutContext:
    """A layout context for tests: g = 9.80665 m/s², latitude 45°, paths relative to ``base_dir``."""
    return LayoutContext(gravity_mps2=9.80665, latitude_deg=45.0, base_dir=Path(base_dir).resolve(), seed=seed)


def with_value(config: Mapping[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``config`` with the dotted ``key`` set to ``value`` (to make bad configs)."""
    out = copy.deepcopy(dict(config))
    node: Any = out
    parts = key.split(".")
    for part in parts[:-1]:
        if isinstance(node, list):
            node = node[int(part)]
        else:
            node = node.setdefault(part, {})
    if isinstance(node, list):
        node[int(parts[-1])] = value
    else:
        node[parts[-1]] = value
    return out
