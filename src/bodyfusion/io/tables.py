"""Delimited text tables and time stamps: the layer every file reader stands on.

Every problem with an input file raises :class:`bodyfusion.base.errors.InputError`
naming the file and, when the problem is one cell or one row, the 1-based
line number of the file (as an editor shows it).

Parsing strategy: a clean file (every row after the header has its fields, no blank line,
every cell asked for a finite number, line ends ``\n`` or ``\r\n``) is read by Arrow's CSV
reader (:func:`bodyfusion.io.arrow_tables.read_clean_table`; a 1-hour 100 Hz IMU file, 35 MB, in about 0.2 s). Any other
file is read a chunk of lines at a time (:mod:`bodyfusion.io.lines`) into arrays sized once
from its line count, so a long recording costs its numbers and one chunk's text. Each chunk's
rows are first handed to ``numpy.loadtxt`` (C parser, fast); only when that fails, or when a
column may hold missing cells, are they parsed one by one in Python, which is also what
locates the offending line for the error message. Both paths give the same numbers, line
numbers and labels (tests/io/test_table_reader_paths.py).

Time stamps and their policies are :mod:`bodyfusion.io.timestamps`.
"""

from __future__ import annotations

import csv
import itertools
import math
from collections.abc import Collection, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.files import file_problem
from bodyfusion.base.sections import TableSection
from bodyfusion.io.arrow_tables import read_clean_table
from bodyfusion.io.lines import line_chunks, scan_text

_QUOTES = "\"'"


def clean_cell(cell: str) -> str:
    """Strip surrounding whitespace and one level of surrounding quotes."""
    cell = cell.strip()
    if len(cell) >= 2 and cell[0] == cell[-1] and cell[0] in _QUOTES:
        cell = cell[1:-1].strip()
    return cell


def split_line(line: str, delimiter: str) -> list[str]:
    if '"' in line or "'" in line:
        return next(csv.reader([line], delimiter=delimiter, skipinitialspace=True))
    return line.split(delimiter)


def _head_lines(f: Any, skip_rows: int) -> list[str]:
    """The non-blank lines of a file's first 64 kB after ``skip_rows``."""
    return [line for line in f.read(1 << 16).decode("utf-8-sig", "replace").splitlines()[skip_rows:] if line.strip()]


def file_header(path: str | Path, *, delimiter: str = ",", skip_rows: int = 0) -> list[str] | None:
    """The column names of a delimited file's header line (after ``skip_rows``), read from its
    first 64 kB only; None when the file or its header cannot be read."""
    if file_problem(Path(path)) is not None:
        return None
    try:
        with open(path, "rb") as f:
            head = _head_lines(f, skip_rows)
    except OSError:
        return None
    return [clean_cell(c) for c in split_line(head[0], delimiter)] if head else None


def file_time_span(path: str | Path, time_column: str, *, time_scale: float = 1.0, delimiter: str = ",",
                   skip_rows: int = 0) -> tuple[float, float] | None:
    """(first, last) value of ``time_column`` × ``time_scale`` (s) in a delimited file, read from
    its header, first data line and last line only (the file's tail, not its body): a cheap look
    at its time base. None when the file or those lines cannot be read as such."""
    if file_problem(Path(path)) is not None:
        return None
    try:
        with open(path, "rb") as f:
            head = _head_lines(f, skip_rows)
            f.seek(max(0, f.seek(0, 2) - (1 << 16)))
            tail = [line for line in f.read().decode("utf-8", "replace").splitlines() if line.strip()]
        header = [clean_cell(c) for c in split_line(head[0], delimiter)]
        j = header.index(time_column)
        first, last = (float(split_line(line, delimiter)[j]) * time_scale for line in (head[1], tail[-1]))
    except (OSError, ValueError, IndexError):
        return None
    return (first, last) if math.isfinite(first) and math.isfinite(last) else None


