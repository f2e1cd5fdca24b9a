"""IMU recordings: the layout section that describes a CSV (:class:`ImuCsvConfig`) and the reader
that turns it into an :class:`~bodyfusion.base.types.ImuStream` in SI units and the body frame,
checked by :func:`bodyfusion.io.imu_checks.check_imu`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from bodyfusion.base.errors import InputError
from bodyfusion.base.sections import DataPath, TableSection
from bodyfusion.base.types import ImuStream
from bodyfusion.io.imu_checks import check_imu
from bodyfusion.io.tables import check_columns, read_source, row_error, source_name
from bodyfusion.io.timestamps import TIMESTAMP_POLICIES, apply_timestamp_policy, check_time_source, sample_times
from bodyfusion.nav.earth import STANDARD_GRAVITY
from bodyfusion.nav.frames import SensorAxisMap

ACC_UNITS: dict[str, float] = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS: dict[str, float] = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
ACC_LIMIT_MPS2 = 1.0e4
"""No accelerometer reads more than this (m/s², ~1000 g, per axis): a larger value is corrupt."""
GYRO_LIMIT_RADPS = 1.0e4
"""No gyroscope reads more than this (rad/s per axis; deg/s misread as rad/s stay below it)."""
MAX_GAP_S = 600.0
"""Default longest gap in a recording's timestamps (s) a navigation system is asked to bridge."""


class ImuCsvConfig(TableSection):
    """An IMU recorded as CSV, or its table given in memory: column names, units and time base
    (see :func:`read_imu_csv`)."""

    path: DataPath | None = None
    """CSV file; relative to the layout file (unset: the table is given in memory)."""
    acc_columns: tuple[str, str, str]
    """Header names of the accelerometer x, y, z columns (body frame)."""
    gyro_columns: tuple[str, str, str]
    """Header names of the gyroscope x, y, z columns (body frame)."""
    stance_column: str | None = None
    """Optional 0/1 stance labels given with the data."""
    acc_unit: Literal["m/s^2", "g"] = "m/s^2"
    """Unit of the accelerometer columns: m/s^2 or g (9.80665 m/s^2)."""
    gyro_unit: Literal["rad/s", "deg/s"] = "rad/s"
    """Unit of the gyroscope columns: rad/s or deg/s."""
    time_column: str | None = None
    """Column of sample times, multiplied by time_scale to give seconds."""
    time_scale: float = Field(default=1.0, gt=0, le=1e6)
    """Factor from the time column to seconds (e.g. 1/60 for a sample counter at 60 Hz)."""
    rate_hz: float | None = Field(default=None, gt=0)
    """Sample rate (Hz): the time base when the file has no time column; with one, the
    nominal rate the timestamps are checked against."""
    skip_rows: int = Field(default=0, ge=0, le=10_000_000)
    """Lines before the header line."""
    delimiter: str = ","
    """Field separator."""
    timestamp_policy: Literal["drop", "sort", "error", "unwrap"] = "drop"
    """Duplicate or backward timestamps: drop (counted), sort (counted), error, or unwrap (a clock
    that restarts goes on where it was, then drop; :func:`~bodyfusion.io.timestamps.apply_timestamp_policy`)."""
    axes: SensorAxisMap = ("x", "y", "z")
    """The body frame in the file's axes, a signed axis map that rotates: ``[x, -y, -z]`` turns a
    sensor whose z points down at rest into one whose z points up; one that mirrors (``[x, y,
    -z]``) is refused (:data:`~bodyfusion.nav.frames.SensorAxisMap`)."""
    max_step_samples: float = Field(default=5.0, gt=1, le=1e6)
    """A time step longer than this many nominal sample periods is a gap (reported, and
    handled by the navigation system's gap policy)."""
    max_gap_s: float = Field(default=MAX_GAP_S, gt=0)
    """Longest gap (s) in the timestamps a navigation system is asked to bridge; a longer one
    refuses the file (split the recording there, or raise this)."""

    @model_validator(mode="after")
    def _time_source(self) -> ImuCsvConfig:
        if self.time_column is None and self.rate_hz is None:
            raise ValueError("give time_column or rate_hz")
        return self


