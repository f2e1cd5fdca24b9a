"""The sensor files a simulation writes, in formats the readers read, the same tables held in
memory, and the layout sections that read them back.

A simulated system hands over each of its files as a :class:`SimFile`: the writer of the file
and its columns as the file holds them (:func:`printed`: every number rounded exactly as its
printf format prints it and the readers parse it back), so a run on the tables in memory equals a
run on the written files, bit for bit, with no file written or read."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from bodyfusion.io.imu import ImuCsvConfig

FLOAT_FORMAT = "%.10g"
"""Printed precision of simulated values (10 significant digits)."""


ROWS = 1 << 16
"""Rows a simulated file is formatted at a time (the same bytes as at once)."""


@dataclass
class SimFile:
    """One sensor file of a simulated system: ``section``, the key (within the system's layout
    section) of the section that reads it; ``name``, its file name; ``table``, its table as the
    file holds it (:attr:`columns`), or what makes that table when it is first asked for (a
    walk only written to files never holds a second, printed copy of its data); ``write``, which
    writes the file at a path."""

    section: str
    name: str
    table: dict[str, np.ndarray] | Callable[[], dict[str, np.ndarray]]
    write: Callable[[Path], None]

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """The file's table as the file holds it (made on first use, then kept)."""
        if callable(self.table):
            self.table = self.table()
        return self.table


def savetxt_rows(fh: TextIO, columns: list[np.ndarray], fmt: str | list[str], delimiter: str = " ") -> None:
    """``numpy.savetxt(fh, numpy.column_stack(columns), fmt, delimiter)`` (the same text),
    :data:`ROWS` rows at a time: no table of the whole file is built."""
    n = len(columns[0])
    for lo in range(0, n, ROWS):
        np.savetxt(fh, np.column_stack([c[lo:lo + ROWS] for c in columns]), fmt=fmt, delimiter=delimiter)


_FORMAT = re.compile(r"%\.(\d+)([gf])")
_EXACT_POWERS = 22
"""10**k is a double exactly for 0 <= k <= 22."""


def printed(x: np.ndarray, fmt: str) -> np.ndarray:
    """``x`` as a file written with the printf format ``fmt`` (``%.Ng``: N significant digits,
    ``%.Nf``: N decimals, ``%d``) holds it when read back: each value the double nearest to its
    printed decimal. Exact and vectorised: the printed decimal is m / 10^k with m = rint(x · 10^k),
    divided by an exact power of ten; values whose x · 10^k lies within its rounding error of a
    tie (or beyond the exact powers) are printed and parsed one by one."""
    x = np.asarray(x, dtype=np.float64)
    if fmt == "%d":
        return np.trunc(x) + 0.0  # "%d" prints −0 as 0
    match = _FORMAT.fullmatch(fmt)
    if match is None:
        raise ValueError(f"unsupported format {fmt!r}")
    n, kind = int(match.group(1)), match.group(2)
    out = x.copy()
    work = np.isfinite(x) & (x != 0.0)
    ax = np.abs(np.where(work, x, 1.0))
    if kind == "g":
        e = np.floor(np.log10(ax))
        e += (ax >= 10.0 ** (e + 1)).astype(float) - (ax < 10.0**e).astype(float)  # log10 a hair off at powers of 10
        k = max(n, 1) - 1 - e
    else:
        k = np.full(x.shape, float(n))
    exact = work & (np.abs(k) <= _EXACT_POWERS)
    scale = 10.0 ** np.abs(np.where(exact, k, 0.0))
    xs = np.where(work, x, 0.0)
    m = np.where(k >= 0, xs * scale, xs / scale)
    frac = np.abs(m - np.floor(m) - 0.5)
    exact &= (np.abs(m) < 2.0**52) & (frac > 4.0 * np.abs(m) * 2.0**-53 + 1e-300)
    r = np.rint(m)
    out[exact] = np.where(k >= 0, r / scale, r * scale)[exact]
    slow = np.flatnonzero(work & ~exact)
    out[slow] = [float(fmt % v) for v in x[slow]]
    return out


def write_imu_csv(path: Path, columns: tuple[str, ...], t: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                  *extra: np.ndarray, flags: np.ndarray | None = None) -> None:
    """An IMU CSV: ``t`` (s), specific force x y z (m/s^2), angular rate x y z (rad/s), any
    ``extra`` (N, k) float columns, then an optional 0/1 ``flags`` column (stance, step);
    ``columns`` names them all, in that order."""
    parts = [t, acc, gyro, *extra]
    floats = sum(1 if p.ndim == 1 else p.shape[1] for p in parts)
    fmt = [FLOAT_FORMAT] * floats + (["%d"] if flags is not None else [])
    with open(path, "w") as fh:
        fh.write(",".join(columns) + "\n")
        savetxt_rows(fh, [*parts] + ([flags] if flags is not None else []), fmt, ",")


def imu_file(section: str, name: str, columns: tuple[str, ...], t: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
             *extra: np.ndarray, flags: np.ndarray | None = None) -> SimFile:
    """The IMU file :func:`write_imu_csv` writes, as a :class:`SimFile` read by the layout section
    ``section``: its columns at the printed precision (flags as booleans)."""
    def table() -> dict[str, np.ndarray]:
        values = np.column_stack([t, acc, gyro, *extra])
        out = {col: printed(values[:, j], FLOAT_FORMAT) for j, col in enumerate(columns[:values.shape[1]])}
        if flags is not None:
            out[columns[-1]] = np.asarray(flags, dtype=bool)
        return out

    return SimFile(section, name, table, lambda path: write_imu_csv(path, columns, t, acc, gyro, *extra, flags=flags))


def imu_csv_section(path: Path, columns: tuple[str, ...], **options: object) -> ImuCsvConfig:
    """The layout's reading of an IMU CSV written by :func:`write_imu_csv` (``t``, then
    specific force x y z, angular rate x y z; more settings in ``options``), with the file
    named relative to the layout written beside it."""
    return ImuCsvConfig(path=Path(path.name), time_column=columns[0], acc_columns=tuple(columns[1:4]),
                        gyro_columns=tuple(columns[4:7]), **options)
