"""Tests for the readers (bodyfusion.io.tables, imu, truth): every bad input names the file and the line."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.base.errors import InputError
from bodyfusion.io.imu import ACC_UNITS, GYRO_UNITS, read_imu_csv
from bodyfusion.io.tables import read_table
from bodyfusion.io.timestamps import TIMESTAMP_POLICIES, apply_timestamp_policy
from bodyfusion.io.truth import read_truth_csv
from tests.paths import SHARED_DATA, needs_shared

DATA = SHARED_DATA
XIO = DATA / "single_foot_loop_xio" / "long_walk.csv"
VICON = DATA / "dual_foot_vicon_hu2025"

HEADER = "t,ax,ay,az,gx,gy,gz,st"
ACC = ["ax", "ay", "az"]
GYRO = ["gx", "gy", "gz"]


def _rows(n: int, t0: float = 0.0, dt: float = 0.01) -> list[str]:
    return [f"{t0 + i * dt:.6f},0.1,0.2,9.8,0.01,0.02,0.03,{i % 2}" for i in range(n)]


def _write(tmp_path: Path, lines: list[str], name: str = "imu.csv") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def _read(p: Path, **kw):
    args = dict(acc_columns=ACC, gyro_columns=GYRO, time_column="t")
    args.update(kw)
    return read_imu_csv(p, **args)


def _err(p: Path, line: int | None, *fragments: str, **kw) -> InputError:
    with pytest.raises(InputError) as ei:
        _read(p, **kw)
    err = ei.value
    msg = str(err)
    assert p.name in msg and str(p) == err.path
    assert err.line == line, msg
    if line is not None:
        assert msg.startswith(f"{p}:{line}: "), msg
    for f in fragments:
        assert f in msg, (f, msg)
    return err


# --------------------------------------------------------------------------- good input


def test_reads_and_converts_units(tmp_path):
    lines = ["time,accx,accy,accz,gyrx,gyry,gyrz"] + [
        f"{i * 0.0025},0.0,0.5,1.0,90.0,-180.0,0.0" for i in range(12)
    ]
    p = _write(tmp_path, lines)
    s = read_imu_csv(
        p, acc_columns=["accx", "accy", "accz"], gyro_columns=["gyrx", "gyry", "gyrz"],
        acc_unit="g", gyro_unit="deg/s", time_column="time",
    )
    assert len(s) == 12 and s.stance is None and s.source == str(p)
    np.testing.assert_allclose(s.acc_b[0], [0.0, 0.5 * 9.80665, 9.80665], rtol=0, atol=1e-12)
    np.testing.assert_allclose(s.gyro_b[0], [math.pi / 2, -math.pi, 0.0], rtol=0, atol=1e-12)
    assert s.acc_b.dtype == np.float64 and s.acc_b.shape == (12, 3)
    assert ACC_UNITS["g"] == 9.80665 and ACC_UNITS["m/s^2"] == 1.0
    assert GYRO_UNITS["deg/s"] == math.pi / 180 and GYRO_UNITS["rad/s"] == 1.0
    assert s.report.dropped_samples == 0 and s.report.reordered_samples == 0


def test_time_from_column_times_scale(tmp_path):
    lines = ["n,ax,ay,az,gx,gy,gz"] + [f"{i + 100},0,0,9.8,0,0,0" for i in range(20)]
    p = _write(tmp_path, lines)
    s = read_imu_csv(p, acc_columns=ACC, gyro_columns=GYRO, time_column="n", time_scale=1 / 60)
    np.testing.assert_allclose(s.t, (np.arange(20) + 100) / 60)


def test_time_from_rate(tmp_path):
    lines = ["ax,ay,az,gx,gy,gz"] + ["0,0,9.8,0,0,0"] * 15
    p = _write(tmp_path, lines)
    s = read_imu_csv(p, acc_columns=ACC, gyro_columns=GYRO, rate_hz=400.0)
    np.testing.assert_allclose(s.t, np.arange(15) / 400.0)


def test_stance_column_is_bool(tmp_path):
    p = _write(tmp_path, [HEADER] + _rows(12))
    s = _read(p, stance_column="st")
    assert s.stance.dtype == bool
    np.testing.assert_array_equal(s.stance, np.arange(12) % 2 == 1)


def test_header_quotes_whitespace_and_skip_rows(tmp_path):
    lines = ["# exported by device", "version 3", ' "t" , \'ax\',"ay",az ,gx,gy,gz'] + [
        f'{i},"1.5",2,3,4,5,6' for i in range(10)
    ]
    p = _write(tmp_path, lines)
    s = _read(p, skip_rows=2)
    np.testing.assert_allclose(s.acc_b[0], [1.5, 2, 3])
    np.testing.assert_allclose(s.t, np.arange(10))


def test_semicolon_delimiter(tmp_path):
    lines = ["t;ax;ay;az;gx;gy;gz"] + [f"{i};0;0;9.8;0;0;0" for i in range(10)]
    p = _write(tmp_path, lines)
    assert len(_read(p, delimiter=";")) == 10


def test_garbage_in_unused_column_is_ignored(tmp_path):
    lines = ["t,ax,ay,az,gx,gy,gz,comment"] + [f"{i},0,0,9.8,0,0,0,walk ok" for i in range(10)]
    p = _write(tmp_path, lines)
    assert len(_read(p)) == 10


def test_read_table_line_numbers(tmp_path):
    lines = ["junk", "a,b", "1,2", "", "3,4", "  ", "5,6"]
    p = _write(tmp_path, lines)
    cols, line_no = read_table(p, ["b", "a"], skip_rows=1)
    np.testing.assert_array_equal(cols["a"], [1, 3, 5])
    np.testing.assert_array_equal(cols["b"], [2, 4, 6])
    assert cols["a"].dtype == np.float64
    np.testing.assert_array_equal(line_no, [3, 5, 7])


def test_read_table_allow_missing(tmp_path):
    p = _write(tmp_path, ["a,b", "1,2", "2,", "3,nan", "4,5"])
    cols, _ = read_table(p, ["a", "b"], allow_missing=["b"])
    np.testing.assert_array_equal(np.isnan(cols["b"]), [False, True, True, False])
    with pytest.raises(InputError) as ei:
        read_table(p, ["a", "b"])
    assert ei.value.line == 3 and "empty cell" in str(ei.value)


def test_reads_28000_rows_to_the_printed_digits(tmp_path):
    rng = np.random.default_rng(0)
    data = np.column_stack([np.arange(28000) * 0.0025, rng.normal(size=(28000, 6))])
    data[:, 3] += 9.81  # an accelerometer sees gravity
    p = tmp_path / "big.csv"
    np.savetxt(p, data, delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.9g")
    s = _read(p)
    assert len(s) == 28000
    np.testing.assert_allclose(s.acc_b, data[:, 1:4], rtol=1e-8)
    np.testing.assert_allclose(s.gyro_b, data[:, 4:7], rtol=1e-8)


# --------------------------------------------------------------------------- bad input


def test_missing_file(tmp_path):
    _err(tmp_path / "nope.csv", None, "not found")


def test_missing_column_lists_header(tmp_path):
    p = _write(tmp_path, ["t,ax,ay,az,gx,gy,gyro_z"] + _rows(12))
    _err(p, 1, "missing column 'gz'", "'gyro_z'", "'ax'", "'t'")


def test_missing_column_after_skip_rows(tmp_path):
    p = _write(tmp_path, ["meta", "meta2", "t,ax,ay,az,gx,gy"] + _rows(12))
    _err(p, 3, "missing column 'gz'", skip_rows=2)


def test_non_numeric_cell(tmp_path):
    rows = _rows(12)
    rows[5] = "0.05,0.1,abc,9.8,0,0,0,0"  # file line 7
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 7, "'abc'", "'ay'", "non-numeric")


def test_non_numeric_cell_counts_blank_lines(tmp_path):
    rows = _rows(12)
    rows[5] = "0.05,0.1,0.2,9.8,0,x1,0,0"
    p = _write(tmp_path, [HEADER, ""] + rows[:3] + [""] + rows[3:])  # bad row at line 9
    _err(p, 9, "'x1'", "'gy'")


def test_empty_cell(tmp_path):
    rows = _rows(12)
    rows[2] = "0.02,,0.2,9.8,0,0,0,0"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 4, "empty cell", "'ax'")


@pytest.mark.parametrize("cell,word", [("nan", "NaN"), ("NaN", "NaN"), ("inf", "infinite"), ("-inf", "infinite")])
def test_nan_and_inf_cells(tmp_path, cell, word):
    rows = _rows(12)
    rows[8] = f"0.08,0.1,0.2,{cell},0,0,0,0"  # line 10
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 10, word, "'az'")


def test_nan_time(tmp_path):
    rows = _rows(12)
    rows[3] = "nan,0.1,0.2,9.8,0,0,0,0"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 5, "NaN", "'t'")


def test_short_row(tmp_path):
    rows = _rows(12)
    rows[4] = "0.04,0.1,0.2"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 6, "fields")


def test_empty_file(tmp_path):
    p = tmp_path / "empty.csv"
    p.write_text("")
    _err(p, None, "empty file")
    p.write_text("\n\n  \n")
    _err(p, None, "empty file")


def test_a_cut_off_last_row_says_so(tmp_path):
    rows = _rows(12)
    rows[-1] = "0.11,0.1"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 13, "fields", "was the file cut off")


@pytest.mark.parametrize("cell, what", [("1e308", "accelerometer"), ("-2e4", "accelerometer")])
def test_a_reading_beyond_any_sensor_is_refused_with_its_line(tmp_path, cell, what):
    rows = _rows(12)
    rows[6] = f"0.06,0.1,{cell},9.8,0.01,0.02,0.03,0"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 8, what, "beyond any sensor's range")
    rows[6] = "0.06,0.1,0.2,9.8,0.01,3e4,0.03,0"
    _err(_write(tmp_path, [HEADER] + rows), 8, "gyroscope")


def test_a_gap_longer_than_max_gap_s_is_refused_with_its_line(tmp_path):
    rows = _rows(10) + _rows(10, t0=700.0)
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 12, "a gap of 699.91 s", "max_gap_s (600 s)")
    assert len(_read(p, max_gap_s=1000.0)) == 20


def test_header_only(tmp_path):
    p = _write(tmp_path, [HEADER])
    _err(p, 1, "no data rows")


def test_too_few_samples(tmp_path):
    p = _write(tmp_path, [HEADER] + _rows(9))
    _err(p, None, "only 9 data rows", "10")
    assert len(_read(p, min_samples=9)) == 9


def test_too_few_samples_after_policy(tmp_path):
    rows = _rows(10) + _rows(3)  # the last 3 go backwards
    p = _write(tmp_path, [HEADER] + rows)
    assert len(_read(p)) == 10
    rows = _rows(8) + _rows(3)
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, None, "only 8 samples left", "'drop'")


@pytest.mark.parametrize(
    "kw,fragments",
    [
        (dict(acc_unit="m/s2"), ("unknown acc_unit 'm/s2'", "m/s^2", "g")),
        (dict(gyro_unit="dps"), ("unknown gyro_unit 'dps'", "rad/s", "deg/s")),
        (dict(timestamp_policy="keep"), ("unknown timestamp policy 'keep'", "drop", "sort", "error")),
        (dict(rate_hz=100.0), ("exactly one of time_column and rate_hz",)),
        (dict(time_column=None), ("exactly one of time_column and rate_hz",)),
        (dict(time_column=None, rate_hz=0.0), ("rate_hz",)),
        (dict(time_scale=-1.0), ("time_scale",)),
        (dict(acc_columns=["ax", "ay"]), ("acc_columns", "3")),
    ],
)
def test_bad_arguments(tmp_path, kw, fragments):
    p = _write(tmp_path, [HEADER] + _rows(12))
    _err(p, None, *fragments, **kw)


def test_stance_values_must_be_0_or_1(tmp_path):
    rows = _rows(12)
    rows[6] = "0.06,0.1,0.2,9.8,0,0,0,2"  # line 8
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 8, "'st'", "0 or 1", "got 2", stance_column="st")
    rows[6] = "0.06,0.1,0.2,9.8,0,0,0,0.5"
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 8, "got 0.5", stance_column="st")


# --------------------------------------------------------------------------- timestamp policies

# times: 0 1 2 2 3 1.5 4 5 6 7 8 9  (duplicate at line 5, backward at line 7)
T_BAD = [0, 1, 2, 2, 3, 1.5, 4, 5, 6, 7, 8, 9]


def _bad_time_file(tmp_path: Path) -> Path:
    rows = [f"{t},{i},0,9.8,0,0,0,0" for i, t in enumerate(T_BAD)]
    return _write(tmp_path, [HEADER] + rows)


def test_policy_drop(tmp_path):
    s = _read(_bad_time_file(tmp_path))
    np.testing.assert_array_equal(s.t, [0, 1, 2, 3, 4, 5, 6, 7, 8, 9])
    np.testing.assert_array_equal(s.acc_b[:, 0], [0, 1, 2, 4, 6, 7, 8, 9, 10, 11])  # first of equal kept
    assert s.report.dropped_samples == 2 and s.report.reordered_samples == 0
    assert any("dropped 2 samples" in n for n in s.report.notes)


def test_policy_sort(tmp_path):
    s = _read(_bad_time_file(tmp_path), timestamp_policy="sort")
    np.testing.assert_array_equal(s.t, [0, 1, 1.5, 2, 3, 4, 5, 6, 7, 8, 9])
    np.testing.assert_array_equal(s.acc_b[:, 0], [0, 1, 5, 2, 4, 6, 7, 8, 9, 10, 11])
    # stable order 0 1 5 2 3 4 6 ...: samples 5, 2, 3, 4 change position
    assert s.report.reordered_samples == 4
    assert s.report.dropped_samples == 1
    assert len(s.report.notes) == 2


@settings(max_examples=40, deadline=None)
@given(order=st.permutations(range(12)))
def test_policy_sort_restores_any_order_of_distinct_times(tmp_path_factory, order):
    """Whatever order the rows come in (no duplicate, so nothing is dropped), ``sort`` gives the
    stream the file in time order gives: every column, the stance labels too."""
    folder = tmp_path_factory.mktemp("sort")
    rows = [f"{0.01 * i:.2f},{i},{-i},9.8,{0.1 * i:.1f},0,0,{i % 2}" for i in range(12)]
    clean = _read(_write(folder, [HEADER] + rows, "clean.csv"), stance_column="st")
    mixed = _read(_write(folder, [HEADER] + [rows[k] for k in order], "mixed.csv"), stance_column="st",
                  timestamp_policy="sort")
    for field in ("t", "acc_b", "gyro_b", "stance"):
        np.testing.assert_array_equal(getattr(mixed, field), getattr(clean, field))
    assert mixed.report.dropped_samples == 0
    assert mixed.report.reordered_samples == sum(k != i for i, k in enumerate(order))


def test_policy_error_duplicate(tmp_path):
    _err(_bad_time_file(tmp_path), 5, "duplicate timestamp", "2.0", timestamp_policy="error")


def test_policy_error_backward(tmp_path):
    rows = [f"{t},0,0,9.8,0,0,0,0" for t in [0, 1, 2, 3, 2.5, 4, 5, 6, 7, 8, 9]]
    p = _write(tmp_path, [HEADER] + rows)
    _err(p, 6, "backward timestamp", "2.5", "3.0", timestamp_policy="error")


def test_policy_error_accepts_increasing(tmp_path):
    p = _write(tmp_path, [HEADER] + _rows(12))
    assert len(_read(p, timestamp_policy="error")) == 12


def test_apply_timestamp_policy_direct():
    t = np.array([0.0, 0.0, 1.0, 0.5, 2.0, 2.0, 3.0])
    kept, rep, _ = apply_timestamp_policy(t, "drop", "x.csv")
    np.testing.assert_array_equal(kept, [0, 2, 4, 6])
    assert rep.dropped_samples == 3
    kept, rep, _ = apply_timestamp_policy(t, "sort", "x.csv")
    np.testing.assert_array_equal(kept, [0, 3, 2, 4, 6])
    assert (rep.dropped_samples, rep.reordered_samples) == (2, 2)
    with pytest.raises(InputError) as ei:
        apply_timestamp_policy(t, "error", "x.csv")
    assert "duplicate timestamp at sample 1" in str(ei.value) and str(ei.value).startswith("x.csv: ")
    with pytest.raises(InputError) as ei:
        apply_timestamp_policy(t, "error", "x.csv", lines=np.arange(7) + 2)
    assert ei.value.line == 3
    with pytest.raises(InputError, match="unknown timestamp policy"):
        apply_timestamp_policy(t, "nope", "x.csv")
    assert set(TIMESTAMP_POLICIES) == {"drop", "sort", "error", "unwrap"}


def _reset_file(tmp_path: Path) -> Path:
    """100 samples at 100 Hz, then the sample counter restarts at 0 for 100 more."""
    rows = [f"{i * 0.01:.2f},{i},0,9.8,0,0,0,0" for i in range(100)]
    rows += [f"{i * 0.01:.2f},{100 + i},0,9.8,0,0,0,0" for i in range(100)]
    return _write(tmp_path, [HEADER] + rows)


@pytest.mark.parametrize("policy, verb", [("drop", "drop them"), ("sort", "mix the two clocks")])
def test_a_clock_that_restarts_is_refused_naming_its_line_not_half_dropped(tmp_path, policy, verb):
    """A counter reset used to drop the whole second half silently under 'drop' (its times are
    below the first half's) and interleave two clocks under 'sort'."""
    err = _err(_reset_file(tmp_path), 102, "the clock restarts", "100 samples follow", verb, "unwrap",
               timestamp_policy=policy)
    assert err.line == 102


def test_unwrap_joins_a_restarted_clock_one_step_on_and_says_so(tmp_path):
    s = _read(_reset_file(tmp_path), timestamp_policy="unwrap")
    np.testing.assert_allclose(s.t, np.arange(200) * 0.01, atol=1e-12)
    np.testing.assert_array_equal(s.acc_b[:, 0], np.arange(200))  # every sample kept, in file order
    assert s.report.dropped_samples == 0
    assert any("the clock restarts 1 time(s) (the first at line 102" in w for w in s.report.warnings)


# --------------------------------------------------------------------------- truth


def test_truth_reader(tmp_path):
    lines = ["frame,lx,ly,lz,rx,ry,rz"]
    for i in range(8):
        left = "nan,nan,nan" if i == 3 else f"{i},{-i},0.1"
        right = ",," if i in (5, 6) else f"{10 + i},{i},0.2"
        lines.append(f"{i * 2},{left},{right}")
    p = _write(tmp_path, lines, "gt.csv")
    tr = read_truth_csv(
        p, position_columns={"left": ["lx", "ly", "lz"], "right": ["rx", "ry", "rz"]},
        time_column="frame", time_scale=0.5,
    )
    assert set(tr) == {"left", "right"}
    np.testing.assert_allclose(tr["left"].t, [0, 1, 2, 4, 5, 6, 7])
    np.testing.assert_allclose(tr["left"].pos_n[3], [4, -4, 0.1])
    np.testing.assert_allclose(tr["right"].t, [0, 1, 2, 3, 4, 7])
    np.testing.assert_allclose(tr["right"].pos_n[-1], [17, 7, 0.2])
    assert not tr["left"].sparse


def test_truth_reader_rate_sparse_and_errors(tmp_path):
    p = _write(tmp_path, ["e,n,u"] + [f"{i},{i},0" for i in range(5)], "pts.csv")
    tr = read_truth_csv(p, position_columns={"pts": ["e", "n", "u"]}, rate_hz=2.0, sparse=True)
    np.testing.assert_allclose(tr["pts"].t, np.arange(5) / 2.0)
    assert tr["pts"].sparse
    with pytest.raises(InputError, match="missing column 'x'"):
        read_truth_csv(p, position_columns={"pts": ["x", "n", "u"]}, rate_hz=2.0)
    bad = _write(tmp_path, ["t,e,n,u", "0,1,2,3", "1,1,zz,3"], "bad.csv")
    with pytest.raises(InputError) as ei:
        read_truth_csv(bad, position_columns={"a": ["e", "n", "u"]}, time_column="t")
    assert ei.value.line == 3 and "'zz'" in str(ei.value) and "bad.csv" in str(ei.value)
    inf = _write(tmp_path, ["t,e,n,u", "0,1,2,3", "1,1,inf,3"], "inf.csv")
    with pytest.raises(InputError) as ei:
        read_truth_csv(inf, position_columns={"a": ["e", "n", "u"]}, time_column="t")
    assert ei.value.line == 3 and "infinite" in str(ei.value)
    back = _write(tmp_path, ["t,e,n,u", "0,1,2,3", "1,1,2,3", "1,1,2,3"], "back.csv")
    with pytest.raises(InputError) as ei:
        read_truth_csv(back, position_columns={"a": ["e", "n", "u"]}, time_column="t")
    assert ei.value.line == 4 and "duplicate timestamp" in str(ei.value)


# --------------------------------------------------------------------------- real data


@needs_shared("single_foot_loop_xio")
def test_xio_long_walk_duplicates_dropped():
    s = read_imu_csv(
        XIO, time_column="Time (s)",
        acc_columns=[f"Accelerometer {a} (g)" for a in "XYZ"],
        gyro_columns=[f"Gyroscope {a} (deg/s)" for a in "XYZ"],
        acc_unit="g", gyro_unit="deg/s",
    )
    assert s.report.dropped_samples == 252
    assert len(s) == 28132 - 252
    assert np.all(np.diff(s.t) > 0)
    g = np.linalg.norm(s.acc_b[:200], axis=1).mean()  # standing still at the start
    assert 9.0 < g < 10.6


@needs_shared("dual_foot_vicon_hu2025")
def test_vicon_imu_and_truth():
    s = read_imu_csv(
        VICON / "imuMeasLeft.csv", time_column="time_index", time_scale=1 / 60,
        acc_columns=["acc_x", "acc_y", "acc_z"], gyro_columns=["gyro_x", "gyro_y", "gyro_z"],
        stance_column="is_zero_vel",
    )
    assert len(s) == 7201 and s.t[-1] == pytest.approx(120.0) and s.stance.dtype == bool
    tr = read_truth_csv(
        VICON / "positionGt.csv", time_column="time_index", time_scale=1 / 60,
        position_columns={
            "left": ["pos_left_x", "pos_left_y", "pos_left_z"],
            "right": ["pos_right_x", "pos_right_y", "pos_right_z"],
        },
    )
    assert tr["left"].pos_n.shape == (7201, 3) and tr["right"].t.shape == (7201,)


def test_long_truth_with_cr_cr_lf_line_ends_reads_and_a_stray_cr_is_refused(tmp_path):
    from bodyfusion.io.truth import read_truth_long_csv

    path = tmp_path / "truth.csv"
    path.write_bytes(b"system,t,east_m,north_m,up_m\r\r\nfoot,0,0,0,0\r\r\nfoot,1,1,0,0\r\r\n")
    track = read_truth_long_csv(path)["foot"]
    np.testing.assert_array_equal(track.pos_n[:, 0], [0.0, 1.0])
    path.write_bytes(b"system,t,east_m,north_m,up_m\nfo\rot,0,0,0,0\nfoot,1,1,0,0\n")
    with pytest.raises(InputError, match=r"truth.csv:2: a carriage return inside the line"):
        read_truth_long_csv(path)
