"""Per-update records kept in numpy arrays: a row appended at a time into preallocated storage
that doubles when full, so recording every update of a long run costs no Python object per row."""

from __future__ import annotations

import numpy as np


class GrowingArray:
    """Rows of one ``shape`` (``()``: scalars) and ``dtype``, appended one at a time.

    :meth:`view` is the (n, *shape) array of the rows so far (a view: copy it to keep it past
    the next append)."""

    def __init__(self, shape: tuple[int, ...] = (), dtype: type | np.dtype = np.float64, capacity: int = 64) -> None:
        self._data = np.empty((max(int(capacity), 1), *shape), dtype=dtype)
        self._n = 0

    def append(self, row: object) -> None:
        """Add one row (broadcast to the row shape)."""
        if self._n == len(self._data):
            grown = np.empty((2 * len(self._data), *self._data.shape[1:]), dtype=self._data.dtype)
            grown[:self._n] = self._data
            self._data = grown
        self._data[self._n] = row
        self._n += 1

    def extend(self, rows: np.ndarray) -> None:
        """Add the rows of ``rows`` (k, *shape) (the capacity at least doubles when it grows)."""
        rows = np.asarray(rows)
        k = rows.shape[0]
        if self._n + k > len(self._data):
            grown = np.empty((max(self._n + k, 2 * len(self._data)), *self._data.shape[1:]), dtype=self._data.dtype)
            grown[:self._n] = self._data[:self._n]
            self._data = grown
        self._data[self._n:self._n + k] = rows
        self._n += k

    def keep(self, n: int) -> None:
        """Drop every row from n on."""
        self._n = min(self._n, max(int(n), 0))

    def drop_first(self, d: int) -> None:
        """Drop the first ``d`` rows (the others move to the front; the capacity stays, so that a
        record that forgets as fast as it grows keeps its size)."""
        d = min(max(int(d), 0), self._n)
        if d:
            self._data[:self._n - d] = self._data[d:self._n]
            self._n -= d

    def pop(self) -> None:
        """Drop the last row."""
        if self._n == 0:
            raise IndexError("pop from an empty record")
        self._n -= 1

    def __len__(self) -> int:
        return self._n

    def view(self) -> np.ndarray:
        """The rows so far, (n, *shape)."""
        return self._data[:self._n]