def read_imu_csv(
    source: str | Path | TableSection,
    *,
    acc_columns: Sequence[str],
    gyro_columns: Sequence[str],
    stance_column: str | None = None,
    acc_unit: str = "m/s^2",
    gyro_unit: str = "rad/s",
    time_column: str | None = None,
    time_scale: float = 1.0,
    rate_hz: float | None = None,
    skip_rows: int = 0,
    delimiter: str = ",",
    timestamp_policy: str = "drop",
    min_samples: int = 10,
    axes: Sequence[str] = ("x", "y", "z"),
    declared_rate_hz: float | None = None,
    max_step_samples: float = 5.0,
    max_gap_s: float = MAX_GAP_S,
    checks: Literal["all", "inputs", "none"] = "all",
) -> ImuStream:
    """Read a body-frame IMU CSV into an :class:`ImuStream` in SI units: the file ``source``, or a
    table section's data (:func:`bodyfusion.io.tables.read_source`: its in-memory table, every
    check the same, errors naming the section and the row instead of the file and the line).

    Time is ``time_column`` × ``time_scale`` seconds (e.g. a sample-number column
    with ``time_scale=1/60``) or ``i / rate_hz``; exactly one must be given.
    Accelerometer units: ``ACC_UNITS`` (``"g"`` is 9.80665 m/s^2); gyroscope
    units: ``GYRO_UNITS``.  ``stance_column`` holds 0/1 labels (1 = stance).
    ``axes`` (a signed axis map that rotates, :data:`bodyfusion.nav.frames.SensorAxisMap`) turns the file's
    axes into the body frame.  Non-increasing timestamps are handled by
    ``timestamp_policy`` (see :func:`apply_timestamp_policy`); what was changed is
    in ``stream.report``.  The stream is then checked
    (:func:`bodyfusion.io.imu_checks.check_imu`, against ``declared_rate_hz`` and with gaps
    longer than ``max_step_samples`` periods): ``stream.checks``, and one warning each in
    ``stream.report``; ``checks="inputs"``: the gaps and clipping only (what shapes a navigation
    system's inputs), ``"none"``: no checks (``stream.checks`` None) — a live run's pass over the
    last seconds of a recording whose whole is checked at its close. Refused with the line: a
    reading beyond :data:`ACC_LIMIT_MPS2` or :data:`GYRO_LIMIT_RADPS` (corrupt, not a sensor's), a
    gap longer than ``max_gap_s``.
    """
    if checks not in ("all", "inputs", "none"):
        raise ValueError(f"checks must be all, inputs or none, got {checks!r}")
    where = source_name(source)
    if acc_unit not in ACC_UNITS:
        raise InputError(where, f"unknown acc_unit {acc_unit!r}; allowed: " + ", ".join(ACC_UNITS))
    if gyro_unit not in GYRO_UNITS:
        raise InputError(where, f"unknown gyro_unit {gyro_unit!r}; allowed: " + ", ".join(GYRO_UNITS))
    if timestamp_policy not in TIMESTAMP_POLICIES:
        raise InputError(
            where, f"unknown timestamp policy {timestamp_policy!r}; allowed: " + ", ".join(TIMESTAMP_POLICIES)
        )
    check_time_source(where, time_column, time_scale, rate_hz)
    acc_cols = check_columns(where, "acc_columns", acc_columns)
    gyro_cols = check_columns(where, "gyro_columns", gyro_columns)
    min_samples = max(int(min_samples), 1)

    cols: list[str] = []
    for c in ([time_column] if time_column is not None else []) + acc_cols + gyro_cols + (
        [stance_column] if stance_column is not None else []
    ):
        if c not in cols:
            cols.append(c)
    arrays, line_no, where = read_source(source, cols, skip_rows=skip_rows, delimiter=delimiter)
    n = len(arrays[cols[0]])
    if n < min_samples:
        raise InputError(where, f"only {n} data rows; at least {min_samples} are needed")

    stance = None
    if stance_column is not None:
        s = arrays[stance_column]
        bad = np.flatnonzero((s != 0.0) & (s != 1.0))
        if bad.size:
            i = int(bad[0])
            raise row_error(where, f"stance column {stance_column!r} must be 0 or 1, got {s[i]:g}", line_no, i)
        stance = s == 1.0

    t = sample_times(arrays, n, time_column, time_scale, rate_hz)
    kept, report, t_kept = apply_timestamp_policy(t, timestamp_policy, where, lines=line_no)
    if kept.size < min_samples:
        raise InputError(
            where, f"only {kept.size} samples left after timestamp policy {timestamp_policy!r}; "
            f"at least {min_samples} are needed"
        )

    acc = _body_frame(tuple(axes), [arrays[c] for c in acc_cols], ACC_UNITS[acc_unit])
    for c in set(acc_cols) - {time_column, stance_column, *gyro_cols}:
        del arrays[c]  # each column goes once it is used: the file's numbers are held about once
    gyro = _body_frame(tuple(axes), [arrays[c] for c in gyro_cols], GYRO_UNITS[gyro_unit])
    if kept.size < n or report.reordered_samples or t_kept is not t:  # the policy's samples (usually all: no copy)
        t, acc, gyro = t_kept, acc[kept], gyro[kept]
        stance = None if stance is None else stance[kept]
    for what, x, limit, unit in (("accelerometer", acc, ACC_LIMIT_MPS2, "m/s^2"),
                                 ("gyroscope", gyro, GYRO_LIMIT_RADPS, "rad/s")):
        if x.max() <= limit and x.min() >= -limit:
            continue
        bad = np.flatnonzero(np.any(np.abs(x) > limit, axis=1))
        if bad.size:
            raise row_error(where, f"{what} reading {np.max(np.abs(x[bad[0]])):.3g} {unit} is beyond any sensor's range "
                            f"({limit:g} {unit}): a corrupt value ({bad.size} such samples)", line_no,
                            int(kept[bad[0]]))
    gap = np.diff(t)
    if gap.size and gap.max() > max_gap_s:
        j = int(np.argmax(gap))
        raise row_error(where, f"a gap of {gap[j]:.6g} s in the timestamps (t = {t[j]:.6g} → {t[j + 1]:.6g} s), "
                        f"longer than max_gap_s ({max_gap_s:g} s): split the recording there, or raise max_gap_s",
                        line_no, int(kept[j + 1]))
    del gap, arrays
    stream = ImuStream(
        t=np.ascontiguousarray(t),
        acc_b=acc,
        gyro_b=gyro,
        stance=None if stance is None else np.ascontiguousarray(stance),
        source=where,
        report=report,
    )
    if checks == "none":
        return stream
    stream.checks = check_imu(stream.t, stream.acc_b, stream.gyro_b, source=Path(where).name if line_no is not None
                              else where, acc_unit=acc_unit, gyro_unit=gyro_unit, declared_rate_hz=declared_rate_hz,
                              max_step_samples=max_step_samples, plausibility=checks == "all")
    for message in stream.checks.warnings:
        report.warn(message)
    return stream


