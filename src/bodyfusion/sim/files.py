"""The sensor files a simulation writes, in formats the readers read, and the layout sections
that read them back."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bodyfusion.io.imu import ImuCsvConfig

FLOAT_FORMAT = "%.10g"
"""Printed precision of simulated values (10 significant digits)."""


def write_imu_csv(path: Path, columns: tuple[str, ...], t: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                  *extra: np.ndarray, flags: np.ndarray | None = None) -> None:
    """An IMU CSV: ``t`` (s), specific force x y z (m/s^2), angular rate x y z (rad/s), any
    ``extra`` (N, k) float columns, then an optional 0/1 ``flags`` column (stance, step);
    ``columns`` names them all, in that order."""
    parts = [t, acc, gyro, *extra] + ([flags.astype(float)] if flags is not None else [])
    table = np.column_stack(parts)
    fmt = [FLOAT_FORMAT] * (table.shape[1] - (flags is not None)) + (["%d"] if flags is not None else [])
    np.savetxt(path, table, fmt=fmt, delimiter=",", header=",".join(columns), comments="")


def imu_csv_section(path: Path, columns: tuple[str, ...], **options: object) -> ImuCsvConfig:
    """The layout's reading of an IMU CSV written by :func:`write_imu_csv` (``t``, then
    specific force x y z, angular rate x y z; more settings in ``options``), with the file
    named relative to the layout written beside it."""
    return ImuCsvConfig(path=Path(path.name), time_column=columns[0], acc_columns=tuple(columns[1:4]),
                        gyro_columns=tuple(columns[4:7]), **options)
