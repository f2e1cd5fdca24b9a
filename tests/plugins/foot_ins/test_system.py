"""The foot-mounted INS plugin on the vendored dual-foot Vicon walk (Hu & Hu, PLANS 2025).

Runs through the public path: ``bodyfusion.runner.batch.run_layout(load_layout(...))``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bodyfusion.base.errors import ConfigError
from bodyfusion.core.heading import wrap_angle
from bodyfusion.core.layout import load_layout
from bodyfusion.runner import build_systems, layout_context, run_layout
from tests.paths import ROOT

VICON_CFG = ROOT / "configs" / "dual_foot_vicon.yaml"
VICON_DATA = ROOT / "examples" / "data" / "dual_foot_vicon_hu2025"
SYSTEMS = ("left_foot", "right_foot")

# The targets for independent feet (measured: about 0.29 m and 0.25 m).
RMSE_TARGET_M = {"left_foot": 1.5, "right_foot": 2.0}
INDEPENDENT = ["fuser.method=none", "heading_alignment.continuous=false"]


@pytest.fixture(scope="module")
def vicon():
    return run_layout(load_layout(VICON_CFG, INDEPENDENT))


def read_imu(path: Path) -> tuple[list[str], np.ndarray]:
    header = path.read_text().splitlines()[0].split(",")
    return header, np.loadtxt(path, delimiter=",", skiprows=1)


def rotated_copy(src: Path, dst: Path, angle_deg: float) -> None:
    """Rotate the IMU about its z axis: (x, y) ← R(angle) (x, y) for acc and gyro."""
    header, d = read_imu(src)
    a = np.deg2rad(angle_deg)
    c, s = np.cos(a), np.sin(a)
    out = d.copy()
    for name in ("acc", "gyro"):
        ix, iy = header.index(f"{name}_x"), header.index(f"{name}_y")
        out[:, ix] = c * d[:, ix] - s * d[:, iy]
        out[:, iy] = s * d[:, ix] + c * d[:, iy]
    fmt = ["%d" if h in ("time_index", "is_zero_vel") else "%.17g" for h in header]
    np.savetxt(dst, out, delimiter=",", header=",".join(header), comments="", fmt=fmt)


# --------------------------------------------------------------------------- accuracy


def test_both_feet_are_scored(vicon):
    assert set(vicon.scores) == set(SYSTEMS)
    for name in SYSTEMS:
        m = vicon.scores[name].metrics
        assert np.isfinite(m["horizontal_error_m"]["rmse"])
        assert m["distance_m"] > 50.0
        assert len(vicon.scores[name].t) > 1000


@pytest.mark.parametrize("name", SYSTEMS)
def test_horizontal_rmse_meets_the_target(vicon, name):
    rmse = vicon.scores[name].metrics["horizontal_error_m"]["rmse"]
    assert rmse < RMSE_TARGET_M[name]


def test_right_foot_heading_is_aligned_to_the_left(vicon):
    assert set(vicon.heading_rotations_rad) == {"right_foot"}
    assert abs(vicon.heading_rotations_rad["right_foot"]) < np.pi


def test_heading_alignment_absorbs_a_rotated_imu_mounting(vicon, tmp_path):
    angle = 40.0
    data = tmp_path / "imuMeasRight_rot40.csv"
    rotated_copy(VICON_DATA / "imuMeasRight.csv", data, angle)
    res = run_layout(load_layout(VICON_CFG, [*INDEPENDENT, f"systems.right_foot.data.path={data}"]))
    base = vicon.heading_rotations_rad["right_foot"]
    change = np.rad2deg(wrap_angle(res.heading_rotations_rad["right_foot"] - base))
    assert change == pytest.approx(angle, abs=1.0)
    for name in SYSTEMS:
        before = vicon.scores[name].metrics["horizontal_error_m"]["rmse"]
        after = res.scores[name].metrics["horizontal_error_m"]["rmse"]
        assert after == pytest.approx(before, abs=0.05)
    # after alignment the right foot's first 3 m point the way the left foot's do
    left_az = res.systems["left_foot"].initial_travel_azimuth(3.0)
    right_az = res.systems["right_foot"].initial_travel_azimuth(3.0)
    assert abs(wrap_angle(left_az - right_az)) < 1e-6


# --------------------------------------------------------------------------- filter health


@pytest.mark.parametrize("name", SYSTEMS)
def test_covariance_is_symmetric_psd_at_the_end(vicon, name):
    P = vicon.systems[name].P
    assert P.shape == (15, 15)
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() >= 0.0
    assert np.all(np.isfinite(P))
    np.testing.assert_array_equal(vicon.systems[name].covariance(), P)


@pytest.mark.parametrize("name", SYSTEMS)
def test_quaternion_history_is_unit_norm(vicon, name):
    s = vicon.systems[name]
    assert s.hist_x.shape == (s.samples, 16)
    norms = np.linalg.norm(s.hist_x[:, 6:10], axis=1)
    assert np.max(np.abs(norms - 1.0)) < 1e-12


@pytest.mark.parametrize("name", SYSTEMS)
def test_trajectory_covers_every_sample(vicon, name):
    s = vicon.systems[name]
    tr = vicon.trajectories[name]
    assert len(tr.t) == s.samples == len(s.stream)
    assert s.t_now == s.t_end
    assert np.all(np.isfinite(tr.pos_n))
    assert np.all(tr.pos_sd >= 0)
    np.testing.assert_array_equal(tr.pos_n, s.hist_x[:, 0:3])


# --------------------------------------------------------------------------- stance


@pytest.mark.parametrize("name,file", [("left_foot", "imuMeasLeft.csv"), ("right_foot", "imuMeasRight.csv")])
def test_stance_fraction_in_diagnostics_equals_the_label_fraction(vicon, name, file):
    """With debouncing off, the labels detector is the labels."""
    header, d = read_imu(VICON_DATA / file)
    labels = d[:, header.index("is_zero_vel")]
    res = run_layout(load_layout(VICON_CFG, [*INDEPENDENT, f"systems.{name}.detector.min_stance_s=0",
                                             f"systems.{name}.detector.min_swing_s=0"]))
    diag = res.systems[name].diagnostics()
    assert diag["stance_fraction"] == pytest.approx(labels.mean(), abs=1e-12)
    # the ZUPT is applied at every stance sample after the first (the initial state is sample 0)
    assert diag["zupt_updates"] == int(labels[1:].sum())
    assert diag["zaru_updates"] == 0
    assert 0.1 < diag["zupt_mean_nis"] < 100.0


def test_debounced_labels_drop_short_flickers(vicon):
    """The layout's 0.05 s debounce: no stance or inner swing run shorter than 3 samples at 60 Hz."""
    from bodyfusion.nav.detectors import stance_events

    for system in vicon.systems.values():
        starts, ends = stance_events(system.stance)
        assert (ends - starts).min() >= 3
        assert (starts[1:] - ends[:-1]).min() >= 3


