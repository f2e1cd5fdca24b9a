"""Readers of reference (truth) tracks: wide CSVs (one row per epoch, columns per system) and
the long ``system,t,east_m,north_m,up_m`` files ``fusion simulate`` writes. The layout's truth
formats (:data:`bodyfusion.core.truth.TRUTH_FORMATS`) are built on them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.sections import TableSection
from bodyfusion.base.types import LOG, TruthTrack
from bodyfusion.io.tables import (
    apply_timestamp_policy,
    check_columns,
    check_time_source,
    clean_cell,
    has_column,
    read_lines,
    read_source,
    sample_times,
    source_name,
    split_line,
    table_columns,
    table_text_column,
    tables_by_name,
)


def read_truth_csv(
    source: str | Path | TableSection,
    *,
    position_columns: Mapping[str, Sequence[str]],
    time_column: str | None = None,
    time_scale: float = 1.0,
    rate_hz: float | None = None,
    skip_rows: int = 0,
    delimiter: str = ",",
    sparse: bool = False,
    timestamp_policy: str = "error",
) -> dict[str, TruthTrack]:
    """Read reference positions, one :class:`TruthTrack` per system, from a file or a table
    section's data (its in-memory table: :func:`bodyfusion.io.tables.read_source`).

    ``position_columns`` maps a system name to its three columns (x, y, z of the
    file's frame, metres) or two (horizontal truth: z is returned as NaN).  A row
    whose cells for one system are empty or NaN (e.g. a motion-capture marker
    drop-out) is skipped for that system only; that is not an error and is not
    counted.  Time rows must be strictly increasing unless ``timestamp_policy``
    says otherwise.
    """
    where = source_name(source)
    if not position_columns:
        raise InputError(where, "position_columns is empty: name at least one system")
    check_time_source(where, time_column, time_scale, rate_hz)
    systems = {name: check_columns(where, f"position_columns[{name!r}]", cols, (2, 3))
               for name, cols in position_columns.items()}

    cols: list[str] = [time_column] if time_column is not None else []
    pos_cols: list[str] = []
    for triplet in systems.values():
        for c in triplet:
            if c not in cols:
                cols.append(c)
                pos_cols.append(c)
    arrays, line_no, where = read_source(source, cols, skip_rows=skip_rows, delimiter=delimiter,
                                         allow_missing=pos_cols)
    n = len(arrays[cols[0]])
    t = sample_times(arrays, n, time_column, time_scale, rate_hz)
    kept, _ = apply_timestamp_policy(t, timestamp_policy, where, lines=line_no)

    out: dict[str, TruthTrack] = {}
    for name, triplet in systems.items():
        pos = np.column_stack([arrays[c] for c in triplet])[kept]
        ok = ~np.isnan(pos).any(axis=1)
        if not ok.any():
            raise InputError(where, f"system {name!r} has no row with all of {triplet} present")
        if not ok.all():
            first = int(kept[np.argmin(ok)])
            LOG.warning("%s: %d truth row(s) of %s skipped (empty or NaN cells; the first at %s)",
                        Path(where).name if line_no is not None else where, int((~ok).sum()), name,
                        f"line {int(line_no[first])}" if line_no is not None else f"row {first}")
        if pos.shape[1] == 2:
            pos = np.column_stack([pos, np.full(len(pos), np.nan)])
        out[name] = TruthTrack(
            t=np.ascontiguousarray(t[kept][ok]), pos_n=np.ascontiguousarray(pos[ok]), sparse=sparse
        )
    return out


LONG_TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")


def _long_rows(source: str | Path | TableSection) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, str]:
    """System names (N,), numbers (N, 4: t, east, north, up), file lines (None for a table) and
    the name errors give, of long-format truth: a file, one in-memory table with a ``system``
    column, or a mapping of system name → table (``t``, ``east_m``, ``north_m``, and ``up_m``
    unless the truth is horizontal)."""
    where = source_name(source)
    table = source.table if isinstance(source, TableSection) else None
    if table is not None and tables_by_name(table):
        parts = []
        for name, tab in table.items():
            label = f"{where}: {name}"
            arrays = table_columns(tab, ["t", "east_m", "north_m"], where=label)
            up = table_columns(tab, ["up_m"], where=label)["up_m"] if has_column(tab, "up_m") else None
            parts.append((name, np.column_stack([arrays["t"], arrays["east_m"], arrays["north_m"],
                                                 up if up is not None else np.full(len(arrays["t"]), np.nan)])))
        names = np.concatenate([np.full(len(data), name, dtype=object) for name, data in parts])
        return names, np.concatenate([data for _, data in parts]), None, where
    arrays, line_no, where = read_source(source, LONG_TRUTH_COLUMNS[1:])
    data = np.column_stack([arrays[c] for c in LONG_TRUTH_COLUMNS[1:]])
    if table is not None:
        return table_text_column(table, "system", where=where), data, None, where
    path = Path(where)
    lines = read_lines(path)
    header = [clean_cell(c) for c in split_line(lines[0], ",")]
    if "system" not in header:
        raise InputError(path, f"missing column 'system'; the header has {header}", line=1)
    j = header.index("system")
    rows = [lines[k - 1].rstrip("\r") for k in line_no]  # CR LF (or CR CR LF) line ends
    stray = next((k for k, row in zip(line_no, rows) if "\r" in row), None)
    if stray is not None:
        raise InputError(path, "a carriage return inside the line", line=int(stray))
    column = np.loadtxt(rows, dtype=str, delimiter=",", usecols=j, ndmin=1, quotechar='"', comments=None)
    raw, inverse = np.unique(column, return_inverse=True)
    return np.array([clean_cell(str(v)) for v in raw], dtype=object)[inverse], data, line_no, where


def read_truth_long_csv(source: str | Path | TableSection, *, sparse: bool = False) -> dict[str, TruthTrack]:
    """Read truth in the long format ``system,t,east_m,north_m,up_m`` (what ``fusion simulate``
    writes), one :class:`TruthTrack` per system; each system's times must increase strictly.
    From a file (numbers as :func:`~bodyfusion.io.tables.read_table` reads them, a bad cell
    refused with its line, the system names from their own column) or a table section's
    in-memory data (see :func:`_long_rows`)."""
    names, data, line_no, where = _long_rows(source)
    raw, first, which = np.unique(names.astype(str), return_index=True, return_inverse=True)
    out: dict[str, TruthTrack] = {}
    for u in np.argsort(first):  # in the order of their first rows
        rows = np.flatnonzero(which == u)
        kept, _ = apply_timestamp_policy(data[rows, 0], "error", where,
                                         lines=None if line_no is None else line_no[rows])
        out[str(raw[u])] = TruthTrack(t=np.ascontiguousarray(data[rows[kept], 0]),
                                      pos_n=np.ascontiguousarray(data[rows[kept], 1:4]), sparse=sparse)
    return out
