"""Readers of reference (truth) tracks: wide CSVs (one row per epoch, columns per system) and
the long ``system,t,east_m,north_m,up_m`` files ``fusion simulate`` writes, whole
(:func:`read_truth_csv`, :func:`read_truth_long_csv`) or one system's a chunk of lines at a time
(:func:`wide_truth_chunks`, :func:`long_truth_chunks`: a live run that keeps a bounded history
reads its truth as it goes). The layout's truth formats
(:data:`bodyfusion.runner.truth.TRUTH_FORMATS`) are built on them."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.sections import TableSection
from bodyfusion.base.types import LOG, TruthTrack
from bodyfusion.io.tables import (
    check_columns,
    has_column,
    labelled_chunks,
    read_labelled_table,
    read_source,
    source_name,
    table_columns,
    table_text_column,
    tables_by_name,
)
from bodyfusion.io.timestamps import apply_timestamp_policy, check_time_source, sample_times


MAX_POSITION_M = 1.0e7
"""Largest truth coordinate (m) a local frame about a point on the Earth can hold: beyond it a
cell is a corrupt number (or another unit), refused with its line."""


def check_truth_positions(where: str, name: str, pos: np.ndarray, lines: np.ndarray | None) -> None:
    """Refuse (:class:`~bodyfusion.base.errors.InputError` naming the file and line, or the row) a
    truth position of ``name`` (N, 3; m, NaN for a missing height) beyond :data:`MAX_POSITION_M`."""
    bad = np.flatnonzero(np.nanmax(np.abs(pos), axis=1, initial=0.0) > MAX_POSITION_M)
    if bad.size:
        k = int(bad[0])
        at = f"line {int(lines[k])}" if lines is not None else f"row {k}"
        raise InputError(where, f"{at}: {name}'s truth position {pos[k].tolist()} m lies beyond "
                                f"{MAX_POSITION_M:.0e} m of the frame's origin ({bad.size} such row(s)): a corrupt "
                                "number, or a unit other than metres")


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
    kept, _, t_kept = apply_timestamp_policy(t, timestamp_policy, where, lines=line_no)

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
        check_truth_positions(where, name, pos[ok], None if line_no is None else line_no[kept][ok])
        out[name] = TruthTrack(
            t=np.ascontiguousarray(t_kept[ok]), pos_n=np.ascontiguousarray(pos[ok]), sparse=sparse
        )
    return out


LONG_TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")


def _long_rows(source: str | Path | TableSection) -> tuple[np.ndarray, list[str], dict[str, np.ndarray],
                                                          np.ndarray | None, str]:
    """Long-format truth as (N,) codes of the rows' systems into the system names (in order of
    their first rows), the columns ``t``, ``east_m``, ``north_m``, ``up_m`` (N,), the file's lines
    (None for a table) and the name errors give: of a file (read a chunk at a time,
    :func:`~bodyfusion.io.tables.read_labelled_table`), one in-memory table with a ``system``
    column, or a mapping of system name → table (``t``, ``east_m``, ``north_m``, and ``up_m``
    unless the truth is horizontal)."""
    where = source_name(source)
    table = source.table if isinstance(source, TableSection) else None
    numbers = list(LONG_TRUTH_COLUMNS[1:])
    if table is None:
        path = source.path if isinstance(source, TableSection) else Path(source)
        arrays, line_no, labels = read_labelled_table(path, numbers, "system")
        codes, names = labels
        return codes, names, arrays, line_no, str(path)
    if tables_by_name(table):
        parts = {}
        for name, tab in table.items():
            label = f"{where}: {name}"
            arrays = table_columns(tab, ["t", "east_m", "north_m"], where=label)
            arrays["up_m"] = (table_columns(tab, ["up_m"], where=label)["up_m"] if has_column(tab, "up_m")
                              else np.full(len(arrays["t"]), np.nan))
            parts[str(name)] = arrays
        text = np.concatenate([np.full(len(arrays["t"]), name, dtype=object) for name, arrays in parts.items()])
        columns = {c: np.concatenate([arrays[c] for arrays in parts.values()]) for c in numbers}
        line_no = None
    else:
        columns, line_no, where = read_source(source, numbers)
        text = table_text_column(table, "system", where=where)
    raw, first, inverse = np.unique(text.astype(str), return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty(raw.size, dtype=np.int32)
    rank[order] = np.arange(raw.size, dtype=np.int32)
    return rank[inverse.reshape(-1)], [str(raw[u]) for u in order], columns, line_no, where


def read_truth_long_csv(source: str | Path | TableSection, *, sparse: bool = False) -> dict[str, TruthTrack]:
    """Read truth in the long format ``system,t,east_m,north_m,up_m`` (what ``fusion simulate``
    writes), one :class:`TruthTrack` per system; each system's times must increase strictly.
    From a file (numbers as :func:`~bodyfusion.io.tables.read_table` reads them, a bad cell
    refused with its line, the system names from their own column) or a table section's
    in-memory data (see :func:`_long_rows`)."""
    codes, names, columns, line_no, where = _long_rows(source)
    out: dict[str, TruthTrack] = {}
    for u, name in enumerate(names):  # in the order of their first rows
        rows = np.flatnonzero(codes == u)
        kept, _, _ = apply_timestamp_policy(columns["t"][rows], "error", where,
                                         lines=None if line_no is None else line_no[rows])
        rows = rows[kept]
        # a system's rows are usually one block of the file: slices, no index arrays
        sel = slice(int(rows[0]), int(rows[-1]) + 1) if rows.size and rows[-1] - rows[0] + 1 == rows.size else rows
        pos = np.empty((rows.size, 3))
        for k, col in enumerate(LONG_TRUTH_COLUMNS[2:]):
            pos[:, k] = columns[col][sel]
        check_truth_positions(where, name, pos, None if line_no is None else line_no[rows])
        out[name] = TruthTrack(t=np.array(columns["t"][sel]), pos_n=pos, sparse=sparse)
    return out


def _increasing_after(where: str, t: np.ndarray, lines: np.ndarray, before: tuple[float, int] | None) -> None:
    """Refuse (naming the line, as the whole file's ``error`` timestamp policy refuses it) a chunk's
    time ``t`` (s) that does not increase strictly, from the previous chunk's last epoch
    ``before`` ((time s, line) or None) on."""
    if before is None:
        apply_timestamp_policy(t, "error", where, lines=lines)
    else:
        apply_timestamp_policy(np.concatenate([[before[0]], t]), "error", where,
                               lines=np.concatenate([[before[1]], lines]))


def long_truth_chunks(path: str | Path, name: str) -> Iterator[TruthTrack]:
    """System ``name``'s epochs of a long-format truth file (:func:`read_truth_long_csv`'s track,
    its checks and errors) a chunk of lines at a time (:func:`~bodyfusion.io.tables.labelled_chunks`);
    nothing for a name without rows."""
    where = str(path)
    before: tuple[float, int] | None = None
    for chunk in labelled_chunks(path, LONG_TRUTH_COLUMNS[1:], "system"):
        if name not in chunk.names:
            continue
        rows = np.flatnonzero(chunk.codes == chunk.names.index(name))
        if not rows.size:
            continue
        t, lines = chunk.arrays["t"][rows], chunk.lines[rows]
        _increasing_after(where, t, lines, before)
        pos = np.column_stack([chunk.arrays[c][rows] for c in LONG_TRUTH_COLUMNS[2:]])
        check_truth_positions(where, name, pos, lines)
        before = (float(t[-1]), int(lines[-1]))
        yield TruthTrack(t, pos)


def wide_truth_chunks(path: str | Path, name: str, columns: Sequence[str], *, time_column: str | None = None,
                      time_scale: float = 1.0, rate_hz: float | None = None, skip_rows: int = 0,
                      delimiter: str = ",") -> Iterator[TruthTrack]:
    """System ``name``'s epochs of a wide truth file, its ``columns`` (two or three, the file's
    frame and unit), a chunk of lines at a time: :func:`read_truth_csv`'s track for that system,
    its checks, skipped rows (counted and warned of once the file is read) and errors."""
    where = str(path)
    check_time_source(where, time_column, time_scale, rate_hz)
    columns = check_columns(where, f"position_columns[{name!r}]", columns, (2, 3))
    cols = list(dict.fromkeys(([time_column] if time_column is not None else []) + columns))
    before: tuple[float, int] | None = None
    rows = skipped = 0
    first_skipped: int | None = None
    for chunk in labelled_chunks(path, cols, skip_rows=skip_rows, delimiter=delimiter, allow_missing=columns):
        m = len(chunk.lines)
        t = (sample_times(chunk.arrays, m, time_column, time_scale, rate_hz) if time_column is not None
             else (rows + np.arange(m, dtype=np.float64)) / rate_hz)
        _increasing_after(where, t, chunk.lines, before)
        before, rows = (float(t[-1]), int(chunk.lines[-1])), rows + m
        pos = np.column_stack([chunk.arrays[c] for c in columns])
        ok = ~np.isnan(pos).any(axis=1)
        if not ok.all():
            first_skipped = first_skipped if first_skipped is not None else int(chunk.lines[np.argmin(ok)])
            skipped += int((~ok).sum())
        if pos.shape[1] == 2:
            pos = np.column_stack([pos, np.full(len(pos), np.nan)])
        check_truth_positions(where, name, pos[ok], chunk.lines[ok])
        if ok.any():
            yield TruthTrack(t[ok], pos[ok])
    if skipped == rows:
        raise InputError(where, f"system {name!r} has no row with all of {list(columns)} present")
    if skipped:
        LOG.warning("%s: %d truth row(s) of %s skipped (empty or NaN cells; the first at line %d)", Path(where).name,
                    skipped, name, first_skipped)


class TruthWindow:
    """One system's truth read as a run goes (:func:`bodyfusion.runner.truth.truth_stream`): the
    epochs from the earliest one a reader still needs to the last read. Each reader holds a
    place (an epoch's index since the track's first, :meth:`place`); :meth:`hold_from` keeps
    every epoch from a time on besides (the finish of a run that keeps its last part).
    :meth:`track` is the track held; ``span`` the first and last epoch read (s), ``epochs`` the
    number read. A chunk the reader refuses (:class:`~bodyfusion.base.errors.InputError`: a bad
    cell, a time that goes back) ends the track there: ``error`` keeps it and it is warned of
    once (a run that reads its truth as it goes meets it hours in; the scores then cover the
    track up to it, and say so). ``name``: the system's, for the warning."""

    def __init__(self, chunks: Iterator[TruthTrack], name: str = "") -> None:
        self._chunks = chunks
        self.name = name
        self.error: InputError | None = None
        self._t = np.empty(0)
        self._pos = np.empty((0, 3))
        self._offset = 0  # the index of the first epoch held
        self._places: dict[str, int] = {}
        self._hold_t = -math.inf
        self.sparse = False
        self.epochs = 0
        self.span = (math.nan, math.nan)
        self.done = False

    def read_through(self, t: float) -> None:
        """Read chunks until an epoch after ``t`` (s) is held, or the track ends."""
        while not self.done and not (self._t.size and self._t[-1] > t):
            try:
                chunk = next(self._chunks, None)
            except InputError as err:
                self.error, chunk = err, None
                LOG.warning("truth: %s: %s; the truth of %s ends at t = %.6g s: scored up to there", self.name, err,
                            self.name, self.span[1])
            if chunk is None:
                self.done = True
                break
            if not chunk.t.size:
                continue
            self._t = np.concatenate([self._t, chunk.t])
            self._pos = np.concatenate([self._pos, chunk.pos_n])
            self.sparse = chunk.sparse
            self.span = (float(chunk.t[0]) if not self.epochs else self.span[0], float(chunk.t[-1]))
            self.epochs += chunk.t.size

    def index(self, t: float, side: str = "left") -> int:
        """The index (since the track's first epoch) of the first epoch at or after ``t`` (s)
        (``side="right"``: after it), the epochs through ``t`` read."""
        self.read_through(t)
        return self._offset + int(np.searchsorted(self._t, t, side=side))

    def epochs_between(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """The times (s) and positions (ENU m) of epochs a … b − 1 (indices since the first; held)."""
        if a < self._offset:
            raise ValueError(f"truth epoch {a} was forgotten (the window holds from {self._offset})")
        return self._t[a - self._offset:b - self._offset], self._pos[a - self._offset:b - self._offset]

    def place(self, reader: str, index: int) -> None:
        """Reader ``reader`` needs the epochs from ``index`` on (the earlier ones go)."""
        self._places[reader] = index
        self._forget()

    def hold_from(self, t: float) -> None:
        """Keep every epoch from ``t`` (s) on besides what the readers need (the earlier ones go)."""
        self._hold_t = t
        self._forget()

    @property
    def first(self) -> int:
        """The index (since the track's first epoch) of the first epoch held."""
        return self._offset

    def held(self) -> TruthTrack:
        """The epochs held so far."""
        return TruthTrack(self._t.copy(), self._pos.copy(), self.sparse)

    def track(self) -> TruthTrack | None:
        """The epochs held, the track read to its end first (None: none)."""
        self.read_through(math.inf)
        return TruthTrack(self._t.copy(), self._pos.copy(), self.sparse) if self._t.size else None

    def _forget(self) -> None:
        """Drop the epochs before every reader's place and the time held from."""
        keep = min([*self._places.values(), self._offset + int(np.searchsorted(self._t, self._hold_t))])
        if keep > self._offset:
            self._t, self._pos = self._t[keep - self._offset:], self._pos[keep - self._offset:]
            self._offset = keep
