"""Readers of reference (truth) tracks: wide CSVs (one row per epoch, columns per system) and
the long ``system,t,east_m,north_m,up_m`` files ``fusion simulate`` writes. The layout's truth
formats (:data:`bodyfusion.core.truth.TRUTH_FORMATS`) are built on them."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import LOG, TruthTrack
from bodyfusion.io.tables import (
    apply_timestamp_policy,
    check_columns,
    check_time_source,
    clean_cell,
    read_lines,
    read_table,
    sample_times,
    split_line,
)


def read_truth_csv(
    path: str | Path,
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
    """Read reference positions, one :class:`TruthTrack` per system.

    ``position_columns`` maps a system name to its three columns (x, y, z of the
    file's frame, metres) or two (horizontal truth: z is returned as NaN).  A row
    whose cells for one system are empty or NaN (e.g. a motion-capture marker
    drop-out) is skipped for that system only; that is not an error and is not
    counted.  Time rows must be strictly increasing unless ``timestamp_policy``
    says otherwise.
    """
    path = Path(path)
    if not position_columns:
        raise InputError(path, "position_columns is empty: name at least one system")
    check_time_source(path, time_column, time_scale, rate_hz)
    systems = {name: check_columns(path, f"position_columns[{name!r}]", cols, (2, 3))
               for name, cols in position_columns.items()}

    cols: list[str] = [time_column] if time_column is not None else []
    pos_cols: list[str] = []
    for triplet in systems.values():
        for c in triplet:
            if c not in cols:
                cols.append(c)
                pos_cols.append(c)
    arrays, line_no = read_table(path, cols, skip_rows=skip_rows, delimiter=delimiter, allow_missing=pos_cols)
    n = line_no.size
    t = sample_times(arrays, n, time_column, time_scale, rate_hz)
    kept, _ = apply_timestamp_policy(t, timestamp_policy, path, lines=line_no)

    out: dict[str, TruthTrack] = {}
    for name, triplet in systems.items():
        pos = np.column_stack([arrays[c] for c in triplet])[kept]
        ok = ~np.isnan(pos).any(axis=1)
        if not ok.any():
            raise InputError(path, f"system {name!r} has no row with all of {triplet} present")
        if not ok.all():
            LOG.warning("%s: %d truth row(s) of %s skipped (empty or NaN cells; the first at line %d)", path.name,
                        int((~ok).sum()), name, int(line_no[kept][np.argmin(ok)]))
        if pos.shape[1] == 2:
            pos = np.column_stack([pos, np.full(len(pos), np.nan)])
        out[name] = TruthTrack(
            t=np.ascontiguousarray(t[kept][ok]), pos_n=np.ascontiguousarray(pos[ok]), sparse=sparse
        )
    return out


LONG_TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")


def read_truth_long_csv(path: str | Path, *, sparse: bool = False) -> dict[str, TruthTrack]:
    """Read truth in the long format ``system,t,east_m,north_m,up_m`` (what ``fusion simulate``
    writes), one :class:`TruthTrack` per system; each system's times must increase strictly.
    Numbers are read as :func:`~bodyfusion.io.tables.read_table` reads them (a bad cell is
    refused with its line), the system names from their own column."""
    path = Path(path)
    arrays, line_no = read_table(path, LONG_TRUTH_COLUMNS[1:])
    lines = read_lines(path)
    header = [clean_cell(c) for c in split_line(lines[0], ",")]
    if "system" not in header:
        raise InputError(path, f"missing column 'system'; the header has {header}", line=1)
    j = header.index("system")
    column = np.loadtxt([lines[k - 1] for k in line_no], dtype=str, delimiter=",", usecols=j, ndmin=1,
                        quotechar='"', comments=None)
    raw, first, which = np.unique(column, return_index=True, return_inverse=True)
    data = np.column_stack([arrays[c] for c in LONG_TRUTH_COLUMNS[1:]])
    out: dict[str, TruthTrack] = {}
    for u in np.argsort(first):  # in the order of their first rows
        name = clean_cell(str(raw[u]))
        rows = np.flatnonzero(which == u)
        kept, _ = apply_timestamp_policy(data[rows, 0], "error", path, lines=line_no[rows])
        out[name] = TruthTrack(t=np.ascontiguousarray(data[rows[kept], 0]),
                                    pos_n=np.ascontiguousarray(data[rows[kept], 1:4]), sparse=sparse)
    return out
