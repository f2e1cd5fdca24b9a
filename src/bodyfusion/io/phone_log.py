"""Reader of GetSensorData phone logs (the IPIN competition's smartphone logs).

One reading per line, ``;``-separated, the line type first (header lines start with
``%`` and document each type). Used here: ``ACCE`` (m/s^2), ``GYRO`` (rad/s), ``MAGN``
(µT), ``GNSS`` (lat, lon, altitude, bearing, accuracy, speed, satellites) and ``POSI``
(surveyed reference points: time, counter, lat, lon, floor, building).

Time base: every line carries the app's timestamp (s, one clock for all sensors);
inertial lines also carry the sensor's own timestamp, whose differences are the true
sampling intervals. Inertial sample times are the sensor timestamps shifted onto the
app clock by the median offset of the two, so dt is the sensor's and every stream
(GNSS, POSI) shares the app's time base. Lines of other types are counted, malformed
lines are skipped and counted with their first line numbers, repeated GNSS fixes (the
same sensor timestamp) are dropped and counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import InputReport
from bodyfusion.io.gnss import GnssFixes, clean_fixes
from bodyfusion.io.imu import ACC_LIMIT_MPS2, GYRO_LIMIT_RADPS, MAX_GAP_S
from bodyfusion.io.timestamps import apply_timestamp_policy

USED_TYPES = {"ACCE": 5, "GYRO": 5, "MAGN": 5, "GNSS": 10, "POSI": 6}
"""Line type → number of numeric fields after the type that are used."""
INTEGER_FIELDS = {"POSI": (1, 4, 5)}
"""Line type → the used fields that are whole numbers (a reference point's counter, floor and
building): a line holding another number there (1.5, 1e300) is malformed."""
MIN_TRIAD_SAMPLES = 10
"""Fewest ACCE and GYRO samples, in increasing time, a log must hold (fewer MAGN: no magnetometer)."""
TRIAD_LIMIT = {"ACCE": ACC_LIMIT_MPS2, "GYRO": GYRO_LIMIT_RADPS, "MAGN": 1.0e4}
"""Largest plausible reading per axis (m/s², rad/s, µT); a larger one is corrupt and dropped."""


@dataclass
class TriadSamples:
    """(N,) times on the app clock (s) and (N, 3) values in the phone's frame."""

    t: np.ndarray
    xyz: np.ndarray


@dataclass
class ReferencePoints:
    """Surveyed points: time (s, app clock), counter, lat/lon (deg), floor and building ids."""

    t: np.ndarray
    counter: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    floor: np.ndarray
    building: np.ndarray


@dataclass
class PhoneLog:
    acc: TriadSamples
    gyro: TriadSamples
    magn: TriadSamples | None
    gnss: GnssFixes | None
    reference: ReferencePoints | None
    report: InputReport = field(default_factory=InputReport)
    line_types: dict[str, int] = field(default_factory=dict)


def _triad(rows: list[list[float]], path: Path, name: str, report: InputReport) -> TriadSamples:
    a = np.array(rows, dtype=float)
    app, sensor = a[:, 0], a[:, 1]
    t = sensor + np.median(app - sensor)
    keep, rep, _ = apply_timestamp_policy(t, "drop", path)
    plausible = np.all(np.abs(a[keep, 2:5]) <= TRIAD_LIMIT[name], axis=1)
    if not plausible.all():
        report.dropped_samples += int((~plausible).sum())
        report.warn(f"{path.name}: dropped {(~plausible).sum()} {name} samples beyond any sensor's range "
                    f"({TRIAD_LIMIT[name]:g} per axis)")
        keep = keep[plausible]
    if keep.size < MIN_TRIAD_SAMPLES:
        raise InputError(path, f"only {keep.size} of the {len(t)} {name} lines are in increasing sensor time; "
                         f"at least {MIN_TRIAD_SAMPLES} are needed")
    gap = np.diff(t[keep])
    if gap.size and gap.max() > MAX_GAP_S:
        j = int(np.argmax(gap))
        raise InputError(path, f"a gap of {gap[j]:.6g} s between {name} samples (t = {t[keep[j]]:.6g} → "
                         f"{t[keep[j + 1]]:.6g} s), longer than {MAX_GAP_S:g} s: split the log there")
    if rep.dropped_samples:
        report.dropped_samples += rep.dropped_samples
        report.notes.append(f"{name}: dropped {rep.dropped_samples} samples with non-increasing sensor time")
    return TriadSamples(np.ascontiguousarray(t[keep]), np.ascontiguousarray(a[keep, 2:5]))


def read_getsensordata(path: str | Path) -> PhoneLog:
    """Read a GetSensorData log; see the module docstring for the time base and policies."""
    path = Path(path)
    try:
        text = path.read_text(errors="replace")
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror}") from None
    rows: dict[str, list[list[float]]] = {k: [] for k in USED_TYPES}
    types: dict[str, int] = {}
    malformed: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line or line.startswith("%"):
            continue
        fields = line.split(";")
        kind = fields[0].strip()
        types[kind] = types.get(kind, 0) + 1
        need = USED_TYPES.get(kind)
        if need is None:
            continue
        values = [f for f in fields[1:] if f.strip() != ""][:need]
        try:
            parsed = [float(v) for v in values]
        except ValueError:
            parsed = []
        if len(parsed) < need or not np.all(np.isfinite(parsed)) or any(
                not (abs(parsed[i]) < 2**31 and parsed[i] == int(parsed[i])) for i in INTEGER_FIELDS.get(kind, ())):
            malformed.append(number)
            continue
        rows[kind].append(parsed)
    report = InputReport()
    if malformed:
        report.dropped_samples += len(malformed)
        report.notes.append(f"skipped {len(malformed)} malformed lines (first at lines {malformed[:5]})")
    ignored = {k: v for k, v in types.items() if k not in USED_TYPES}
    if ignored:
        report.notes.append("line types not used: " + ", ".join(f"{k} ×{v}" for k, v in sorted(ignored.items())))
    for kind in ("ACCE", "GYRO"):
        if len(rows[kind]) < MIN_TRIAD_SAMPLES:
            raise InputError(path, f"fewer than {MIN_TRIAD_SAMPLES} usable {kind} lines")
    acc = _triad(rows["ACCE"], path, "ACCE", report)
    gyro = _triad(rows["GYRO"], path, "GYRO", report)
    magn = _triad(rows["MAGN"], path, "MAGN", report) if len(rows["MAGN"]) >= MIN_TRIAD_SAMPLES else None
    gnss = None
    if rows["GNSS"]:
        g = np.array(rows["GNSS"])
        _, first = np.unique(g[:, 1], return_index=True)  # the same fix logged twice
        repeated = len(g) - len(first)
        if repeated:
            report.notes.append(f"GNSS: dropped {repeated} repeated fixes")
            report.dropped_samples += repeated
        g = g[np.sort(first)]
        # app time, lat, lon, altitude, accuracy, speed, bearing
        fix_rows = np.column_stack([g[:, 0], g[:, 2], g[:, 3], g[:, 4], g[:, 6], g[:, 7], g[:, 5]])
        gnss = clean_fixes(fix_rows, path, report)
    reference = None
    if rows["POSI"]:
        p = np.array(rows["POSI"])
        reference = ReferencePoints(p[:, 0], p[:, 1].astype(int), p[:, 2], p[:, 3], p[:, 4].astype(int),
                                    p[:, 5].astype(int))
    return PhoneLog(acc, gyro, magn, gnss, reference, report, types)
