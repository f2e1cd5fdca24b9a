"""The files a layout names, looked at without reading them: each file's dotted key and path,
what a run could not read of them (missing files, special files, table columns the layout names
and the header lacks: ``fusion validate`` lists them all) and each timed file's first and last
time, read from its ends only, so that files on different clocks are caught before a run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel

from bodyfusion.base.files import file_problem
from bodyfusion.base.sections import TableSection
from bodyfusion.core.layout import LoadedLayout, TruthConfig
from bodyfusion.io.tables import file_header, file_time_span


def layout_nodes(loaded: LoadedLayout) -> list[tuple[str, Any]]:
    """(dotted key, value) of every node of the truth section and the systems' sections."""
    found: list[tuple[str, Any]] = []

    def walk(node: Any, key: str) -> None:
        found.append((key, node))
        if isinstance(node, BaseModel):
            for name in type(node).model_fields:
                walk(getattr(node, name), f"{key}.{name}" if key else name)
        elif isinstance(node, dict):
            for name, value in node.items():
                walk(value, f"{key}.{name}" if key else str(name))
        elif isinstance(node, (list, tuple)):
            for k, value in enumerate(node):
                walk(value, f"{key}.{k}")

    walk(loaded.layout.truth, "truth")
    for name, cfg in loaded.system_configs.items():
        walk(cfg, f"systems.{name}")
    return found


def data_files(loaded: LoadedLayout) -> list[tuple[str, Path]]:
    """(dotted key, path) of every file the layout names (its data, truth, fixes...), for a
    check that needs no reading: ``fusion validate`` refuses a layout whose files are missing."""
    return [(key, node) for key, node in layout_nodes(loaded) if isinstance(node, Path)]


def file_problems(loaded: LoadedLayout) -> list[tuple[str, str]]:
    """(dotted key, problem) of every file the layout names that a run could not read (missing,
    a FIFO, a device, a folder: :func:`~bodyfusion.base.files.file_problem`), and of every table
    file whose header lacks a column its section names
    (:meth:`~bodyfusion.base.sections.TableSection.required_columns`): all of them, read from the
    files' first lines only."""
    recordings = {f"{key}.path" for key, node in layout_nodes(loaded)
                  if isinstance(node, TableSection) and node.topic is not None}

    def problem(key: str, path: Path) -> str | None:
        if key in recordings:  # a ROS 2 bag is a folder
            return None if path.exists() else "file not found"
        return file_problem(path)

    problems = [(key, f"{path}: {why}") for key, path in data_files(loaded) if (why := problem(key, path)) is not None]
    bad = {key for key, _ in problems}
    for key, node in layout_nodes(loaded):
        path = getattr(node, "path", None)
        if not isinstance(node, TableSection) or not isinstance(path, Path) or f"{key}.path" in bad \
                or node.topic is not None or node.group is not None:  # no header line: known once read
            continue
        wanted = node.required_columns()
        if not wanted:
            continue
        header = file_header(path, delimiter=getattr(node, "delimiter", ","), skip_rows=getattr(node, "skip_rows", 0))
        if header is None:
            problems.append((f"{key}.path", f"{path}: no header line to read"))
            continue
        missing = [c for c in dict.fromkeys(wanted) if c not in header]
        if missing:
            shown = ", ".join(header[:12]) + (", ..." if len(header) > 12 else "")
            problems.append((key, f"{path.name} has no column(s) {', '.join(missing)} (it has {shown})"))
    return problems


def time_spans(loaded: LoadedLayout) -> dict[str, tuple[float, float]]:
    """Dotted key of each file section with a time column → the (first, last) time in it (s),
    read from the file's ends only (:func:`bodyfusion.io.tables.file_time_span`)."""
    spans = {}
    for key, node in layout_nodes(loaded):
        path = getattr(node, "path", None)
        column = "t" if isinstance(node, TruthConfig) and node.format == "long" else getattr(node, "time_column", None)
        if isinstance(node, BaseModel) and isinstance(path, Path) and isinstance(column, str):
            span = file_time_span(path, column, time_scale=getattr(node, "time_scale", 1.0),
                                  delimiter=getattr(node, "delimiter", ","), skip_rows=getattr(node, "skip_rows", 0))
            if span is not None:
                spans[key] = span
    return spans


def disjoint_time_bases(loaded: LoadedLayout) -> list[str]:
    """Lines naming the layout's timed files whose time spans do not overlap — every file of a
    layout is on one clock (docs/contract.md), so such files are a clock or ``time_scale``
    mistake a run would otherwise meet as fixes or ranges never used: first each file that
    overlaps none of the others (of three or more), then each other disjoint pair."""
    spans = time_spans(loaded)
    keys = sorted(spans)

    def disjoint(a: str, b: str) -> bool:
        return spans[a][1] < spans[b][0] or spans[b][1] < spans[a][0]

    def span(k: str) -> str:
        return f"{k} ({spans[k][0]:.6g}–{spans[k][1]:.6g} s)"

    alone = [k for k in keys if len(keys) > 2 and all(disjoint(k, o) for o in keys if o != k)]
    rest = [k for k in keys if k not in alone]
    return ([f"{span(k)} overlaps no other file of the layout in time: is it on their clock?" for k in alone]
            + [f"{span(a)} and {span(b)} do not overlap in time: are they on one clock?"
               for i, a in enumerate(rest) for b in rest[i + 1:] if disjoint(a, b)])