def _body_frame(axes: tuple[str, str, str], columns: list[np.ndarray], unit: float) -> np.ndarray:
    """(N, 3) vectors in the body frame from the file's x, y, z ``columns`` in a unit ``unit``
    SI units large: :func:`~bodyfusion.nav.frames.apply_axis_map` of the columns times ``unit``
    (the same numbers: a sign flip commutes with the rounding), written once."""
    out = np.empty((len(columns[0]), 3))
    for k, entry in enumerate(axes):
        source = columns[{"x": 0, "y": 1, "z": 2}[entry.lstrip("-")]]
        np.multiply(source, -unit if entry.startswith("-") else unit, out=out[:, k])
    return out


def read_imu(section: ImuCsvConfig, checks: Literal["all", "inputs", "none"] = "all") -> ImuStream:
    """The stream a layout's IMU section describes (its file, or its in-memory table), in SI units
    and the body frame, checked
    (:func:`read_imu_csv`; with both a time column and ``rate_hz``, the rate is the nominal
    one the timestamps are checked against; ``checks``: which, as :func:`read_imu_csv`'s)."""
    timed = section.time_column is not None
    return read_imu_csv(
        section, acc_columns=section.acc_columns, gyro_columns=section.gyro_columns,
        stance_column=section.stance_column, acc_unit=section.acc_unit, gyro_unit=section.gyro_unit,
        time_column=section.time_column, time_scale=section.time_scale, rate_hz=None if timed else section.rate_hz,
        skip_rows=section.skip_rows, delimiter=section.delimiter, timestamp_policy=section.timestamp_policy,
        axes=section.axes, declared_rate_hz=section.rate_hz if timed else None,
        max_step_samples=section.max_step_samples, max_gap_s=section.max_gap_s, checks=checks)
