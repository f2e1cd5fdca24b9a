"""IMU sanity checks: every wrongly declared or damaged stream is warned about, counted, and the
warning reaches metrics.json and the console."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bodyfusion.io.imu import read_imu_csv
from bodyfusion.io.imu_checks import check_imu

RATE = 100.0


def walking_imu(seconds: float = 8.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A foot-like stream in SI units: 1 s still, then 1 Hz swings (rate up to 5 rad/s, specific
    force ±6 m/s^2 about gravity), with sensor noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE)) / RATE
    swing = np.where(t > 1.0, np.clip(np.sin(2 * np.pi * (t - 1.0)), 0.0, None), 0.0)
    acc = np.column_stack([6.0 * swing * np.cos(2 * np.pi * t), np.zeros_like(t), 9.81 + 4.0 * swing])
    gyro = np.column_stack([np.zeros_like(t), 5.0 * swing, np.zeros_like(t)])
    return t, acc + rng.normal(0, 0.02, acc.shape), gyro + rng.normal(0, 0.003, gyro.shape)


def write_csv(path: Path, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray) -> Path:
    data = np.column_stack([t, acc, gyro])
    np.savetxt(path, data, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    return path


def read(path: Path, **kw):
    return read_imu_csv(path, acc_columns=["ax", "ay", "az"], gyro_columns=["gx", "gy", "gz"], time_column="t", **kw)


def test_a_clean_stream_raises_no_warning(tmp_path):
    stream = read(write_csv(tmp_path / "imu.csv", *walking_imu()))
    assert stream.checks.warnings == [] and stream.report.warnings == []
    assert stream.checks.rest_specific_force_mps2 == pytest.approx(9.81, abs=0.05)


def test_g_declared_as_metres_per_second_squared_is_warned(tmp_path):
    t, acc, gyro = walking_imu()
    stream = read(write_csv(tmp_path / "imu.csv", t, acc / 9.80665, gyro))
    (line,) = stream.report.warnings
    assert "not near gravity" in line and "set acc_unit: g" in line and "imu.csv" in line


def test_metres_per_second_squared_declared_as_g_is_warned(tmp_path):
    stream = read(write_csv(tmp_path / "imu.csv", *walking_imu()), acc_unit="g")
    (line,) = stream.report.warnings
    assert "set acc_unit: m/s^2" in line


def test_degrees_per_second_declared_as_radians_is_warned(tmp_path):
    t, acc, gyro = walking_imu()
    stream = read(write_csv(tmp_path / "imu.csv", t, acc, np.degrees(gyro)))
    (line,) = stream.report.warnings
    assert "faster than any body segment" in line and "set gyro_unit: deg/s" in line


def test_radians_per_second_declared_as_degrees_is_warned(tmp_path):
    stream = read(write_csv(tmp_path / "imu.csv", *walking_imu()), gyro_unit="deg/s")
    (line,) = stream.report.warnings
    assert "never exceeds" in line and "set gyro_unit: rad/s" in line


def test_a_declared_rate_that_the_timestamps_contradict_is_warned(tmp_path):
    stream = read(write_csv(tmp_path / "imu.csv", *walking_imu()), declared_rate_hz=200.0)
    (line,) = stream.report.warnings
    assert "timestamps give 100 Hz" in line and "declares 200 Hz" in line


def test_milliseconds_declared_as_seconds_is_warned(tmp_path):
    t, acc, gyro = walking_imu()
    stream = read(write_csv(tmp_path / "imu.csv", 1000.0 * t, acc, gyro))
    assert any("sample rate of 0.1 Hz" in w for w in stream.report.warnings)


def test_gaps_are_found_counted_and_warned(tmp_path):
    t, acc, gyro = walking_imu()
    keep = np.ones(t.size, dtype=bool)
    keep[300:340] = False  # 0.4 s missing
    keep[500:503] = False  # 3 samples missing: not a gap at max_step_samples 5
    stream = read(write_csv(tmp_path / "imu.csv", t[keep], acc[keep], gyro[keep]))
    assert stream.checks.gap_index.tolist() == [300]
    assert stream.checks.gap_missing_s.sum() == pytest.approx(0.40, abs=1e-6)
    (line,) = stream.report.warnings
    assert "1 gap(s)" in line and "0.4 s missing" in line


def test_clipped_samples_are_counted(tmp_path):
    t, acc, gyro = walking_imu()
    acc[:, 0] = np.clip(acc[:, 0], -2.0, 2.0)  # a ±2 m/s^2 accelerometer range on x
    stream = read(write_csv(tmp_path / "imu.csv", t, acc, gyro))
    clipped = np.sum(np.abs(acc[:, 0]) == 2.0)
    assert 10 < stream.checks.clipped_acc_samples <= clipped
    assert stream.checks.clipped_gyro_samples == 0
    assert any("accelerometer saturated" in w for w in stream.report.warnings)


def test_checks_work_on_arrays_alone():
    t, acc, gyro = walking_imu()
    checks = check_imu(t, acc / 9.80665, gyro, source="array", acc_unit="m/s^2", gyro_unit="rad/s")
    assert checks.to_dict()["warnings"] == 1 and checks.rate_hz == pytest.approx(RATE)


@pytest.mark.parametrize("g", [9.80665, 1.0])  # in m/s^2, and g declared as m/s^2 (a plausibility warning)
def test_without_plausibility_the_gaps_and_clipping_are_the_full_checks_and_nothing_is_reported_of_units(g):
    """A live pass's checks: what shapes the inputs (gaps, clipping) as the full checks find it;
    the units, rate and rest checks (which only report) left out."""
    t, acc, gyro = walking_imu()
    keep = np.ones(t.size, dtype=bool)
    keep[300:340] = False
    acc[:, 0] = np.clip(acc[:, 0], -2.0, 2.0)
    t, acc, gyro = t[keep], acc[keep] * g / 9.80665, gyro[keep]
    full = check_imu(t, acc, gyro, source="array", acc_unit="m/s^2", gyro_unit="rad/s", declared_rate_hz=50.0)
    inputs = check_imu(t, acc, gyro, source="array", acc_unit="m/s^2", gyro_unit="rad/s", declared_rate_hz=50.0,
                       plausibility=False)
    assert inputs.gap_index.tolist() == full.gap_index.tolist() == [300]
    np.testing.assert_array_equal(inputs.gap_missing_s, full.gap_missing_s)
    assert inputs.clipping.keys() == full.clipping.keys() == {"acc"}
    assert inputs.clipped_acc_samples == full.clipped_acc_samples > 10
    assert inputs.rate_hz == full.rate_hz
    assert math.isnan(inputs.rest_specific_force_mps2) and math.isnan(inputs.max_angular_rate_radps)
    assert inputs.warnings == [w for w in full.warnings if "gap(s)" in w or "saturated" in w]
    assert len(full.warnings) > len(inputs.warnings)  # the declared rate (and g as m/s^2) only in the full


def test_a_reader_asked_for_fewer_checks_reads_the_same_samples(tmp_path):
    """``checks="inputs"``: the gaps and clipping of the full checks, no unit warning; ``"none"``:
    no checks at all; the samples the same bits in every case; an unknown choice refused."""
    t, acc, gyro = walking_imu()
    path = write_csv(tmp_path / "imu.csv", t, acc / 9.80665, gyro)  # g declared as m/s^2: a unit warning
    full, inputs, none = (read(path, checks=c) for c in ("all", "inputs", "none"))
    for stream in (inputs, none):
        for name in ("t", "acc_b", "gyro_b"):
            np.testing.assert_array_equal(getattr(stream, name), getattr(full, name))
    assert any("acc_unit" in w for w in full.report.warnings) and not inputs.report.warnings
    assert inputs.checks.gap_index.size == full.checks.gap_index.size and none.checks is None
    with pytest.raises(ValueError, match="checks must be"):
        read(path, checks="some")


def test_warnings_reach_metrics_json_and_the_console(tmp_path, write_yaml):
    t, acc, gyro = walking_imu(seconds=6.0)
    write_csv(tmp_path / "imu.csv", t, acc / 9.80665, gyro)
    cfg = write_yaml({"systems": {"foot": {"plugin": "foot_ins", "data": {
        "path": "imu.csv", "time_column": "t", "acc_columns": ["ax", "ay", "az"], "gyro_columns": ["gx", "gy", "gz"]}}},
        "output": {"plots": False}})
    fusion = Path(sys.executable).with_name("fusion")
    proc = subprocess.run([str(fusion), "run", str(cfg), "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    warned = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning: ") and "not near gravity" in ln]
    assert len(warned) == 1
    doc = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert any("not near gravity" in w for w in doc["input"]["warnings"])
    checks = doc["systems"]["foot"]["diagnostics"]["input_checks"]
    assert checks["warnings"] >= 1 and math.isclose(checks["rate_hz"], RATE, rel_tol=1e-6)


def test_the_foot_ins_inflates_its_covariance_across_a_gap(tmp_path, write_yaml):
    """Gap policy: the step across 0.4 s of missing samples is not integrated silently; the
    velocity and attitude variances grow by the recording's own RMS motion over the gap."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout

    t, acc, gyro = walking_imu()
    keep = np.ones(t.size, dtype=bool)
    keep[300:340] = False
    write_csv(tmp_path / "imu.csv", t[keep], acc[keep], gyro[keep])
    write_csv(tmp_path / "whole.csv", t, acc, gyro)
    section = {"time_column": "t", "acc_columns": ["ax", "ay", "az"], "gyro_columns": ["gx", "gy", "gz"]}
    runs = {}
    for name in ("imu.csv", "whole.csv"):
        cfg = write_yaml({"systems": {"foot": {"plugin": "foot_ins", "data": {"path": name, **section}}}}, f"{name}.yaml")
        runs[name] = run_layout(load_layout(cfg))
    gap, whole = runs["imu.csv"].systems["foot"], runs["whole.csv"].systems["foot"]
    i = int(gap.stream.checks.gap_index[0])  # the inflation lands before the step to i (row i − 1)
    before, after = gap.hist_cov[i - 2, :3].sum(), gap.hist_cov[i, :3].sum()
    j = int(np.searchsorted(whole.stream.t, gap.stream.t[i]))
    assert after - before > 10 * (whole.hist_cov[j, :3].sum() - whole.hist_cov[j - 2, :3].sum())
    assert gap.diagnostics()["input_checks"]["gaps"] == 1


