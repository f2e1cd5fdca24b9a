"""GetSensorData phone logs (IPIN smartphone competition)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bodyfusion.base.errors import InputError
from bodyfusion.io.phone_log import read_getsensordata
from tests.paths import SHARED_DATA, needs_shared

IPIN = SHARED_DATA / "handheld_phone_ipin2023"


def synthetic_log(tmp_path: Path, n: int = 50, extra: list[str] | None = None) -> Path:
    lines = ["% header", "% ACCE;AppTimestamp(s);SensorTimestamp(s);..."]
    for k in range(n):
        app, sensor = 0.02 * k + 0.003 * (k % 3), 5000.0 + 0.02 * k
        lines.append(f"ACCE;{app:.4f};{sensor:.4f};0.1;0.2;9.8;3")
        lines.append(f"GYRO;{app:.4f};{sensor:.4f};0.01;0.02;0.03;3")
        lines.append(f"MAGN;{app:.4f};{sensor:.4f};10;;-20;5;3")
    lines += ["GNSS;0.30;1686735550.999;49.461281;11.110946;389.8;7.4;6.0;0.1;15;10",
              "GNSS;0.31;1686735550.999;49.461281;11.110946;389.8;7.4;6.0;0.1;15;10",
              "GNSS;1.30;1686735551.999;49.461290;11.110950;389.7;7.4;5.0;0.2;15;9",
              "POSI;0.5;1;49.4613;11.1109;0;100", "WIFI;0.4;net;aa:bb;2412;-70;"]
    path = tmp_path / "log.txt"
    path.write_text("\n".join(lines + (extra or [])) + "\n")
    return path


def test_reads_every_used_line_type(tmp_path):
    log = read_getsensordata(synthetic_log(tmp_path))
    assert len(log.acc.t) == len(log.gyro.t) == 50
    np.testing.assert_allclose(np.diff(log.acc.t), 0.02, atol=1e-9)  # sensor clock intervals
    np.testing.assert_allclose(log.acc.xyz[0], [0.1, 0.2, 9.8])
    np.testing.assert_allclose(log.magn.xyz[0], [10, -20, 5])  # the empty field of the MAGN format
    assert len(log.gnss) == 2 and log.gnss.accuracy_m[0] == 6.0 and log.gnss.course_deg[0] == pytest.approx(7.4)
    assert log.reference.counter.tolist() == [1] and log.reference.building.tolist() == [100]
    assert log.line_types["WIFI"] == 1
    assert any("repeated" in n for n in log.report.notes)


def test_inertial_times_are_on_the_app_clock(tmp_path):
    log = read_getsensordata(synthetic_log(tmp_path))
    assert abs(np.median(log.acc.t - 0.02 * np.arange(50))) < 0.005


def test_malformed_lines_are_skipped_and_counted_with_their_line(tmp_path):
    path = synthetic_log(tmp_path, extra=["ACCE;1.0;5001.0;abc;0;9.8;3", "GYRO;1.0"])
    log = read_getsensordata(path)
    note = next(n for n in log.report.notes if "malformed" in n)
    assert "skipped 2 malformed" in note and "[158, 159]" in note


@pytest.mark.parametrize("posi", ["POSI;0.9;2;49.4613;11.1109;1e300;100", "POSI;0.9;2;49.4613;11.1109;0;1.5",
                                  "POSI;0.9;3e10;49.4613;11.1109;0;100"], ids=["floor_beyond_int", "building_half",
                                                                             "counter_beyond_int"])
def test_a_reference_point_without_whole_numbers_where_they_belong_is_malformed(tmp_path, posi):
    """A POSI line's counter, floor and building are whole numbers: another number there is a
    malformed line, skipped and counted, not cast to an integer of any value."""
    log = read_getsensordata(synthetic_log(tmp_path, extra=[posi]))
    assert log.reference.counter.tolist() == [1]
    assert any("skipped 1 malformed" in n and "[158]" in n for n in log.report.notes)


def test_too_few_inertial_lines_is_one_line_error(tmp_path):
    with pytest.raises(InputError, match="fewer than 10 usable ACCE"):
        read_getsensordata(synthetic_log(tmp_path, n=5))
    with pytest.raises(InputError, match="file not found"):
        read_getsensordata(tmp_path / "missing.txt")


@needs_shared("handheld_phone_ipin2023")
def test_ipin_trial01_log():
    log = read_getsensordata(IPIN / "IPIN2023_T3_TrainingTrial01_repetition04.txt")
    assert len(log.acc.t) == 10319
    assert np.median(np.diff(log.acc.t)) == pytest.approx(0.02, abs=1e-6)
    assert len(log.reference.t) == 14
    assert len(log.gnss) == 207 and np.nanmedian(log.gnss.accuracy_m) == pytest.approx(4.0)


def test_a_log_in_reverse_time_is_refused_not_crashed(tmp_path):
    path = synthetic_log(tmp_path)
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:2] + lines[2:][::-1]) + "\n")
    with pytest.raises(InputError, match="only 1 of the 50 ACCE lines are in increasing sensor time"):
        read_getsensordata(path)


def test_readings_beyond_any_sensor_are_dropped_and_warned(tmp_path, caplog):
    log = read_getsensordata(synthetic_log(tmp_path, extra=["ACCE;1.0;5001.0;1e300;0;9.8;3"]))
    assert len(log.acc.t) == 50
    assert any("dropped 1 ACCE samples beyond any sensor's range" in w for w in log.report.warnings)