# --------------------------------------------------------------------------- determinism


def test_restart_then_advance_reproduces_the_run_bit_for_bit():
    res = run_layout(load_layout(VICON_CFG, INDEPENDENT))
    for name in SYSTEMS:
        s = res.systems[name]
        hist_x, hist_var, P, x = s.hist_x.copy(), s.hist_cov.copy(), s.P.copy(), s.x.copy()
        counters = s.counters.copy()
        s.restart()
        assert s.t_now == s.t_start
        s.advance(s.t_end)
        np.testing.assert_array_equal(s.hist_x, hist_x)
        np.testing.assert_array_equal(s.hist_cov, hist_var)
        np.testing.assert_array_equal(s.P, P)
        np.testing.assert_array_equal(s.x, x)
        np.testing.assert_array_equal(s.counters, counters)


def test_advancing_in_chunks_equals_one_pass():
    loaded = load_layout(VICON_CFG)
    a = build_systems(loaded, layout_context(loaded))["left_foot"]
    a.advance(a.t_end)
    b = build_systems(loaded, layout_context(loaded))["left_foot"]
    for t in np.arange(b.t_start, b.t_end, 3.7):
        b.advance(t)
    b.advance(b.t_end)
    np.testing.assert_array_equal(a.hist_x, b.hist_x)
    np.testing.assert_array_equal(a.P, b.P)


def test_labels_detector_without_stance_column_is_refused_at_validation():
    with pytest.raises(ConfigError) as ei:
        load_layout(VICON_CFG, ["systems.left_foot.data.stance_column=null"])
    assert ei.value.key == "systems.left_foot.detector.kind"
    assert "dual_foot_vicon.yaml" in str(ei.value)
