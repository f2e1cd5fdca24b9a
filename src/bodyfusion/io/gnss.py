"""GNSS fixes: containers, readers (CSV, NMEA 0183 via pynmea2) and geodetic ↔ ENU.

Geodetic coordinates are WGS84 latitude/longitude (deg) and ellipsoidal height (m);
the navigation frame is local ENU about an origin, converted with pymap3d.
Readers skip what cannot be used and count it in the :class:`InputReport`
(bad checksums, no-fix or empty sentences, coordinates out of range, non-increasing
time); when nothing usable remains they raise a one-line :class:`InputError`.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymap3d
import pynmea2

from bodyfusion.base.errors import InputError
from bodyfusion.base.extras import import_optional
from bodyfusion.base.sections import TableSection
from bodyfusion.base.types import InputReport
from bodyfusion.io.tables import read_source

KNOT = 1852.0 / 3600.0
"""One knot in m/s."""


@dataclass
class GnssFixes:
    """Receiver fixes. t (s), lat/lon (deg), height (m), accuracy_m (1-σ horizontal, m;
    NaN when the receiver gives none), speed (m/s) and course (deg clockwise from North;
    NaN when unknown)."""

    t: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    height_m: np.ndarray
    accuracy_m: np.ndarray
    speed_mps: np.ndarray
    course_deg: np.ndarray
    report: InputReport = field(default_factory=InputReport)

    def __len__(self) -> int:
        return len(self.t)

    def enu(self, origin: tuple[float, float, float]) -> np.ndarray:
        """(N, 3) positions in the ENU frame about ``origin`` (lat deg, lon deg, height m)."""
        e, n, u = pymap3d.geodetic2enu(self.lat_deg, self.lon_deg, self.height_m, *origin)
        return np.column_stack([e, n, u])

    def repeats_previous(self) -> np.ndarray:
        """(N,) True where a fix repeats the previous fix's latitude, longitude and height
        exactly: a receiver holding its last solution (phones do while standing still)."""
        same = (np.diff(self.lat_deg) == 0) & (np.diff(self.lon_deg) == 0) & (np.diff(self.height_m) == 0)
        return np.concatenate([[False], same])

    def select(self, keep: np.ndarray) -> GnssFixes:
        return GnssFixes(self.t[keep], self.lat_deg[keep], self.lon_deg[keep], self.height_m[keep],
                         self.accuracy_m[keep], self.speed_mps[keep], self.course_deg[keep], self.report)


def enu_to_geodetic(pos_n: np.ndarray, origin: tuple[float, float, float]) -> np.ndarray:
    """(N, 3) ENU positions about ``origin`` → (N, 3) latitude (deg), longitude (deg), height (m)."""
    lat, lon, h = pymap3d.enu2geodetic(pos_n[:, 0], pos_n[:, 1], pos_n[:, 2], *origin)
    return np.column_stack([lat, lon, h])


HEIGHT_LIMIT_M = 100_000.0
"""Largest |height| (m) of a fix a pedestrian's receiver can report."""
ACCURACY_LIMIT_M = 10_000.0
"""Largest reported accuracy (m) of a usable fix."""


def clean_fixes(rows: np.ndarray, path: str | Path, report: InputReport) -> GnssFixes:
    """Rows (t, lat, lon, h, accuracy, speed, course) → fixes with out-of-range or non-finite
    coordinates, heights beyond :data:`HEIGHT_LIMIT_M`, negative accuracies or accuracies beyond
    :data:`ACCURACY_LIMIT_M` (a missing accuracy, NaN, stays) and non-increasing times dropped
    and counted."""
    if rows.size == 0:
        raise InputError(path, "no usable GNSS fix")
    with np.errstate(invalid="ignore"):
        ok = ((np.abs(rows[:, 1]) <= 90) & (np.abs(rows[:, 2]) <= 180) & (np.abs(rows[:, 3]) <= HEIGHT_LIMIT_M)
              & np.isfinite(rows[:, 0]) & ~(rows[:, 4] > ACCURACY_LIMIT_M) & ~(rows[:, 4] < 0))
    if (~ok).any():
        report.dropped_samples += int((~ok).sum())
        report.notes.append(f"dropped {int((~ok).sum())} GNSS fixes with coordinates, height or accuracy out of "
                            "range")
    rows = rows[ok]
    keep, last = [], -np.inf
    for k, t in enumerate(rows[:, 0]):
        if t > last:
            keep.append(k)
            last = t
    dropped = len(rows) - len(keep)
    if dropped:
        report.dropped_samples += dropped
        report.notes.append(f"dropped {dropped} GNSS fixes with non-increasing time")
    rows = rows[keep]
    if len(rows) == 0:
        raise InputError(path, "no usable GNSS fix")
    return GnssFixes(*(np.ascontiguousarray(rows[:, k]) for k in range(7)), report=report)


def read_gnss_csv(source: str | Path | TableSection, *, time_column: str, lat_column: str, lon_column: str,
                  height_column: str | None = None, accuracy_column: str | None = None,
                  speed_column: str | None = None, course_column: str | None = None,
                  delimiter: str = ",") -> GnssFixes:
    """GNSS fixes from a CSV with named columns (deg, m, m/s, deg), or from a table section's
    in-memory table with those columns (:func:`bodyfusion.io.tables.read_source`)."""
    optional = [c for c in (height_column, accuracy_column, speed_column, course_column) if c]
    arrays, _, path = read_source(source, [time_column, lat_column, lon_column, *optional], delimiter=delimiter,
                                  allow_missing=optional)
    n = len(arrays[time_column])
    col = lambda name: arrays[name] if name else np.full(n, np.nan)
    height = arrays[height_column] if height_column else np.zeros(n)
    rows = np.column_stack([arrays[time_column], arrays[lat_column], arrays[lon_column], height,
                            col(accuracy_column), col(speed_column), col(course_column)])
    return clean_fixes(rows, path, InputReport())


