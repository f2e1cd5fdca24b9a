"""Hypothesis strategies for corrupted inputs: each draws a short list of edits of a text file
(truncate, insert garbage, non-finite or absurd numbers in a field or a whole column, swapped
or scaled columns, duplicated, deleted or reversed lines, a changed delimiter, time jumps) or
of a layout (a key set to a bad value, deleted, an unknown key added, duplicated keys)."""

from __future__ import annotations

import contextlib
import copy
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pynmea2
from hypothesis import strategies as st

BAD_NUMBERS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-320", "0", "-1", "-0", "1e30", "-1e30",
               "99999999999999999999999", "", " ", "abc", "0x1F", "1,5", "++1", "None", "null"]
"""Field values a corrupted file may hold."""

GARBAGE_LINES = ["nan,nan,nan,nan,nan,nan,nan", ",,,,,,,,", "\x00\x00\x00", "1e999,1,2,3,4,5,6", "9" * 5000,
                 "t,acc_x,acc_y,acc_z,gyro_x,gyro_y,gyro_z", "ACCE;1;2;3", "GNSS;;;;;;;;;;",
                 "$GPGGA,,,,,,0,,,,,,,,*66", "$GPGGA,250000.00,9999.0,N,99999.0,E,1,09,1.0,1e9,M,,M,,*00",
                 "POSI;1;1;91;181;0;1", "\ufeff", "% comment", "   ", "\t\t", "; ;"]


def _lines(text: str) -> list[str]:
    return text.split("\n")


def _at(frac: float, n: int) -> int:
    return min(int(frac * n), max(n - 1, 0))


def _edit_fields(text: str, at: float, count: int, edit: Callable[[list[str]], None]) -> str:
    """``edit`` applied to the fields of ``count`` lines from the fraction ``at`` of the file
    (fields split on ';' or ',', whichever the line has more of)."""
    lines = _lines(text)
    start = _at(at, len(lines))
    for k in range(start, min(start + count, len(lines))):
        sep = ";" if lines[k].count(";") > lines[k].count(",") else ","
        fields = lines[k].split(sep)
        edit(fields)
        lines[k] = sep.join(fields)
    return "\n".join(lines)


@dataclass(frozen=True)
class Truncate:
    at: float

    def __call__(self, text: str) -> str:
        return text[: int(self.at * len(text))]


@dataclass(frozen=True)
class InsertGarbage:
    at: float
    garbage: str

    def __call__(self, text: str) -> str:
        lines = _lines(text)
        lines.insert(_at(self.at, len(lines) + 1), self.garbage)
        return "\n".join(lines)


@dataclass(frozen=True)
class SetField:
    """One field of ``count`` lines from ``at`` set to ``value`` (``count`` large: a whole column)."""
    at: float
    count: int
    field: int
    value: str

    def __call__(self, text: str) -> str:
        def edit(fields: list[str]) -> None:
            fields[self.field % len(fields)] = self.value

        return _edit_fields(text, self.at, self.count, edit)


@dataclass(frozen=True)
class ScaleField:
    """A numeric field of every line from ``at`` multiplied by ``factor`` or shifted by ``offset``
    (a unit mistake, a time jump)."""
    at: float
    field: int
    factor: float
    offset: float

    def __call__(self, text: str) -> str:
        def edit(fields: list[str]) -> None:
            j = self.field % len(fields)
            with contextlib.suppress(ValueError):
                fields[j] = repr(float(fields[j]) * self.factor + self.offset)

        return _edit_fields(text, self.at, len(text), edit)


@dataclass(frozen=True)
class SwapFields:
    """Fields ``i`` and ``j`` swapped in every line (``header_only``: only in the first line, a
    mislabelled header)."""
    i: int
    j: int
    header_only: bool

    def __call__(self, text: str) -> str:
        def edit(fields: list[str]) -> None:
            a, b = self.i % len(fields), self.j % len(fields)
            fields[a], fields[b] = fields[b], fields[a]

        return _edit_fields(text, 0.0, 1 if self.header_only else len(text), edit)