def test_a_foot_at_rest_through_a_long_gap_stays_where_it_was(tmp_path, write_yaml):
    """A minute with no samples is not integrated as one 60 s step (0.02 m/s^2 of noise held
    for 60 s would move the foot 36 m): the gap step holds its sample for 0.1 s at most, and the
    uncertainty the gap adds is bounded by a walker's speed."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout
    from bodyfusion.plugins.foot_ins.input_policy import GAP_SPEED_SD_MPS

    t, acc, gyro = walking_imu(seconds=20.0)
    acc[:, 0:2] = acc[0, 0:2] + np.random.default_rng(1).normal(0, 0.02, (t.size, 2))
    acc[:, 2] = 9.81 + np.random.default_rng(2).normal(0, 0.02, t.size)
    gyro[:] = np.random.default_rng(3).normal(0, 0.003, gyro.shape)
    t[1000:] += 60.0
    write_csv(tmp_path / "gap.csv", t, acc, gyro)
    section = {"time_column": "t", "acc_columns": ["ax", "ay", "az"], "gyro_columns": ["gx", "gy", "gz"]}
    cfg = write_yaml({"systems": {"foot": {"plugin": "foot_ins", "data": {"path": "gap.csv", **section}}}})
    track = run_layout(load_layout(cfg)).trajectories["foot"]
    np.testing.assert_allclose(track.t, t, atol=1e-9)  # output times are the recording's
    assert np.max(np.abs(track.pos_n)) < 0.05
    assert track.pos_sd[1000, 0] > 1.0
    assert np.all(track.pos_sd <= GAP_SPEED_SD_MPS * 60.0)
