"""CSV readers for IMU streams and reference (truth) tracks.

Every problem with an input file raises :class:`bodyfusion.core.errors.InputError`
naming the file and, when the problem is one cell or one row, the 1-based
line number of the file (as an editor shows it).

Parsing strategy: the rows are first handed to ``numpy.loadtxt`` (C parser,
fast); only when that fails, or when a column may hold missing cells, are the
rows parsed one by one in Python, which is also what locates the offending
line for the error message.  A 28 000-row IMU file reads in a few tens of ms.

Timestamps are never silently integrated with a zero or negative step: see
:func:`apply_timestamp_policy`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import numpy as np

from bodyfusion.core.layout import ImuCsvConfig, apply_axis_map
from bodyfusion.nav.earth import STANDARD_GRAVITY
from bodyfusion.core.errors import InputError
from bodyfusion.io.imu_checks import check_imu
from bodyfusion.core.types import ImuStream, InputReport, TruthTrack

ACC_UNITS: dict[str, float] = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}
GYRO_UNITS: dict[str, float] = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
TIMESTAMP_POLICIES = ("drop", "sort", "error")

_QUOTES = "\"'"

__all__ = [
    "ACC_UNITS",
    "GYRO_UNITS",
    "STANDARD_GRAVITY",
    "TIMESTAMP_POLICIES",
    "apply_timestamp_policy",
    "read_imu",
    "read_imu_csv",
    "read_table",
    "read_truth_csv",
]


# --------------------------------------------------------------------------- generic table


def _clean(cell: str) -> str:
    """Strip surrounding whitespace and one level of surrounding quotes."""
    cell = cell.strip()
    if len(cell) >= 2 and cell[0] == cell[-1] and cell[0] in _QUOTES:
        cell = cell[1:-1].strip()
    return cell


def _split(line: str, delimiter: str) -> list[str]:
    if '"' in line or "'" in line:
        return next(csv.reader([line], delimiter=delimiter, skipinitialspace=True))
    return line.split(delimiter)


def _read_lines(path: Path) -> list[str]:
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except IsADirectoryError:
        raise InputError(path, "is a directory, not a file") from None
    except OSError as err:
        raise InputError(path, f"cannot read file: {err.strerror or err}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise InputError(path, "not a UTF-8 text file", line) from None
    lines = text.split("\n")
    return [ln[:-1] if ln.endswith("\r") else ln for ln in lines]


def _slow_parse(
    path: Path,
    rows: list[str],
    line_no: np.ndarray,
    idx: list[int],
    names: Sequence[str],
    delimiter: str,
    allow_missing: Collection[str],
    n_header: int,
) -> np.ndarray:
    """Row-by-row parse; raises at the first bad cell with its line number."""
    out = np.empty((len(rows), len(idx)), dtype=np.float64)
    need = max(idx) + 1
    for r, line in enumerate(rows):
        cells = _split(line, delimiter)
        if len(cells) < need:
            raise InputError(
                path,
                f"row has {len(cells)} fields, the header has {n_header} "
                f"(column {names[int(np.argmax(np.asarray(idx) >= len(cells)))]!r} is missing)",
                int(line_no[r]),
            )
        for c, (j, name) in enumerate(zip(idx, names)):
            cell = _clean(cells[j])
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
    """
    path = Path(path)
    columns = list(columns)
    if skip_rows < 0:
        raise InputError(path, f"skip_rows must be >= 0, got {skip_rows}")
    if not delimiter:
        raise InputError(path, "delimiter must not be empty")
    lines = _read_lines(path)
    if len(lines) <= skip_rows or all(not ln.strip() for ln in lines[skip_rows:]):
        raise InputError(path, "empty file: no header line" + (f" after skipping {skip_rows} rows" if skip_rows else ""))
    header_line = skip_rows + 1
    header_text = lines[skip_rows]
    if not header_text.strip():
        raise InputError(path, "header line is empty", header_line)
    header = [_clean(h) for h in _split(header_text, delimiter)]

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

    body = lines[skip_rows + 1 :]
    keep = [i for i, ln in enumerate(body) if ln.strip()]
    rows = [body[i] for i in keep]
    line_no = np.asarray(keep, dtype=np.int64) + header_line + 1
    if not rows:
        raise InputError(path, "no data rows after the header", header_line)

    data: np.ndarray | None = None
    if not columns:
        data = np.empty((len(rows), 0))
    elif not allow_missing:
        try:
            data = np.loadtxt(
                rows, delimiter=delimiter, usecols=idx, dtype=np.float64, ndmin=2,
                quotechar='"', comments=None,
            )
        except (ValueError, IndexError):
            data = None
        if data is not None and data.shape != (len(rows), len(idx)):
            data = None
    if data is None:
        data = _slow_parse(path, rows, line_no, idx, columns, delimiter, set(allow_missing), len(header))

    # Non-finite cells: NaN allowed only where asked for; inf never.
    bad = ~np.isfinite(data)
    if bad.any():
        allowed = np.array([c in allow_missing for c in columns], dtype=bool)
        bad &= ~(np.isnan(data) & allowed[None, :])
        if bad.any():
            r, c = np.argwhere(bad)[0]
            what = "NaN" if np.isnan(data[r, c]) else "infinite value"
            raise InputError(path, f"{what} in column {columns[c]!r}", int(line_no[r]))

    arrays = {name: np.ascontiguousarray(data[:, c]) for c, name in enumerate(columns)}
    return arrays, line_no