def _slow_parse(
    path: Path,
    rows: list[str],
    line_no: np.ndarray,
    idx: list[int],
    names: Sequence[str],
    delimiter: str,
    allow_missing: Collection[str],
    n_header: int,
    last: bool = True,
) -> np.ndarray:
    """Row-by-row parse; raises at the first bad cell with its line number (``last``: the rows
    end the file, so a short last row may have been cut off)."""
    out = np.empty((len(rows), len(idx)), dtype=np.float64)
    need = max(idx) + 1
    for r, line in enumerate(rows):
        if "\r" in line.rstrip("\r"):  # a line end the file's others are not (csv cannot split it)
            raise InputError(path, "a carriage return inside the line", int(line_no[r]))
        cells = split_line(line, delimiter)
        if len(cells) < need:
            raise InputError(
                path,
                f"row has {len(cells)} fields, the header has {n_header} "
                f"(column {names[int(np.argmax(np.asarray(idx) >= len(cells)))]!r} is missing)"
                + ("; the last row: was the file cut off? remove that row" if last and r == len(rows) - 1 else ""),
                int(line_no[r]),
            )
        for c, (j, name) in enumerate(zip(idx, names)):
            cell = clean_cell(cells[j])
            if cell == "":
                if name in allow_missing:
                    out[r, c] = np.nan
                    continue
                raise InputError(path, f"empty cell in column {name!r}", int(line_no[r]))
            try:
                out[r, c] = float(cell)
            except ValueError:
                raise InputError(
                    path, f"non-numeric value {cell!r} in column {name!r}", int(line_no[r])
                ) from None
    return out


def _parse_rows(path: Path, rows: list[str], line_no: np.ndarray, idx: list[int], names: Sequence[str],
                delimiter: str, allow_missing: Collection[str], n_header: int, last: bool) -> np.ndarray:
    """(len(rows), len(idx)) numbers of one chunk of rows: ``numpy.loadtxt`` where it parses them
    all, else row by row (:func:`_slow_parse`, which names the first bad cell's line)."""
    if not names:
        return np.empty((len(rows), 0))
    data: np.ndarray | None = None
    if not allow_missing:
        try:
            data = np.loadtxt(rows, delimiter=delimiter, usecols=idx, dtype=np.float64, ndmin=2, quotechar='"',
                              comments=None)
        except (ValueError, IndexError):
            data = None
        if data is not None and data.shape != (len(rows), len(idx)):
            data = None
    if data is None:
        data = _slow_parse(path, rows, line_no, idx, names, delimiter, set(allow_missing), n_header, last)
    return data


def _non_finite(path: Path, data: np.ndarray, names: Sequence[str], allowed: np.ndarray,
                line_no: np.ndarray) -> InputError | None:
    """The error for the chunk's first non-finite cell (NaN allowed only in ``allowed`` columns,
    infinity never), or None."""
    bad = ~np.isfinite(data)
    if not bad.any():
        return None
    bad &= ~(np.isnan(data) & allowed[None, :])
    if not bad.any():
        return None
    r, c = np.argwhere(bad)[0]
    what = "NaN" if np.isnan(data[r, c]) else "infinite value"
    return InputError(path, f"{what} in column {names[c]!r}", int(line_no[r]))


