"""The columns of a run's trajectory files (docs/contract.md) and their reader: the
``trajectories.csv`` and ``trajectories.parquet`` that ``fusion run`` writes
(:mod:`bodyfusion.outputs.trajectories`) read back into one
:class:`~bodyfusion.base.types.Trajectory` per system.

Positions ENU m in the run's frame, times s of the input's clock; velocity m/s (ENU);
attitude the quaternion ``q_nb`` (scalar first, body to ENU) and its ZYX Euler angles in the
ENU frame, degrees: ``yaw_deg`` counter-clockwise from East (90° − the azimuth of
docs/conventions.md), ``pitch_deg``, ``roll_deg``; each with its 1σ (``sd_`` + the column)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import Trajectory

POSITION_COLUMNS = ("system", "t", "east_m", "north_m", "up_m", "sd_east_m", "sd_north_m", "sd_up_m")
"""The first columns of ``trajectories.csv``, in order: every system has them."""
VELOCITY_COLUMNS = ("v_east_mps", "v_north_mps", "v_up_mps")
QUATERNION_COLUMNS = ("qw", "qx", "qy", "qz")
EULER_COLUMNS = ("roll_deg", "pitch_deg", "yaw_deg")
MOTION_COLUMNS = (*VELOCITY_COLUMNS, *QUATERNION_COLUMNS, *EULER_COLUMNS)
"""Velocity and attitude, after the positions (empty where a system has no such state)."""
MOTION_SD_COLUMNS = tuple(f"sd_{c}" for c in MOTION_COLUMNS)
"""Their 1σ, in the same order (empty where the system gives none)."""
TRAJECTORY_COLUMNS = (*POSITION_COLUMNS, *MOTION_COLUMNS, *MOTION_SD_COLUMNS)
"""The columns of ``trajectories.csv``, in order (docs/contract.md)."""
TRAJECTORY_HEADER = ",".join(TRAJECTORY_COLUMNS)
COV_EN_COLUMN = "cov_east_north_m2"
"""The Parquet file's last column: the east–north position covariance (m², null where not given)."""

UNITS = {"t": "s", "east_m": "m", "north_m": "m", "up_m": "m", "sd_east_m": "m", "sd_north_m": "m",
         "sd_up_m": "m", **{c: "m/s" for c in VELOCITY_COLUMNS}, **dict.fromkeys(QUATERNION_COLUMNS, "1"),
         **dict.fromkeys(EULER_COLUMNS, "deg"), COV_EN_COLUMN: "m^2"}
UNITS.update({f"sd_{c}": UNITS[c] for c in MOTION_COLUMNS})
"""The unit of every numeric column."""


def _read_table(path: Path) -> pa.Table:
    """The file as an Arrow table, numbers float64 (an empty CSV cell is null)."""
    try:
        if path.suffix == ".parquet":
            import pyarrow.parquet as pq  # ~40 MB resident: loaded when Parquet is used
            table = pq.read_table(path)
        else:
            types = {c: pa.string() if c == "system" else pa.float64() for c in (*TRAJECTORY_COLUMNS, COV_EN_COLUMN)}
            table = pacsv.read_csv(path, convert_options=pacsv.ConvertOptions(column_types=types))
        _ = table.column_names  # decoded here: a header that is not UTF-8 raises
        return table
    except (OSError, pa.ArrowInvalid, UnicodeDecodeError) as err:
        raise InputError(path, f"not a trajectory file ({','.join(POSITION_COLUMNS)}, ...): "
                               f"{str(err).splitlines()[0]}") from None


def _given(table: pa.Table, columns: tuple[str, ...], rows: pa.Array) -> np.ndarray | None:
    """(n, k) float64 of ``columns`` at ``rows``, None where the file lacks them or they are all
    null for these rows (the system has no such state)."""
    if not all(c in table.column_names for c in columns):
        return None
    picked = [table.column(c).take(rows) for c in columns]
    if all(p.null_count == len(p) for p in picked) and len(rows):
        return None
    return np.column_stack([p.to_numpy(zero_copy_only=False) for p in picked]).astype(float)


def read_trajectories(path: str | Path) -> dict[str, Trajectory]:
    """Trajectories from ``trajectories.parquet`` or ``trajectories.csv`` (by the suffix), one
    per system in file order: positions and their σ, ``pos_cov_en`` from the Parquet file's
    covariance column where given (the CSV has none), velocity and attitude quaternion where
    the system had them. A file without the position columns is an :class:`InputError`."""
    path = Path(path)
    table = _read_table(path)
    missing = [c for c in POSITION_COLUMNS if c not in table.column_names]
    if missing:
        raise InputError(path, f"missing column(s) {missing}")
    system = pc.dictionary_encode(table.column("system").cast(pa.string()).combine_chunks())  # first-seen order
    codes = system.indices.to_numpy(zero_copy_only=False)
    out: dict[str, Trajectory] = {}
    for code, name in enumerate(system.dictionary.to_pylist()):
        rows = pa.array(np.flatnonzero(codes == code))
        cov = _given(table, (COV_EN_COLUMN,), rows)
        out[name] = Trajectory(_given(table, ("t",), rows)[:, 0], _given(table, POSITION_COLUMNS[2:5], rows),
                               _given(table, POSITION_COLUMNS[5:8], rows), None if cov is None else cov[:, 0],
                               vel_n=_given(table, VELOCITY_COLUMNS, rows), q_nb=_given(table, QUATERNION_COLUMNS, rows))
    return out
