"""Reader of UWB range logs: ``t, id, range_m`` rows (CSV with a header line, or the same columns
in an in-memory table).

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
from bodyfusion.base.sections import TableSection
from bodyfusion.base.types import InputReport
from bodyfusion.io.tables import clean_cell, row_error, source_name, split_line, table_columns, table_text_column
from bodyfusion.io.lines import read_lines


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


def _file_rows(path: Path, time_column: str, id_column: str, range_column: str, nlos_column: str | None,
               delimiter: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Times, ids, ranges (NaN: failed), NLOS flags and the line of every row of a range file;
    a malformed row stops with its line."""
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
    t, who, rng, nlos, line_nos = [], [], [], [], []
    for line_no, text in enumerate(lines[1:], start=2):
        if not text.strip():
            continue
        cells = split_line(text, delimiter)
        if len(cells) <= max(cols):
            raise InputError(path, f"row has {len(cells)} fields, the header has {len(header)}", line_no)
        ti = _number(path, clean_cell(cells[cols[0]]), time_column, line_no)
        if not math.isfinite(ti):
            raise InputError(path, f"non-finite time {ti!r}", line_no)
        cell = clean_cell(cells[cols[2]])
        ri = math.nan if cell == "" else _number(path, cell, range_column, line_no)
        if math.isinf(ri):
            raise InputError(path, f"infinite value in column {range_column!r}", line_no)
        t.append(ti)
        who.append(clean_cell(cells[cols[1]]))
        rng.append(ri)
        line_nos.append(line_no)
        if nlos_column:
            nlos.append(_number(path, clean_cell(cells[cols[3]]), nlos_column, line_no))
    return (np.asarray(t, dtype=float), np.asarray(who, dtype=object), np.asarray(rng, dtype=float),
            np.asarray(nlos, dtype=float) if nlos_column else None, np.asarray(line_nos, dtype=np.int64))


def read_ranges(source: str | Path | TableSection, ids: list[str], *, time_column: str = "t", id_column: str = "id",
                range_column: str = "range_m", nlos_column: str | None = None, delimiter: str = ",") -> RangeLog:
    """Read a range log; ``ids`` are the ends the layout names (anchors, then peers). From a file,
    or a table section's in-memory table with the same columns (ids as names, a failed ranging
    as NaN); the same policies either way."""
    where = source_name(source)
    if isinstance(source, TableSection) and source.table is not None:
        cols = [time_column, range_column] + ([nlos_column] if nlos_column else [])
        arrays = table_columns(source.table, cols, where=where, allow_missing=[range_column])
        t, rng, lines = arrays[time_column], arrays[range_column], None
        nlos = arrays[nlos_column] if nlos_column else None
        who = table_text_column(source.table, id_column, where=where)
    else:
        path = Path(source.path if isinstance(source, TableSection) else source)
        t, who, rng, nlos, lines = _file_rows(path, time_column, id_column, range_column, nlos_column, delimiter)
    names, inverse = np.unique(who.astype(str), return_inverse=True)
    lookup = {name: k for k, name in enumerate(ids)}
    unknown = np.flatnonzero(~np.isin(names[inverse], ids))
    if unknown.size:
        i = int(unknown[0])
        raise row_error(where, f"id {who[i]!r} is neither an anchor nor a peer of this tag (the layout names "
                               f"{', '.join(ids)})", lines, i)
    end = np.array([lookup.get(n, -1) for n in names], dtype=np.int64)[inverse]
    before = np.maximum.accumulate(np.concatenate([[-np.inf], t[:-1]]))  # the latest time of the rows above
    out_of_order = t < before
    failed = ~out_of_order & np.isnan(rng)
    negative = ~out_of_order & ~failed & (rng < 0)
    keep = ~(out_of_order | failed | negative)
    dropped = {"failed": int(failed.sum()), "negative": int(negative.sum()), "out_of_order": int(out_of_order.sum())}
    total = sum(dropped.values())
    label = Path(where).name if lines is not None else where
    notes = [(f"{label}: dropped {dropped['failed']} failed rangings (empty/NaN), {dropped['negative']} negative, "
              f"{dropped['out_of_order']} out of time order")] if total else []
    return RangeLog(np.ascontiguousarray(t[keep]), np.ascontiguousarray(end[keep]), np.ascontiguousarray(rng[keep]),
                    None if nlos is None else nlos[keep] != 0, dropped, InputReport(dropped_samples=total, notes=notes))