# --------------------------------------------------------------------------- timestamps


def apply_timestamp_policy(
    t: np.ndarray,
    policy: str,
    path: str | Path,
    *,
    lines: np.ndarray | None = None,
) -> tuple[np.ndarray, InputReport]:
    """Make time strictly increasing by an explicit policy.

    Returns ``(kept, report)``: ``kept`` are indices into ``t`` of the samples
    to keep, in output order, so ``t[kept]`` is strictly increasing.

    - ``"drop"``: keep a sample only if its time is strictly greater than that of
      the last kept sample; the others count as ``dropped_samples``.
    - ``"sort"``: stable sort by time; ``reordered_samples`` counts the samples
      whose position changed; then exact duplicate times are dropped (the first
      in file order is kept) and counted as ``dropped_samples``.
    - ``"error"``: raise :class:`InputError` at the first sample whose time is not
      strictly greater than the previous one.

    ``lines`` (optional): the file line number of each sample, for messages.
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    if policy not in TIMESTAMP_POLICIES:
        raise InputError(
            path, f"unknown timestamp policy {policy!r}; allowed: " + ", ".join(TIMESTAMP_POLICIES)
        )

    def where(i: int) -> int | None:
        return None if lines is None else int(lines[i])

    nonfinite = np.flatnonzero(~np.isfinite(t))
    if nonfinite.size:
        i = int(nonfinite[0])
        raise InputError(path, f"non-finite time {float(t[i])!r}" + ("" if lines is not None else f" at sample {i}"), where(i))

    report = InputReport()
    if n == 0:
        return np.arange(0, dtype=np.int64), report

    if policy == "error":
        bad = np.flatnonzero(np.diff(t) <= 0.0)
        if bad.size:
            i = int(bad[0]) + 1
            kind = "duplicate timestamp" if t[i] == t[i - 1] else "backward timestamp"
            at = "" if lines is not None else f" at sample {i}"
            raise InputError(
                path, f"{kind}{at}: t = {float(t[i])!r} s after t = {float(t[i - 1])!r} s (timestamp policy 'error')", where(i)
            )
        return np.arange(n, dtype=np.int64), report

    if policy == "drop":
        # The max over kept samples before i equals the max over all samples before i.
        prev_max = np.empty(n)
        prev_max[0] = -np.inf
        np.maximum.accumulate(t[:-1], out=prev_max[1:])
        keep = t > prev_max
        kept = np.flatnonzero(keep).astype(np.int64)
        dropped = n - kept.size
        report.dropped_samples = dropped
        if dropped:
            report.notes.append(f"dropped {dropped} samples with non-increasing time (timestamp policy 'drop')")
        return kept, report

    # sort
    order = np.argsort(t, kind="stable").astype(np.int64)
    moved = int(np.count_nonzero(order != np.arange(n)))
    ts = t[order]
    keep = np.ones(n, dtype=bool)
    keep[1:] = ts[1:] > ts[:-1]
    kept = order[keep]
    dropped = n - kept.size
    report.reordered_samples = moved
    report.dropped_samples = dropped
    if moved:
        report.notes.append(f"reordered {moved} samples to restore time order (timestamp policy 'sort')")
    if dropped:
        report.notes.append(f"dropped {dropped} samples with duplicate time (timestamp policy 'sort')")
    return kept, report


# --------------------------------------------------------------------------- helpers


def _check_time_args(path: Path, time_column: str | None, time_scale: float, rate_hz: float | None) -> None:
    if (time_column is None) == (rate_hz is None):
        raise InputError(path, "give exactly one of time_column and rate_hz")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(path, f"rate_hz must be a positive finite number, got {rate_hz!r}")
    if not (math.isfinite(time_scale) and time_scale > 0):
        raise InputError(path, f"time_scale must be a positive finite number, got {time_scale!r}")


def _check_columns(path: Path, what: str, cols: Sequence[str], counts: tuple[int, ...] = (3,)) -> list[str]:
    if isinstance(cols, str) or len(cols) not in counts:
        need = " or ".join(map(str, counts))
        raise InputError(path, f"{what} must name {need} columns (x, y, z), got {cols!r}")
    return list(cols)


def _time(
    arrays: dict[str, np.ndarray], n: int, time_column: str | None, time_scale: float, rate_hz: float | None
) -> np.ndarray:
    if time_column is not None:
        return arrays[time_column] * time_scale
    assert rate_hz is not None
    return np.arange(n, dtype=np.float64) / rate_hz


# --------------------------------------------------------------------------- IMU


def read_imu_csv(
    path: str | Path,
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
) -> ImuStream:
    """Read a body-frame IMU CSV into an :class:`ImuStream` in SI units.

    Time is ``time_column`` × ``time_scale`` seconds (e.g. a sample-number column
    with ``time_scale=1/60``) or ``i / rate_hz``; exactly one must be given.
    Accelerometer units: ``ACC_UNITS`` (``"g"`` is 9.80665 m/s^2); gyroscope
    units: ``GYRO_UNITS``.  ``stance_column`` holds 0/1 labels (1 = stance).
    ``axes`` (a signed axis map, :data:`bodyfusion.core.layout.AxisMap`) turns the file's
    axes into the body frame.  Non-increasing timestamps are handled by
    ``timestamp_policy`` (see :func:`apply_timestamp_policy`); what was changed is
    in ``stream.report``.  The stream is then checked
    (:func:`bodyfusion.io.imu_checks.check_imu`, against ``declared_rate_hz`` and with gaps
    longer than ``max_step_samples`` periods): ``stream.checks``, and one warning
    each in ``stream.report``.
    """
    path = Path(path)
    if acc_unit not in ACC_UNITS:
        raise InputError(path, f"unknown acc_unit {acc_unit!r}; allowed: " + ", ".join(ACC_UNITS))
    if gyro_unit not in GYRO_UNITS:
        raise InputError(path, f"unknown gyro_unit {gyro_unit!r}; allowed: " + ", ".join(GYRO_UNITS))
    if timestamp_policy not in TIMESTAMP_POLICIES:
        raise InputError(
            path, f"unknown timestamp policy {timestamp_policy!r}; allowed: " + ", ".join(TIMESTAMP_POLICIES)
        )
    _check_time_args(path, time_column, time_scale, rate_hz)
    acc_cols = _check_columns(path, "acc_columns", acc_columns)
    gyro_cols = _check_columns(path, "gyro_columns", gyro_columns)
    min_samples = max(int(min_samples), 1)

    cols: list[str] = []
    for c in ([time_column] if time_column is not None else []) + acc_cols + gyro_cols + (
        [stance_column] if stance_column is not None else []
    ):
        if c not in cols:
            cols.append(c)
    arrays, line_no = read_table(path, cols, skip_rows=skip_rows, delimiter=delimiter)
    n = line_no.size
    if n < min_samples:
        raise InputError(path, f"only {n} data rows; at least {min_samples} are needed")

    stance = None
    if stance_column is not None:
        s = arrays[stance_column]
        bad = np.flatnonzero((s != 0.0) & (s != 1.0))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                path, f"stance column {stance_column!r} must be 0 or 1, got {s[i]:g}", int(line_no[i])
            )
        stance = s == 1.0

    t = _time(arrays, n, time_column, time_scale, rate_hz)
    kept, report = apply_timestamp_policy(t, timestamp_policy, path, lines=line_no)
    if kept.size < min_samples:
        raise InputError(
            path, f"only {kept.size} samples left after timestamp policy {timestamp_policy!r}; "
            f"at least {min_samples} are needed"
        )

    acc = apply_axis_map(tuple(axes), np.column_stack([arrays[c] for c in acc_cols]) * ACC_UNITS[acc_unit])
    gyro = apply_axis_map(tuple(axes), np.column_stack([arrays[c] for c in gyro_cols]) * GYRO_UNITS[gyro_unit])
    stream = ImuStream(
        t=np.ascontiguousarray(t[kept]),
        acc_b=np.ascontiguousarray(acc[kept]),
        gyro_b=np.ascontiguousarray(gyro[kept]),
        stance=None if stance is None else np.ascontiguousarray(stance[kept]),
        source=str(path),
        report=report,
    )
    stream.checks = check_imu(stream.t, stream.acc_b, stream.gyro_b, source=path.name, acc_unit=acc_unit,
                              gyro_unit=gyro_unit, declared_rate_hz=declared_rate_hz,
                              max_step_samples=max_step_samples)
    for message in stream.checks.warnings:
        report.warn(message)
    return stream


# --------------------------------------------------------------------------- truth


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
    _check_time_args(path, time_column, time_scale, rate_hz)
    systems = {name: _check_columns(path, f"position_columns[{name!r}]", cols, (2, 3))
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
    t = _time(arrays, n, time_column, time_scale, rate_hz)
    kept, _ = apply_timestamp_policy(t, timestamp_policy, path, lines=line_no)

    out: dict[str, TruthTrack] = {}
    for name, triplet in systems.items():
        pos = np.column_stack([arrays[c] for c in triplet])[kept]
        ok = ~np.isnan(pos).any(axis=1)
        if not ok.any():
            raise InputError(path, f"system {name!r} has no row with all of {triplet} present")
        if pos.shape[1] == 2:
            pos = np.column_stack([pos, np.full(len(pos), np.nan)])
        out[name] = TruthTrack(
            t=np.ascontiguousarray(t[kept][ok]), pos_n=np.ascontiguousarray(pos[ok]), sparse=sparse
        )
    return out


LONG_TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")


def read_truth_long_csv(path: str | Path, *, sparse: bool = False) -> dict[str, TruthTrack]:
    """Read truth in the long format ``system,t,east_m,north_m,up_m`` (what ``fusion simulate``
    writes), one :class:`TruthTrack` per system; each system's times must increase strictly."""
    path = Path(path)
    lines = _read_lines(path)
    if not lines:
        raise InputError(path, "empty file")
    header = [_clean(c) for c in _split(lines[0], ",")]
    missing = [c for c in LONG_TRUTH_COLUMNS if c not in header]
    if missing:
        raise InputError(path, f"missing column(s) {missing}; the header has {header}", line=1)
    idx = [header.index(c) for c in LONG_TRUTH_COLUMNS]
    rows: dict[str, list[tuple[int, list[float]]]] = {}
    for k, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        cells = _split(line, ",")
        if len(cells) < len(header):
            raise InputError(path, f"expected {len(header)} fields, found {len(cells)}", line=k)
        name = _clean(cells[idx[0]])
        try:
            values = [float(cells[i]) for i in idx[1:]]
        except ValueError:
            raise InputError(path, "non-numeric cell in t/east_m/north_m/up_m", line=k) from None
        if not all(map(math.isfinite, values)):
            raise InputError(path, "NaN or inf cell", line=k)
        rows.setdefault(name, []).append((k, values))
    out: dict[str, TruthTrack] = {}
    for name, items in rows.items():
        line_no = np.array([k for k, _ in items])
        data = np.array([v for _, v in items])
        kept, _ = apply_timestamp_policy(data[:, 0], "error", path, lines=line_no)
        out[name] = TruthTrack(t=np.ascontiguousarray(data[kept, 0]), pos_n=np.ascontiguousarray(data[kept, 1:4]),
                               sparse=sparse)
    if not out:
        raise InputError(path, "no data rows")
    return out


def read_imu(section: ImuCsvConfig) -> ImuStream:
    """The stream a layout's IMU section describes, in SI units and the body frame, checked
    (:func:`read_imu_csv`; with both a time column and ``rate_hz``, the rate is the nominal
    one the timestamps are checked against)."""
    timed = section.time_column is not None
    return read_imu_csv(
        section.path, acc_columns=section.acc_columns, gyro_columns=section.gyro_columns,
        stance_column=section.stance_column, acc_unit=section.acc_unit, gyro_unit=section.gyro_unit,
        time_column=section.time_column, time_scale=section.time_scale, rate_hz=None if timed else section.rate_hz,
        skip_rows=section.skip_rows, delimiter=section.delimiter, timestamp_policy=section.timestamp_policy,
        axes=section.axes, declared_rate_hz=section.rate_hz if timed else None,
        max_step_samples=section.max_step_samples)
