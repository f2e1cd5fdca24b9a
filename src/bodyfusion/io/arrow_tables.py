"""Delimited tables read by Arrow's CSV reader (C++, several times ``numpy.loadtxt``'s speed): the
fast path of :func:`bodyfusion.io.tables.read_labelled_table`, taken for a file Arrow reads
exactly as the chunked reader of :mod:`bodyfusion.io.tables` does; any other file is left to
that reader, which names its first bad line."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def arrow_values(values: Any, dtype: type) -> np.ndarray:
    """The numbers of an Arrow array or chunked array of ``dtype`` (float64, int32) as one numpy
    array (a copy), nulls NaN, read from its buffers: ``to_numpy`` and ``fill_null`` with a
    Python float would import pandas (0.3 s)."""
    dtype = np.dtype(dtype)
    out = []
    for c in getattr(values, "chunks", [values]):
        v = np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c), offset=c.offset * dtype.itemsize).copy()
        if c.null_count:
            valid = np.unpackbits(np.frombuffer(c.buffers()[0], dtype=np.uint8), bitorder="little")
            v[~valid[c.offset:c.offset + len(c)].astype(bool)] = np.nan
        out.append(v)
    return np.concatenate(out or [np.empty(0, dtype)])


def read_clean_table(path: Path, columns: list[str], n_header: int, idx: list[int], label_j: int | None,
                     header_line: int, n_lines: int, delimiter: str, allowed: np.ndarray
                     ) -> tuple[dict[str, np.ndarray], np.ndarray, tuple[np.ndarray, list[str]] | None] | None:
    """The ``columns`` (float64, at header positions ``idx`` of ``n_header``), the file line
    number of every row and, with a label column at ``label_j``, its cells as (int32 codes, raw
    names in order of first appearance), for a file Arrow reads exactly as the chunked reader
    would: every row after the header line ``header_line`` (of ``n_lines``) has the header's
    fields, none is blank, every cell asked for is a number (empty only where ``allowed``),
    finite. None for any other file. Columns are taken by position, so the header's own
    spelling is the chunked reader's business."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    if len(delimiter) != 1:
        return None
    names = [f"c{j}" for j in range(n_header)]
    types = {names[j]: pa.float64() for j in idx}
    if label_j is not None:
        types[names[label_j]] = pa.string()
    try:
        table = pacsv.read_csv(path, read_options=pacsv.ReadOptions(column_names=names, skip_rows=header_line,
                                                                    use_threads=False, block_size=1 << 22),
                               parse_options=pacsv.ParseOptions(delimiter=delimiter, quote_char='"'),
                               convert_options=pacsv.ConvertOptions(column_types=types, include_columns=list(types),
                                                                    null_values=[""], strings_can_be_null=False,
                                                                    quoted_strings_can_be_null=False))
    except (pa.ArrowException, OSError):
        return None
    try:
        return _result(table, path, columns, idx, label_j, header_line, n_lines, allowed)
    finally:  # the reader's buffers back to the system, not kept by Arrow's allocator (~100 MB an hour of truth)
        del table
        pa.default_memory_pool().release_unused()


def _result(table: Any, path: Path, columns: list[str], idx: list[int], label_j: int | None, header_line: int,
            n_lines: int, allowed: np.ndarray
            ) -> tuple[dict[str, np.ndarray], np.ndarray, tuple[np.ndarray, list[str]] | None] | None:
    """:func:`read_clean_table`'s result from the table Arrow read (columns ``c<j>``), or None."""
    with path.open("rb") as fh:
        fh.seek(-1, 2)
        rows = n_lines - header_line - (fh.read(1) == b"\n")
    if table.num_rows != rows:  # a blank line skipped, or a quoted line end
        return None
    arrays = {}
    for name, j, ok in zip(columns, idx, allowed):
        column = table.column(f"c{j}")
        if column.null_count and not ok:
            return None
        values = arrow_values(column, np.float64)
        if not np.all(np.isfinite(values) | (ok & np.isnan(values))):
            return None
        arrays[name] = values
    labels = None
    if label_j is not None:
        encoded = table.column(f"c{label_j}").combine_chunks().dictionary_encode()  # codes in order of first sight
        labels = arrow_values(encoded.indices, np.int32), encoded.dictionary.to_pylist()
    line_no = np.arange(header_line + 1, header_line + 1 + rows, dtype=np.int64)
    return arrays, line_no, labels
