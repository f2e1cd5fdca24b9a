"""Reader of UWB range logs: ``t, id, range_m`` rows (CSV with a header line).

Policies (counted in the :class:`bodyfusion.base.types.InputReport` and the tag's diagnostics):
failed rangings (empty or NaN range) and negative ranges are dropped; a row whose time is
earlier than the row before it is dropped (several ranges may share one time). Anything
else wrong with a row — a missing or non-numeric cell, an infinite value, an id the layout
does not name — stops with a one-line :class:`bodyfusion.base.errors.InputError` naming the file
and line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.io.tables import clean_cell, read_lines, split_line
from bodyfusion.base.types import InputReport


@dataclass
class RangeLog:
    """Ranges in time order. t (K,) s; end (K,) index into the ids the reader was given;
    range_m (K,) m; nlos (K,) truth flags or None; ``dropped``: counts per policy."""

    t: np.ndarray
    end: np.ndarray
    range_m: np.ndarray
    nlos: np.ndarray | None
    dropped: dict[str, int] = field(default_factory=dict)
    report: InputReport = field(default_factory=InputReport)

    def __len__(self) -> int:
        return len(self.t)


def _number(path: Path, cell: str, column: str, line: int) -> float:
    try:
        return float(cell)
    except ValueError:
        raise InputError(path, f"non-numeric value {cell!r} in column {column!r}", line) from None


def read_ranges(path: str | Path, ids: list[str], *, time_column: str = "t", id_column: str = "id",
                range_column: str = "range_m", nlos_column: str | None = None, delimiter: str = ",") -> RangeLog:
    """Read a range log; ``ids`` are the ends the layout names (anchors, then peers)."""
    path = Path(path)
    lines = read_lines(path)
    if not lines or not lines[0].strip():
        raise InputError(path, "empty file: no header line", 1)
    header = [clean_cell(h) for h in split_line(lines[0], delimiter)]
    wanted = [time_column, id_column, range_column] + ([nlos_column] if nlos_column else [])
    cols = []
    for name in wanted:
        if header.count(name) != 1:
            why = "missing column" if name not in header else "repeated column"
            raise InputError(path, f"{why} {name!r}; the header has: " + ", ".join(repr(h) for h in header), 1)
        cols.append(header.index(name))
    lookup = {name: k for k, name in enumerate(ids)}
    t, end, rng, nlos = [], [], [], []
    dropped = {"failed": 0, "negative": 0, "out_of_order": 0}
    t_last = -math.inf
    for line_no, text in enumerate(lines[1:], start=2):
        if not text.strip():
            continue
        cells = split_line(text, delimiter)
        if len(cells) <= max(cols):
            raise InputError(path, f"row has {len(cells)} fields, the header has {len(header)}", line_no)
        ti = _number(path, clean_cell(cells[cols[0]]), time_column, line_no)
        if not math.isfinite(ti):
            raise InputError(path, f"non-finite time {ti!r}", line_no)
        who = clean_cell(cells[cols[1]])
        if who not in lookup:
            raise InputError(path, f"id {who!r} is neither an anchor nor a peer of this tag "
                                   f"(the layout names {', '.join(ids)})", line_no)
        cell = clean_cell(cells[cols[2]])
        ri = math.nan if cell == "" else _number(path, cell, range_column, line_no)
        if math.isinf(ri):
            raise InputError(path, f"infinite value in column {range_column!r}", line_no)
        if ti < t_last:
            dropped["out_of_order"] += 1
            continue
        t_last = ti
        if math.isnan(ri):
            dropped["failed"] += 1
            continue
        if ri < 0:
            dropped["negative"] += 1
            continue
        t.append(ti)
        end.append(lookup[who])
        rng.append(ri)
        if nlos_column:
            nlos.append(_number(path, clean_cell(cells[cols[3]]), nlos_column, line_no) != 0)
    total = sum(dropped.values())
    notes = [f"{path.name}: dropped {dropped['failed']} failed rangings (empty/NaN), {dropped['negative']} negative, "
             f"{dropped['out_of_order']} out of time order"] if total else []
    return RangeLog(np.asarray(t, dtype=float), np.asarray(end, dtype=np.int64), np.asarray(rng, dtype=float),
                    np.asarray(nlos, dtype=bool) if nlos_column else None, dropped,
                    InputReport(dropped_samples=total, notes=notes))
