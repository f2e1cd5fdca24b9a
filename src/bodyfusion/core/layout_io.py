"""Layout files as data: YAML read with size and alias limits, dotted overrides, a section
validated with one-line errors naming its dotted key, and models turned back into plain data.
The layout's models (:mod:`bodyfusion.core.layout`) stand on these; nothing here knows them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, ValidationError

from bodyfusion.base.errors import ConfigError
from bodyfusion.base.files import file_problem
from bodyfusion.base.sections import KeyedError


def _dotted(loc: tuple[Any, ...]) -> str:
    return ".".join(str(p) for p in loc if p not in ("function-after", "function-before"))


def _data_location(loc: tuple[Any, ...], data: Any) -> tuple[Any, ...]:
    """The part of a pydantic error location that names keys of the user's data
    (drops union-member tags such as ``float`` that pydantic appends)."""
    kept: list[Any] = []
    node = data
    for part in loc:
        if isinstance(node, dict):
            kept.append(part)
            if part not in node:  # a missing or unknown key is still the user's key
                break
            node = node[part]
        elif isinstance(node, (list, tuple)) and isinstance(part, int) and part < len(node):
            kept.append(part)
            node = node[part]
        else:
            break
    return tuple(kept)


def _errors(err: ValidationError, prefix: str = "", data: Any = None) -> list[tuple[str, str]]:
    """(dotted key, reason) of every error pydantic found."""
    return [_keyed(e, prefix, data) for e in err.errors(include_url=False)]


def _keyed(e: dict, prefix: str, data: Any) -> tuple[str, str]:
    loc = _dotted(_data_location(e["loc"], data) if data is not None else e["loc"])
    ctx_err = (e.get("ctx") or {}).get("error")
    if isinstance(ctx_err, KeyedError):  # its key is relative to the section that raised it
        return ".".join(p for p in (prefix, loc, ctx_err.key) if p), str(ctx_err)
    msg = e["msg"]
    if e["type"] == "extra_forbidden":
        msg = "unknown key"
    elif msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    key = ".".join(p for p in (prefix, loc) if p)
    return key, msg


def validate_section(model: type[BaseModel], data: Any, *, key: str, path: Path | None, base_dir: Path | None) -> Any:
    """Validate ``data`` with ``model``; errors become a one-line :class:`ConfigError` under ``key``
    (the first; every other one in its ``others``)."""
    try:
        return model.model_validate(data, context={"base_dir": base_dir})
    except ValidationError as err:
        raise ConfigError.of([ConfigError(k, msg, path) for k, msg in _errors(err, key, data)]) from None


def parse_override(item: str) -> tuple[str, Any]:
    """``a.b.c=VALUE`` → (``a.b.c``, VALUE parsed as YAML)."""
    if "=" not in item:
        raise ConfigError(item, "override must be KEY=VALUE, e.g. fuser.method=none")
    key, raw = item.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError(key, "empty part in the dotted key")
    try:
        value = yaml.safe_load(raw) if raw.strip() else None
    except yaml.YAMLError:
        value = raw
    return key, value


def _unshared_copy(node: Any) -> Any:
    """Copy dicts and lists without keeping YAML aliases shared (unlike ``copy.deepcopy``)."""
    if isinstance(node, dict):
        return {k: _unshared_copy(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_unshared_copy(v) for v in node]
    return node


def apply_overrides(raw: dict[str, Any], overrides: Sequence[str] | Mapping[str, Any]) -> dict[str, Any]:
    """Set dotted paths in a raw layout dict (lists by integer index); returns a copy. Overrides
    are ``KEY=VALUE`` strings (VALUE read as YAML) or a mapping of dotted key → value."""
    out = _unshared_copy(raw)
    pairs = overrides.items() if isinstance(overrides, Mapping) else map(parse_override, overrides)
    for key, value in pairs:
        if not key or any(not part for part in key.split(".")):
            raise ConfigError(key, "empty part in the dotted key")
        node: Any = out
        parts = key.split(".")
        for depth, part in enumerate(parts):
            last = depth == len(parts) - 1
            here = ".".join(parts[: depth + 1])
            if isinstance(node, list):
                if not part.isdigit() or int(part) >= len(node):
                    raise ConfigError(here, f"no list item {part} (the list has {len(node)})")
                idx = int(part)
                if last:
                    node[idx] = value
                else:
                    node = node[idx]
            elif isinstance(node, dict):
                if last:
                    node[part] = value
                else:
                    if depth == 1 and parts[0] == "systems" and part not in node:
                        raise ConfigError(here, f"unknown system (have {sorted(node)}); a new system is set "
                                                f"whole: --set 'systems.{part}={{plugin: ..., ...}}'")
                    if node.get(part) is None:
                        node[part] = {}
                    node = node[part]
            else:
                raise ConfigError(here, "cannot set a key inside a plain value")
    return out


MAX_YAML_BYTES = 4 * 1024 * 1024
"""Largest layout, scenario or study file read, bytes (real ones are a few kB)."""
MAX_YAML_NODES = 100_000
"""Most YAML nodes a file may hold once its aliases are expanded (an alias "bomb" is refused
before it is built; real layouts hold a few hundred)."""
MAX_YAML_DEPTH = 32
"""Deepest nesting of mappings and lists a file may hold (real layouts: about 6)."""


class _UniqueKeyLoader(yaml.SafeLoader):
    """SafeLoader that refuses a key repeated in one mapping (two systems with one name) and
    a key that is not a plain value (a YAML complex key such as ``? [a, b]``)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            if not isinstance(key_node, yaml.ScalarNode):
                raise yaml.constructor.ConstructorError(None, None, "a mapping key must be a plain value",
                                                        key_node.start_mark)
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(None, None, f"key {key!r} appears twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _expanded_size(node: yaml.Node, memo: dict[int, int]) -> int:
    """Nodes in the document once every alias is expanded, counted without expanding
    (shared nodes counted once per reference; capped so a bomb stops the count early)."""
    key = id(node)
    if key in memo:
        return memo[key]
    memo[key] = MAX_YAML_NODES + 1  # a node reached again while being counted: a cycle
    if isinstance(node, yaml.MappingNode):
        size = 1 + sum(_expanded_size(k, memo) + _expanded_size(v, memo) for k, v in node.value)
    elif isinstance(node, yaml.SequenceNode):
        size = 1 + sum(_expanded_size(v, memo) for v in node.value)
    else:
        size = 1
    memo[key] = min(size, MAX_YAML_NODES + 1)
    return memo[key]


def _depth(node: yaml.Node) -> int:
    """How deep collections nest in the document (1: a scalar), walked without recursion."""
    deepest, stack, seen = 0, [(node, 1)], set()
    while stack:
        item, depth = stack.pop()
        deepest = max(deepest, depth)
        if id(item) in seen or depth > MAX_YAML_DEPTH:
            continue
        seen.add(id(item))
        if isinstance(item, yaml.MappingNode):
            stack.extend((v, depth + 1) for _, v in item.value)
        elif isinstance(item, yaml.SequenceNode):
            stack.extend((v, depth + 1) for v in item.value)
    return deepest


def _text(path: Path, raw: bytes) -> str:
    """The file's bytes as UTF-8 (a byte-order mark dropped); anything else is refused naming
    the line and byte."""
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[:err.start].count(b"\n") + 1
        raise ConfigError("", f"not UTF-8 text (byte 0x{raw[err.start]:02x} at offset {err.start}): save the file as "
                              "UTF-8", f"{path}:{line}") from None


def read_yaml(path: Path) -> dict[str, Any]:
    """Read a YAML mapping; syntax errors name the file and line. A file over
    :data:`MAX_YAML_BYTES`, not UTF-8, nested deeper than :data:`MAX_YAML_DEPTH` or over
    :data:`MAX_YAML_NODES` nodes once its aliases are expanded is refused before anything is
    built."""
    try:
        problem = file_problem(path)
        if problem is not None:
            raise ConfigError("", problem, path)
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise ConfigError("", f"{size} bytes: larger than a layout can be ({MAX_YAML_BYTES} bytes)", path)
        text = _text(path, path.read_bytes())
    except FileNotFoundError:
        raise ConfigError("", "file not found", path) from None
    except OSError as err:
        raise ConfigError("", f"cannot read: {err.strerror}", path) from None
    too_deep = ConfigError("", f"collections nested deeper than {MAX_YAML_DEPTH} levels: not a layout", path)
    try:
        loader = _UniqueKeyLoader(text)
        try:
            node = loader.get_single_node()
            if node is not None and _depth(node) > MAX_YAML_DEPTH:
                raise too_deep
            if node is not None and _expanded_size(node, {}) > MAX_YAML_NODES:
                raise ConfigError("", f"more than {MAX_YAML_NODES} YAML nodes once its aliases are expanded", path)
            raw = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except RecursionError:  # the parser recurses per level: nesting it cannot follow
        raise too_deep from None
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        problem = getattr(err, "problem", None) or "invalid YAML"
        raise ConfigError("", f"YAML syntax: {problem}", where) from None
    if not isinstance(raw, dict):
        raise ConfigError("", "the file must hold a YAML mapping", path)
    return raw


def plain(node: Any, base_dir: Path | None = None) -> Any:
    """Models, tuples and paths as plain YAML/JSON values: dicts, lists, strings (a path under
    ``base_dir`` relative to it)."""
    if isinstance(node, BaseModel):
        node = node.model_dump()
    if isinstance(node, dict):
        return {str(k): plain(v, base_dir) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [plain(v, base_dir) for v in node]
    if isinstance(node, Path):
        if base_dir is not None and node.is_relative_to(base_dir):
            return node.relative_to(base_dir).as_posix()
        return node.as_posix()
    return node
