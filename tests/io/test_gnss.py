"""GNSS readers (CSV, NMEA 0183) and geodetic ↔ ENU."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pynmea2
import pytest

from bodyfusion.base.errors import InputError
from bodyfusion.io.gnss import GnssFixes, enu_to_geodetic, read_gnss_csv, read_nmea


def gga(time: str, lat: str, ns: str, lon: str, ew: str, quality: str = "1", hdop: str = "0.9") -> str:
    return str(pynmea2.GGA("GP", "GGA", (time, lat, ns, lon, ew, quality, "08", hdop, "545.4", "M", "46.9", "M", "", "")))


def rmc(time: str, status: str = "A", speed_kn: str = "2.0", course: str = "90.0") -> str:
    return str(pynmea2.RMC("GP", "RMC", (time, status, "4807.038", "N", "01131.000", "E", speed_kn, course,
                                         "230394", "", "")))


def write(tmp_path: Path, lines: list[str]) -> Path:
    path = tmp_path / "log.nmea"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_nmea_reads_gga_positions_with_rmc_speed_and_course(tmp_path):
    path = write(tmp_path, [gga("120000", "4807.038", "N", "01131.000", "E"), rmc("120000"),
                            gga("120001", "4807.039", "N", "01131.000", "E"), rmc("120001", course="45.0")])
    fixes = read_nmea(path)
    assert len(fixes) == 2
    np.testing.assert_allclose(fixes.t, [43200.0, 43201.0])
    assert fixes.lat_deg[0] == pytest.approx(48.1173)
    assert fixes.lon_deg[0] == pytest.approx(11.516666667)
    assert fixes.height_m[0] == pytest.approx(545.4 + 46.9)
    np.testing.assert_allclose(fixes.speed_mps, 2.0 * 1852 / 3600)
    np.testing.assert_allclose(fixes.course_deg, [90.0, 45.0])
    np.testing.assert_allclose(fixes.accuracy_m, 0.9 * 5.0)


def test_nmea_skips_and_counts_bad_sentences(tmp_path):
    good = gga("120000", "4807.038", "N", "01131.000", "E")
    bad_checksum = good[:-2] + ("00" if good[-2:] != "00" else "11")
    lines = [good, bad_checksum, "$GPGGA,garbage", gga("120001", "", "", "", "", quality="0"),
             rmc("120001", status="V"), str(pynmea2.GSA("GP", "GSA", ("A", "3") + ("",) * 15)),
             gga("115959", "4807.038", "N", "01131.000", "E"),  # backward in time
             gga("120002", "9907.038", "N", "01131.000", "E")]  # latitude 99°: out of range
    fixes = read_nmea(write(tmp_path, lines))
    assert len(fixes) == 1
    note = fixes.report.notes[0]
    assert "2 bad or missing checksum" in note and "2 no fix" in note and "1 other sentence" in note
    assert fixes.report.dropped_samples >= 5


def test_nmea_with_nothing_usable_is_one_line_error(tmp_path):
    with pytest.raises(InputError, match="no usable GNSS fix"):
        read_nmea(write(tmp_path, [rmc("120000", status="V"), "$GPGGA,garbage"]))


def test_nmea_time_wraps_past_midnight(tmp_path):
    fixes = read_nmea(write(tmp_path, [gga("235959", "4807.038", "N", "01131.000", "E"),
                                       gga("000001", "4807.038", "N", "01131.000", "E")]))
    np.testing.assert_allclose(np.diff(fixes.t), 2.0)


def test_gnss_csv_reader_and_enu_round_trip(tmp_path):
    path = tmp_path / "gnss.csv"
    path.write_text("t,lat,lon,h,acc\n0,49.4613,11.1109,390,4.0\n1,49.46131,11.11091,390.5,\n")
    fixes = read_gnss_csv(path, time_column="t", lat_column="lat", lon_column="lon", height_column="h",
                          accuracy_column="acc")
    assert len(fixes) == 2 and np.isnan(fixes.accuracy_m[1])
    origin = (49.4613, 11.1109, 390.0)
    enu = fixes.enu(origin)
    np.testing.assert_allclose(enu[0], 0.0, atol=1e-6)
    assert enu[1, 1] == pytest.approx(1.112, abs=0.01)  # 1e-5 deg of latitude ≈ 1.11 m north
    back = enu_to_geodetic(enu, origin)
    np.testing.assert_allclose(back[:, 0], fixes.lat_deg, atol=1e-10)
    np.testing.assert_allclose(back[:, 1], fixes.lon_deg, atol=1e-10)


def test_select_keeps_the_report():
    f = GnssFixes(*(np.arange(3.0) for _ in range(7)))
    f.report.notes.append("x")
    assert f.select(np.array([True, False, True])).report.notes == ["x"]


def test_repeats_previous_marks_a_receiver_holding_its_position():
    lat = np.array([49.0, 49.0, 49.0, 49.00001, 49.00001])
    lon = np.array([11.0, 11.0, 11.0, 11.0, 11.00001])
    f = GnssFixes(np.arange(5.0), lat, lon, np.zeros(5), *(np.full(5, np.nan) for _ in range(3)))
    assert f.repeats_previous().tolist() == [False, True, True, False, False]


@pytest.mark.parametrize(("height", "accuracy"), [("1e308", "4.0"), ("390", "1e308"), ("390", "-2")])
def test_fixes_with_impossible_height_or_accuracy_are_dropped_and_counted(tmp_path, height, accuracy):
    """A height no receiver reports (1e308 m moved the phone off any float) or an accuracy
    that is no fix's: the fix is dropped and said, the others kept (a non-finite cell is refused
    with its line by the table reader)."""
    path = tmp_path / "gnss.csv"
    path.write_text(f"t,lat,lon,h,acc\n0,49.4613,11.1109,390,4.0\n1,49.46131,11.11091,{height},{accuracy}\n"
                    "2,49.46132,11.11092,390,4.0\n")
    fixes = read_gnss_csv(path, time_column="t", lat_column="lat", lon_column="lon", height_column="h",
                          accuracy_column="acc")
    np.testing.assert_array_equal(fixes.t, [0.0, 2.0])
    assert fixes.report.dropped_samples == 1
    assert any("height or accuracy out of range" in note for note in fixes.report.notes)


def test_an_nmea_altitude_of_infinity_drops_its_fix(tmp_path):
    fields = ("092751.000", "4807.038", "N", "01131.000", "E", "1", "08", "0.9", "inf", "M", "46.9", "M", "", "")
    bad = str(pynmea2.GGA("GP", "GGA", fields))
    fixes = read_nmea(write(tmp_path, [gga("092750.000", "4807.038", "N", "01131.000", "E"), bad,
                                       gga("092752.000", "4807.038", "N", "01131.000", "E")]))
    assert len(fixes) == 2 and np.all(np.isfinite(fixes.height_m))