def read_nmea(path: str | Path, *, user_range_error_m: float = 5.0) -> GnssFixes:
    """GNSS fixes from an NMEA 0183 log (GGA for position, RMC for speed and course).

    Time is seconds since the first sentence's UTC midnight (a day is added when the time
    of day wraps past midnight). Accuracy: HDOP × ``user_range_error_m`` (GGA has no accuracy field).
    Skipped and counted: bad or missing checksums, unparsable sentences, no-fix GGA (quality 0),
    void RMC, empty fields.
    """
    path = Path(path)
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror}") from None
    report = InputReport()
    counts = {"bad_or_missing_checksum": 0, "unparsable": 0, "no_fix": 0, "other_sentence": 0}
    gga: list[list[float]] = []
    rmc: dict[float, tuple[float, float]] = {}
    clock = _DayClock()
    for line in lines:
        line = line.strip()
        if not line:
            continue
        try:
            msg = pynmea2.parse(line, check=True)
        except pynmea2.ChecksumError:
            counts["bad_or_missing_checksum"] += 1
            continue
        except (pynmea2.ParseError, ValueError, AttributeError):
            counts["unparsable"] += 1
            continue
        kind = msg.sentence_type
        try:
            stamp = msg.timestamp if kind in ("RMC", "GGA") else None
            if stamp is not None and not isinstance(stamp, dt.time):  # a time field not hhmmss.ss
                raise ValueError(stamp)
            if kind == "RMC":
                if msg.status != "A" or stamp is None:
                    counts["no_fix"] += 1
                    continue
                t = clock(stamp)
                rmc[t] = (float(msg.spd_over_grnd or np.nan) * KNOT,
                          float(msg.true_course) if msg.true_course not in (None, "") else np.nan)
            elif kind == "GGA":
                if not msg.gps_qual or int(msg.gps_qual) == 0 or msg.lat in ("", None) or stamp is None:
                    counts["no_fix"] += 1
                    continue
                t = clock(stamp)
                hdop = float(msg.horizontal_dil) if msg.horizontal_dil else np.nan
                alt = float(msg.altitude or 0.0) + float(msg.geo_sep or 0.0)
                gga.append([t, float(msg.latitude), float(msg.longitude), alt, hdop * user_range_error_m])
            else:
                counts["other_sentence"] += 1
        except (TypeError, ValueError, AttributeError):
            counts["unparsable"] += 1
    skipped = counts["bad_or_missing_checksum"] + counts["unparsable"] + counts["no_fix"]
    report.dropped_samples += skipped
    report.notes.append("NMEA: " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v))
    rows = [row + list(rmc.get(row[0], (np.nan, np.nan))) for row in gga]  # file order
    return clean_fixes(np.array(rows, dtype=float).reshape(-1, 7), path, report)


UBX_WEEK_S = 604800.0
"""A GPS week (s): ``iTOW`` counts the time of week and starts again at each week."""


def read_ubx(path: str | Path) -> GnssFixes:
    """GNSS fixes from a u-blox UBX log: its ``NAV-PVT`` messages (read with pyubx2, the ``[ubx]``
    extra), those with a valid fix (``gnssFixOk``, 2-D or 3-D). Time is the GPS time of week
    (``iTOW``, s; a week is added where it starts again); height the ellipsoidal one (m);
    accuracy the receiver's horizontal accuracy estimate ``hAcc`` (m); speed and course the
    ground speed (m/s) and heading of motion (deg). Other messages are skipped and counted, as
    are fixes without ``gnssFixOk``; a message that does not parse is refused naming the file."""
    pyubx2 = import_optional("pyubx2", "ubx", "reading a u-blox UBX log")
    path = Path(path)
    report = InputReport()
    rows: list[list[float]] = []
    counts = {"no_fix": 0, "other_message": 0}
    weeks, last = 0, None
    try:
        with path.open("rb") as stream:
            reader = pyubx2.UBXReader(stream, protfilter=pyubx2.UBX_PROTOCOL, quitonerror=pyubx2.ERR_RAISE)
            for _, message in reader:
                if message is None:
                    break
                if message.identity != "NAV-PVT":
                    counts["other_message"] += 1
                    continue
                if not message.gnssFixOk or message.fixType not in (2, 3):
                    counts["no_fix"] += 1
                    continue
                tow = message.iTOW / 1000.0
                if last is not None and tow < last - UBX_WEEK_S / 2:
                    weeks += 1
                last = tow
                rows.append([weeks * UBX_WEEK_S + tow, float(message.lat), float(message.lon), message.height / 1000.0,
                             message.hAcc / 1000.0, message.gSpeed / 1000.0, float(message.headMot)])
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror}") from None
    except (pyubx2.UBXParseError, pyubx2.UBXStreamError, pyubx2.UBXMessageError, pyubx2.UBXTypeError) as err:
        raise InputError(path, f"not a UBX log: {err}") from None
    report.dropped_samples += counts["no_fix"]
    report.notes.append("UBX: " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v))
    return clean_fixes(np.array(rows, dtype=float).reshape(-1, 7), path, report)


class _DayClock:
    """UTC time of day → seconds since the first midnight, counting midnight wraps."""

    def __init__(self) -> None:
        self.day = 0
        self.last = None

    def __call__(self, t: dt.time) -> float:
        sod = t.hour * 3600.0 + t.minute * 60.0 + t.second + t.microsecond * 1e-6
        if self.last is not None and sod < self.last - 43200.0:
            self.day += 1
        self.last = sod
        return self.day * 86400.0 + sod
