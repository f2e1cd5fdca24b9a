"""The documentation rule: which parameters of a plugin's ``Config`` are not documented.

The ``documented`` conformance check applies :func:`undocumented_fields` to a plugin's
``Config``; the rule is in its docstring.
"""

from __future__ import annotations

import ast
import inspect
import re
import textwrap
import typing
from typing import Any

from pydantic import BaseModel

from bodyfusion.base.sections import StrictModel

UNIT_SUFFIXES = ("m", "m2", "s", "hz", "mps", "mps2", "deg", "rad", "radps", "pa", "hpa", "k", "pct")
"""Unit suffixes a field name may end with (``_m``, ``_hz``...): a docstring may name the field without it."""


def _own_doc(cls: type) -> str:
    return cls.__dict__.get("__doc__") or ""


def _config_classes(model: type[BaseModel]) -> list[type]:
    """The model and its bases that are layout sections (not pydantic/core plumbing)."""
    return [c for c in model.__mro__ if isinstance(c, type) and issubclass(c, BaseModel)
            and c not in (BaseModel, StrictModel)]


def _attribute_docstrings(model: type[BaseModel]) -> dict[str, str]:
    """Field name → the string literal right below its annotation in the class body."""
    out: dict[str, str] = {}
    for cls in reversed(_config_classes(model)):
        try:
            tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
        except (OSError, TypeError, SyntaxError):
            continue
        body = tree.body[0].body if tree.body and isinstance(tree.body[0], ast.ClassDef) else []
        for stmt, nxt in zip(body, body[1:]):
            if (isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name)
                    and isinstance(nxt, ast.Expr) and isinstance(nxt.value, ast.Constant)
                    and isinstance(nxt.value.value, str) and nxt.value.value.strip()):
                out[stmt.target.id] = nxt.value.value
    return out


def _stem(name: str) -> str:
    parts = name.split("_")
    if len(parts) > 1 and parts[-1] in UNIT_SUFFIXES:
        parts = parts[:-1]
    return " ".join(parts)


def _mentions(doc: str, name: str) -> bool:
    text = doc.lower().replace("`", " ")
    if re.search(rf"(?<![a-z0-9_]){re.escape(name.lower())}(?![a-z0-9_])", text):
        return True
    stem = r"[\s_]+".join(re.escape(w) for w in _stem(name).lower().split())
    return bool(re.search(rf"(?<![a-z0-9_]){stem}(?![a-z0-9])", text))


def nested_models(annotation: Any) -> list[type[BaseModel]]:
    """The pydantic models a field's annotation holds (itself, or inside Optional, list, dict...)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    out: list[type[BaseModel]] = []
    for arg in typing.get_args(annotation):
        out.extend(nested_models(arg))
    return out


def undocumented_fields(model: type[BaseModel]) -> list[str]:
    """Dotted paths of the fields of ``model`` (nested models included) that are not documented.

    A field counts as documented when any of these holds:

    1. it has a description: ``Field(description=...)``, or an attribute docstring (a
       string literal on the line after the field, which pydantic also reads with
       ``use_attribute_docstrings=True``);
    2. the docstring of its model class (or of a base) names it: the field name itself,
       or its name without a trailing unit suffix (``_m``, ``_s``, ``_hz``, ``_mps``,
       ``_deg``, ``_pa``...) with underscores read as spaces, as whole words,
       case-insensitive (``duration_s`` is documented by "… duration (s) …");
    3. it holds a nested model (optionally, or in a list/dict) whose class has its own
       docstring; that model's fields are then checked in turn under ``field.``;
    4. it is the top-level ``plugin`` key, which the core documents.
    """
    missing: list[str] = []
    seen: set[type] = set()

    def walk(m: type[BaseModel], prefix: str) -> None:
        if m in seen:
            return
        seen.add(m)
        doc = " ".join(_own_doc(c) for c in _config_classes(m))
        attr_docs = _attribute_docstrings(m)
        for fname, finfo in m.model_fields.items():
            nested = nested_models(finfo.annotation)
            ok = (bool((finfo.description or "").strip()) or fname in attr_docs or _mentions(doc, fname)
                  or (bool(nested) and all(_own_doc(n).strip() for n in nested))
                  or (prefix == "" and fname == "plugin"))
            if not ok:
                missing.append(prefix + fname)
            for n in nested:
                walk(n, f"{prefix}{fname}.")

    walk(model, "")
    return missing