@dataclass(frozen=True)
class EditLines:
    """``count`` lines from ``at`` duplicated, deleted, reversed or given another delimiter."""
    at: float
    count: int
    how: str

    def __call__(self, text: str) -> str:
        lines = _lines(text)
        a = _at(self.at, len(lines))
        b = min(a + self.count, len(lines))
        block = lines[a:b]
        if self.how == "duplicate":
            block = block + block
        elif self.how == "delete":
            block = []
        elif self.how == "reverse":
            block = block[::-1]
        elif self.how == "delimiter":
            block = [line.replace(",", "\t").replace(";", ",") for line in block]
        return "\n".join(lines[:a] + block + lines[b:])


@dataclass(frozen=True)
class Recode:
    """The whole file: emptied, CRLF line ends, a byte-order mark, or bytes that are not UTF-8."""
    how: str

    def __call__(self, text: str) -> str:
        return {"empty": "", "crlf": text.replace("\n", "\r\n"), "bom": "\ufeff" + text,
                "latin1": text.replace("0", "\udcb0", 3)}[self.how]


@dataclass(frozen=True)
class Rechecksum:
    """NMEA checksums recomputed after the edits, so the edited sentences reach the parser."""

    def __call__(self, text: str) -> str:
        out = []
        for line in _lines(text):
            if line.startswith("$") and "*" in line:
                body = line[1:line.rindex("*")]
                line = f"${body}*{pynmea2.NMEASentence.checksum(body):02X}"
            out.append(line)
        return "\n".join(out)


fraction = st.floats(0.0, 1.0, allow_nan=False)
field = st.integers(0, 11)
text_edit = st.one_of(
    st.builds(Truncate, fraction),
    st.builds(InsertGarbage, fraction, st.one_of(st.sampled_from(GARBAGE_LINES), st.text(max_size=60))),
    st.builds(SetField, fraction, st.sampled_from([1, 3, 50, 100_000]), field, st.sampled_from(BAD_NUMBERS)),
    st.builds(ScaleField, fraction, field, st.sampled_from([1.0, -1.0, 0.0, 1e-3, 57.29578, 1000.0, 1e12]),
              st.sampled_from([0.0, -1e9, -10.0, -0.005, 0.005, 3600.0, 1e9, 1e30])),
    st.builds(SwapFields, field, field, st.booleans()),
    st.builds(EditLines, fraction, st.sampled_from([1, 2, 10, 200, 5000]),
              st.sampled_from(["duplicate", "delete", "reverse", "delimiter"])),
    st.builds(Recode, st.sampled_from(["empty", "crlf", "bom", "latin1"])),
)
text_edits = st.lists(text_edit, min_size=1, max_size=3)
nmea_edits = st.tuples(text_edits, st.booleans()).map(lambda p: p[0] + [Rechecksum()] * p[1])

BAD_VALUES: list[Any] = [math.nan, math.inf, -math.inf, 0, -1, 1e300, -1e300, 1e-300, 10**20, 0.5, 1_000_000,
                         "", "abc", None, True, [], {}, [0, 0], [1e9, 1e9, 1e9], {"x": 1}]
"""Values a corrupted layout may give a key."""


def key_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a nested mapping/list, in document order."""
    out = []
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        out.append(prefix + (key,))
        out += key_paths(value, prefix + (key,))
    return out


@dataclass(frozen=True)
class LayoutEdit:
    """The key at ``at`` (a fraction of the layout's key paths) set to ``value``, deleted, or
    given an unknown sibling."""
    at: float
    how: str
    value: Any

    def __call__(self, doc: dict) -> None:
        paths = key_paths(doc)
        path = paths[_at(self.at, len(paths))]
        parent = doc
        for key in path[:-1]:
            parent = parent[key]
        if self.how == "set":
            parent[path[-1]] = copy.deepcopy(self.value)
        elif self.how == "delete":
            del parent[path[-1]]
        elif isinstance(parent, dict):
            parent[f"unknown_{len(parent)}"] = copy.deepcopy(self.value)


layout_edit = st.builds(LayoutEdit, fraction, st.sampled_from(["set", "delete", "unknown"]),
                        st.sampled_from(BAD_VALUES))
layout_edits = st.tuples(st.lists(layout_edit, min_size=1, max_size=3),
                         st.lists(st.one_of(st.builds(Truncate, fraction),
                                            st.builds(EditLines, fraction, st.sampled_from([1, 2, 5]),
                                                      st.sampled_from(["duplicate", "delete"]))), max_size=1))
"""Edits of the parsed layout, then at most one edit of its YAML text (duplicated keys, a cut)."""