def _labels(path: Path, rows: list[str], line_no: np.ndarray, j: int, label: str, n_header: int,
            names: dict[str, int], out: np.ndarray) -> InputError | None:
    """The codes (into ``names``, extended in order of first appearance) of one chunk's text
    cells in column ``j`` (surrounding whitespace and quotes stripped) into ``out``; or the
    error of the chunk's first row with a carriage return inside it or without the cell."""
    rows = [row.rstrip("\r") for row in rows]  # CR LF (or CR CR LF) line ends
    stray = next((k for k, row in zip(line_no, rows) if "\r" in row), None)
    if stray is not None:
        return InputError(path, "a carriage return inside the line", int(stray))
    try:
        cells = np.loadtxt(rows, dtype=str, delimiter=",", usecols=j, ndmin=1, quotechar='"', comments=None)
    except (ValueError, IndexError):
        split = [split_line(row, ",") for row in rows]
        short = next((k for k, row in enumerate(split) if len(row) <= j), None)
        if short is not None:
            return InputError(path, f"row has {len(split[short])} fields, the header has {n_header} (column "
                                    f"{label!r} is missing)", int(line_no[short]))
        cells = np.array([row[j] for row in split], dtype=str)
    raw, first, inverse = np.unique(cells, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    code = np.empty(raw.size, dtype=out.dtype)
    code[order] = _name_codes([str(v) for v in raw[order]], names)
    out[:] = code[inverse.reshape(-1)]
    return None


def _name_codes(raw: list[str], names: dict[str, int]) -> np.ndarray:
    """(len(raw),) int32 codes of label cells ``raw`` (in order of first appearance) into
    ``names``, cleaned (:func:`clean_cell`) and extended in that order: two spellings of one
    name (``"left"``, ``left``) share its code."""
    return np.array([names.setdefault(clean_cell(v), len(names)) for v in raw], dtype=np.int32)


def read_table(
    path: str | Path,
    columns: Sequence[str],
    *,
    skip_rows: int = 0,
    delimiter: str = ",",
    allow_missing: Collection[str] = (),
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Read named numeric columns of a delimited text file.

    The header is the first line after ``skip_rows`` lines; header names are
    matched exactly after stripping surrounding whitespace and quotes.  Blank
    lines are ignored (but counted for line numbers).

    Returns ``(arrays, line_no)``: one float64 array per requested column and
    the 1-based file line number of every data row.

    Cells must be finite numbers.  For columns listed in ``allow_missing`` an
    empty cell or NaN is accepted and returned as NaN (motion-capture drop-outs);
    infinity is an error in every column.

    The file is read a chunk of lines at a time (:data:`~bodyfusion.io.lines.CHUNK_BYTES`)
    into arrays sized once; an error is the one the whole file's first bad line gives.
    """
    arrays, line_no, _ = read_labelled_table(path, columns, None, skip_rows=skip_rows, delimiter=delimiter,
                                             allow_missing=allow_missing)
    return arrays, line_no


def _table_body(path: Path, columns: list[str], skip_rows: int, delimiter: str
                ) -> tuple[list[str], list[int], int, int, bool, tuple[list[str], np.ndarray],
                           Iterator[tuple[list[str], np.ndarray]]]:
    """A delimited file opened for its ``columns``: its header's names, the columns' places in
    it, the header's line, the file's line count, whether its text is plain (Arrow can read it),
    the first chunk of data rows (rows, their 1-based lines) and an iterator over the others.
    Refuses a file without a header, a column, or data rows."""
    if skip_rows < 0:
        raise InputError(path, f"skip_rows must be >= 0, got {skip_rows}")
    if not delimiter:
        raise InputError(path, "delimiter must not be empty")
    n_lines, plain = scan_text(path)
    empty = InputError(path, "empty file: no header line" + (f" after skipping {skip_rows} rows" if skip_rows else ""))
    if n_lines <= skip_rows:
        raise empty
    header_line = skip_rows + 1
    chunks = line_chunks(path)
    for start, lines in chunks:
        if start + len(lines) > header_line:  # the header is in this chunk
            header_text = lines[header_line - start]
            body = itertools.chain([(header_line + 1, lines[header_line - start + 1:])], chunks)
            break

    def row_chunks() -> Iterator[tuple[list[str], np.ndarray]]:
        for first, part in body:
            keep = [i for i, ln in enumerate(part) if ln.strip()]
            if keep:
                yield [part[i] for i in keep], np.asarray(keep, dtype=np.int64) + first

    rows = row_chunks()
    pending = next(rows, None)
    if not header_text.strip():
        raise empty if pending is None else InputError(path, "header line is empty", header_line)
    if "\r" in header_text.rstrip("\r"):
        raise InputError(path, "a carriage return inside the line", header_line)
    header = [clean_cell(h) for h in split_line(header_text, delimiter)]

    idx: list[int] = []
    for name in columns:
        hits = [j for j, h in enumerate(header) if h == name]
        if not hits:
            raise InputError(
                path,
                f"missing column {name!r}; the header has: " + ", ".join(repr(h) for h in header),
                header_line,
            )
        if len(hits) > 1:
            raise InputError(path, f"column {name!r} appears {len(hits)} times in the header", header_line)
        idx.append(hits[0])
    if pending is None:
        raise InputError(path, "no data rows after the header", header_line)

    return header, idx, header_line, n_lines, plain, pending, rows


class TableChunk(NamedTuple):
    """One chunk of :func:`labelled_chunks`: column → (m,) float64, the rows' 1-based file
    lines (m,), and with a label column its cells' (m,) int32 codes into the names met so far
    (in order of first appearance; the list grows with later chunks), else None."""

    arrays: dict[str, np.ndarray]
    lines: np.ndarray
    codes: np.ndarray | None
    names: list[str]


def labelled_chunks(path: str | Path, columns: Sequence[str], label: str | None = None, *, skip_rows: int = 0,
                    delimiter: str = ",", allow_missing: Collection[str] = ()) -> Iterator[TableChunk]:
    """:func:`read_labelled_table` a chunk of lines at a time (:data:`~bodyfusion.io.lines.CHUNK_BYTES`),
    for a reader that streams a file of any length (a live replay, a truth read as a run goes):
    the same cells, names and codes as the whole file's; a chunk's first bad cell (or label) is
    refused as the whole read refuses it, once the chunks before it are given."""
    path = Path(path)
    columns = list(columns)
    allowed = np.array([c in allow_missing for c in columns], dtype=bool)
    header, idx, header_line, _, _, pending, rows = _table_body(path, columns, skip_rows, delimiter)
    if label is not None and label not in header:
        raise InputError(path, f"missing column {label!r}; the header has {header}", header_line)
    label_j = header.index(label) if label is not None else None
    found: dict[str, int] = {}
    while pending is not None:
        chunk, lines_of = pending
        pending = next(rows, None)
        data = _parse_rows(path, chunk, lines_of, idx, columns, delimiter, allow_missing, len(header), pending is None)
        bad = _non_finite(path, data, columns, allowed, lines_of)
        if bad is not None:
            raise bad
        codes = None
        if label_j is not None:
            codes = np.empty(len(chunk), dtype=np.int32)
            bad = _labels(path, chunk, lines_of, label_j, label, len(header), found, codes)
            if bad is not None:
                raise bad
        yield TableChunk({name: data[:, c] for c, name in enumerate(columns)}, lines_of, codes, list(found))


def table_chunks(path: str | Path, columns: Sequence[str], *, skip_rows: int = 0,
                 delimiter: str = ",") -> Iterator[dict[str, np.ndarray]]:
    """:func:`read_table`'s columns a chunk of lines at a time (:func:`labelled_chunks`)."""
    for chunk in labelled_chunks(path, columns, skip_rows=skip_rows, delimiter=delimiter):
        yield chunk.arrays


def read_labelled_table(
    path: str | Path,
    columns: Sequence[str],
    label: str | None,
    *,
    skip_rows: int = 0,
    delimiter: str = ",",
    allow_missing: Collection[str] = (),
) -> tuple[dict[str, np.ndarray], np.ndarray, tuple[np.ndarray, list[str]] | None]:
    """:func:`read_table`, and with a ``label`` column (of names: the system of a long-format
    row) its cells as ``(codes, names)``: (N,) int32 codes into the names, in order of first
    appearance, each name stripped of surrounding whitespace and quotes. Errors about the
    label column (missing from the header, a carriage return inside a row) come after those
    about the numbers."""
    path = Path(path)
    columns = list(columns)
    header, idx, header_line, n_lines, plain, pending, rows = _table_body(path, columns, skip_rows, delimiter)

    deferred: InputError | None = None
    label_j = None
    if label is not None:
        if label in header:
            label_j = header.index(label)
        else:
            deferred = InputError(path, f"missing column {label!r}; the header has {header}", header_line)
    allowed = np.array([c in allow_missing for c in columns], dtype=bool)
    if plain and deferred is None:
        fast = read_clean_table(path, columns, len(header), idx, label_j, header_line, n_lines, delimiter, allowed)
        if fast is not None and np.array_equal(
                np.column_stack([fast[0][name][:1] for name in columns]) if columns else np.empty((1, 0)),
                _parse_rows(path, pending[0][:1], pending[1][:1], idx, columns, delimiter, allow_missing, len(header),
                            False),
                equal_nan=True):
            arrays, line_no, labels = fast
            if labels is not None:  # the label names cleaned as the chunked reader cleans them
                found: dict[str, int] = {}
                labels = _name_codes(labels[1], found)[labels[0]], list(found)
            return arrays, line_no, labels
    cap = n_lines - header_line
    cols = [np.empty(cap) for _ in columns]
    line_no = np.empty(cap, dtype=np.int64)
    codes = np.empty(cap if label_j is not None else 0, dtype=np.int32)
    names: dict[str, int] = {}
    bad: InputError | None = None
    n = 0
    while pending is not None:
        chunk, lines_of = pending
        pending = next(rows, None)
        data = _parse_rows(path, chunk, lines_of, idx, columns, delimiter, allow_missing, len(header),
                           pending is None)
        m = len(chunk)
        for c, col in enumerate(cols):
            col[n:n + m] = data[:, c]
        line_no[n:n + m] = lines_of
        bad = bad or _non_finite(path, data, columns, allowed, lines_of)
        if label_j is not None and deferred is None:
            deferred = _labels(path, chunk, lines_of, label_j, label, len(header), names, codes[n:n + m])
        n += m
    if bad is not None:
        raise bad
    if deferred is not None:
        raise deferred
    arrays = {name: cols[c][:n] for c, name in enumerate(columns)}
    return arrays, line_no[:n], (codes[:n], list(names)) if label_j is not None else None


# --------------------------------------------------------------------------- in-memory tables


def _raw_columns(table: Any, where: str) -> dict[str, Any]:
    """Name → column of an in-memory table: a pandas DataFrame (its columns, and its index when
    the index is named), a mapping of name → array (an (N, 3) array under ``acc`` gives ``acc_x``,
    ``acc_y``, ``acc_z``; (N, k) otherwise ``acc_0``...), or a numpy structured array."""
    if hasattr(table, "columns") and hasattr(table, "index"):  # a pandas DataFrame
        cols = {str(c): table[c] for c in table.columns}
        if table.index.name is not None:
            cols.setdefault(str(table.index.name), table.index)
        return cols
    if isinstance(table, np.ndarray) and table.dtype.names:
        return {name: table[name] for name in table.dtype.names}
    if isinstance(table, Mapping):
        cols = {}
        for name, value in table.items():
            arr = np.asarray(value)
            if arr.ndim == 2:
                suffixes = "xyz" if arr.shape[1] == 3 else range(arr.shape[1])
                cols.update({f"{name}_{s}": arr[:, k] for k, s in enumerate(suffixes)})
            else:
                cols[str(name)] = value
        return cols
    shape = getattr(table, "shape", None)
    raise InputError(where, f"an in-memory table is a DataFrame, a mapping of column name to array or a structured "
                            f"array, not {type(table).__name__}{'' if shape is None else f' {shape}'}: name its columns")


def is_table(value: Any) -> bool:
    """A pandas DataFrame, a numpy structured array or a mapping (of column name to array)."""
    return ((hasattr(value, "columns") and hasattr(value, "index")) or isinstance(value, Mapping)
            or (isinstance(value, np.ndarray) and value.dtype.names is not None))


def tables_by_name(value: Any) -> bool:
    """``value`` is a mapping of names to tables (one table per system, per section), not one
    table given as a mapping of column names to arrays."""
    return isinstance(value, Mapping) and bool(value) and all(is_table(v) for v in value.values())


def _column(cols: dict[str, Any], name: str, where: str) -> Any:
    if name not in cols:
        raise InputError(where, f"missing column {name!r}; the table has: " + ", ".join(repr(c) for c in cols))
    return cols[name]


def table_columns(table: Any, columns: Sequence[str], *, where: str,
                  allow_missing: Collection[str] = ()) -> dict[str, np.ndarray]:
    """Named numeric columns (float64 copies) of an in-memory table (see :func:`_raw_columns`),
    checked as :func:`read_table` checks a file's: every column present, numeric, one length,
    at least one row; cells finite (NaN allowed in ``allow_missing`` columns, infinity never).
    Errors name ``where``, the column and the row (0-based)."""
    cols = _raw_columns(table, where)
    out: dict[str, np.ndarray] = {}
    for name in columns:
        col = _column(cols, name, where)
        try:
            values = col.to_numpy(dtype=float, na_value=np.nan) if hasattr(col, "to_numpy") else np.asarray(col, float)
        except (TypeError, ValueError):
            raise InputError(where, f"column {name!r} is not numeric ({getattr(col, 'dtype', type(col).__name__)})"
                             ) from None
        values = np.array(values, dtype=np.float64)
        if values.ndim != 1:
            raise InputError(where, f"column {name!r} is not one-dimensional (shape {values.shape})")
        out[name] = values
    lengths = {name: len(v) for name, v in out.items()}
    if len(set(lengths.values())) > 1:
        raise InputError(where, "columns of different lengths: " + ", ".join(f"{k} {v}" for k, v in lengths.items()))
    if not lengths or not next(iter(lengths.values())):
        raise InputError(where, "no rows")
    for name, values in out.items():
        bad = np.isinf(values) | (np.isnan(values) & (name not in allow_missing))
        if bad.any():
            r = int(np.argmax(bad))
            raise InputError(where, f"{'NaN' if np.isnan(values[r]) else 'infinite value'} in column {name!r} (row {r})")
    return out


def has_column(table: Any, name: str) -> bool:
    """The in-memory table has a column ``name``."""
    return name in _raw_columns(table, "table")


def table_text_column(table: Any, name: str, *, where: str) -> np.ndarray:
    """A column of names (ids, system names) of an in-memory table, as an array of str."""
    col = _column(_raw_columns(table, where), name, where)
    return np.char.strip(np.asarray(col, dtype=str).reshape(-1)).astype(object)


def row_error(where: str, reason: str, lines: np.ndarray | None, i: int) -> InputError:
    """An error at row i of a table: the file's line where the table is a file, else the
    in-memory table's row (0-based)."""
    if lines is not None:
        return InputError(where, reason, int(lines[i]))
    return InputError(where, f"{reason} (row {i})")


def read_source(source: str | Path | TableSection, columns: Sequence[str], *, skip_rows: int = 0,
                delimiter: str = ",", allow_missing: Collection[str] = ()) -> tuple[dict[str, np.ndarray],
                                                                                     np.ndarray | None, str]:
    """Named numeric columns of a file, or of a table section's data (its in-memory table when
    one is bound, else its file): ``(arrays, lines, where)`` with the file's line numbers (None
    for an in-memory table) and what errors name (the path, or the section's dotted key)."""
    where = source_name(source)
    if isinstance(source, TableSection):
        if source.table is not None:
            return table_columns(source.table, columns, where=where, allow_missing=allow_missing), None, where
        if source.topic is not None:
            from bodyfusion.io.ros import read_topic  # rosbags loads only for a recording that needs it

            return read_topic(source.path, source.topic, columns), None, where
        if source.group is not None:
            from bodyfusion.io.hdf5 import read_group  # h5py likewise

            return read_group(source.path, source.group, columns), None, where
        source = source.path
    arrays, lines = read_table(source, columns, skip_rows=skip_rows, delimiter=delimiter, allow_missing=allow_missing)
    return arrays, lines, where


def source_chunks(section: TableSection, columns: Sequence[str]) -> Iterator[dict[str, np.ndarray]]:
    """:func:`read_source` of a table section (its ``skip_rows`` and ``delimiter`` as its reader
    takes them) a chunk of rows at a time: a file's a chunk of lines at a time
    (:func:`table_chunks`), an in-memory table, a topic or a group whole."""
    if section.table is not None or section.topic is not None or section.group is not None:
        yield read_source(section, columns)[0]
        return
    yield from table_chunks(section.path, columns, skip_rows=getattr(section, "skip_rows", 0),
                            delimiter=getattr(section, "delimiter", ","))


def source_name(source: str | Path | TableSection) -> str:
    """What errors about ``source`` name: a file's path (and topic), or an in-memory table's
    section key."""
    if isinstance(source, TableSection):
        if source.table is not None:
            return f"{source.label} (in-memory table)"
        if source.topic is not None:
            return f"{source.path} (topic {source.topic})"
        return str(source.path) if source.group is None else f"{source.path} (group {source.group})"
    return str(source)


def check_columns(path: str | Path, what: str, cols: Sequence[str], counts: tuple[int, ...] = (3,)) -> list[str]:
    if isinstance(cols, str) or len(cols) not in counts:
        need = " or ".join(map(str, counts))
        raise InputError(path, f"{what} must name {need} columns (x, y, z), got {cols!r}")
    return list(cols)
