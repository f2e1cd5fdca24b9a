"""Tests for bodyfusion.nav.detectors on synthetic signals, small exact arrays and real labels."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.nav.detectors import (
    acceleration_magnitude,
    adaptive_shoe_threshold,
    axes_sum_band,
    debounce,
    shoe_statistic,
    stance_events,
)
from bodyfusion.nav.stance_detectors import AdaptiveShoe, Shoe
from tests.paths import ROOT, SHARED_DATA, needs_shared

G = 9.81


def shoe(acc: np.ndarray, gyro: np.ndarray, **params) -> np.ndarray:
    """The SHOE detector's stance at its defaults (``params``: others)."""
    return Shoe(**params).detect(acc, gyro, 100.0, G).stance


def default_threshold(statistic: np.ndarray, period_s: np.ndarray, rate_hz: float) -> np.ndarray:
    """The adaptive threshold at the adaptive detector's defaults."""
    d = AdaptiveShoe()
    return adaptive_shoe_threshold(statistic, period_s, rate_hz, gamma_still=d.threshold, gamma_motion=d.motion_threshold,
                                   margin_decades=d.margin_decades, prominence_decades=d.prominence_decades)
VICON = SHARED_DATA / "dual_foot_vicon_hu2025"


def synthetic(seed: int = 1, up=(0.0, 0.0, 1.0)):
    """Alternating rest / motion segments sampled at 100 Hz.

    Rest: specific force g along the body's ``up`` axis + 0.02 m/s^2 noise,
    angular rate 0.003 rad/s noise.  Motion: specific force offset by 2..10
    m/s^2 per axis (so |a| and the axes sum stay well away from their rest
    values) and an angular rate of norm >= 1 rad/s.
    """
    rng = np.random.default_rng(seed)
    up = np.asarray(up, float) / np.linalg.norm(up)
    acc, gyro, stance = [], [], []
    for k in range(16):
        rest = k % 2 == 0
        n = int(rng.integers(40, 120))
        if rest:
            a = G * up + rng.normal(0, 0.02, (n, 3))
            w = rng.normal(0, 0.003, (n, 3))
        else:
            ph = np.linspace(0, 2 * np.pi, n)[:, None]
            a = G * up + np.column_stack([3 + 2 * np.sin(ph), 2 + 1.5 * np.cos(ph), 6 + 4 * np.sin(2 * ph)])
            a = a + rng.normal(0, 0.05, (n, 3))
            w = np.column_stack([3 * np.sin(ph), 2 * np.cos(ph), np.ones_like(ph)]) + rng.normal(0, 0.01, (n, 3))
        acc.append(a)
        gyro.append(w)
        stance.append(np.full(n, rest))
    return np.vstack(acc), np.vstack(gyro), np.concatenate(stance)


# --------------------------------------------------------------------------- synthetic recovery


def test_shoe_recovers_stance():
    acc, gyro, truth = synthetic()
    det = shoe(acc, gyro)
    assert det.shape == truth.shape and det.dtype == bool
    assert (det == truth).mean() > 0.95
    assert not (det & ~truth).any()  # windows straddling a boundary never pass


def test_shoe_recovers_stance_tilted_sensor():
    acc, gyro, truth = synthetic(seed=2, up=(0.3, -0.5, 0.8))
    assert (shoe(acc, gyro) == truth).mean() > 0.95


def test_acceleration_magnitude_recovers_stance():
    acc, _, truth = synthetic(seed=3)
    for window in (1, 5):
        det = acceleration_magnitude(acc, threshold=0.5, gravity=G, window=window)
        assert (det == truth).mean() > 0.95


def test_axes_sum_band_recovers_stance():
    acc, _, truth = synthetic(seed=4)
    for window in (1, 5):
        det = axes_sum_band(acc, low=G - 0.5, high=G + 0.5, window=window)
        assert (det == truth).mean() > 0.95


# --------------------------------------------------------------------------- exact small cases


def test_shoe_statistic_matches_formula():
    rng = np.random.default_rng(5)
    acc = rng.normal(0, 1, (9, 3)) + [0, 0, G]
    gyro = rng.normal(0, 0.1, (9, 3))
    W, sa, sg = 4, 0.05, 0.01
    T = shoe_statistic(acc, gyro, window=W, sigma_acc=sa, sigma_gyro=sg, gravity=G)
    assert T.shape == (9 - W + 1,)
    for k in range(T.size):
        a, w = acc[k : k + W], gyro[k : k + W]
        m = a.mean(axis=0)
        ref = (np.sum((a - G * m / np.linalg.norm(m)) ** 2) / sa**2 + np.sum(w**2) / sg**2) / W
        assert T[k] == pytest.approx(ref, rel=1e-12)


def test_shoe_marks_whole_passing_window():
    # 10 samples, only the window starting at 3 (W = 3) is quiet -> samples 3, 4, 5.
    acc = np.tile([0.0, 0.0, G], (10, 1))
    gyro = np.full((10, 3), 1.0)
    gyro[3:6] = 0.0
    np.testing.assert_array_equal(np.flatnonzero(shoe(acc, gyro, window=3)), [3, 4, 5])
    assert not shoe(acc[:2], gyro[:2], window=3).any()  # shorter than one window


def test_threshold_detectors_exact():
    # gravity 10 and binary-exact values: |a| - g <= threshold is inclusive,
    # the axes-sum band low < sum < high is strict (as printed in the papers).
    acc = np.array([[0, 0, 10], [0, 0, 10.5], [0, 0, 10.75], [0, 0, 9.5], [0, 0, 9.25], [3, 3, 3]], float)
    np.testing.assert_array_equal(
        acceleration_magnitude(acc, threshold=0.5, gravity=10.0, window=1), [True, True, False, True, False, False]
    )
    np.testing.assert_array_equal(
        axes_sum_band(acc, low=9.5, high=10.5, window=1), [True, False, False, False, False, False]
    )
    # moving average over 3 samples (centred, shrinking at the ends)
    mag = np.array([10.0, 10.0, 13.0, 10.0, 10.0, 10.0])
    acc = np.column_stack([np.zeros(6), np.zeros(6), mag])
    np.testing.assert_array_equal(
        acceleration_magnitude(acc, threshold=0.5, gravity=10.0, window=3), [True, False, False, False, True, True]
    )


def test_bad_shapes_rejected():
    with pytest.raises(ValueError):
        shoe(np.zeros((5, 2)), np.zeros((5, 3)))
    with pytest.raises(ValueError):
        acceleration_magnitude(np.zeros((5, 3)), threshold=1.0, gravity=G, window=0)
    with pytest.raises(ValueError):
        axes_sum_band(np.zeros((5, 3)), low=1.0, high=0.0, window=1)


def test_stance_events_exact():
    s = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1], bool)
    starts, ends = stance_events(s)
    np.testing.assert_array_equal(starts, [0, 4, 6])
    np.testing.assert_array_equal(ends, [2, 5, 9])
    e = stance_events(np.zeros(4, bool))
    assert e[0].size == 0 and e[1].size == 0
    e = stance_events(np.zeros(0, bool))
    assert e[0].size == 0


def test_debounce_exact():
    s = np.array([0, 1, 1, 1, 0, 1, 1, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 1], bool)
    # min_swing=2: the one-sample gap at 4 is filled; edge swing (0) is kept.
    # min_stance=3: the lone stance at 12 and the 2-sample run at the end go.
    out = debounce(s, min_stance=3, min_swing=2)
    exp = np.array([0, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0], bool)
    np.testing.assert_array_equal(out, exp)
    # disabled steps leave the input alone, and the input is not modified
    np.testing.assert_array_equal(debounce(s, min_stance=1, min_swing=1), s)
    assert s[4] == 0


def test_debounce_fill_before_remove():
    # two 2-sample stance halves split by a one-sample flicker become one run of 5
    s = np.array([0, 0, 1, 1, 0, 1, 1, 0, 0], bool)
    np.testing.assert_array_equal(
        debounce(s, min_stance=4, min_swing=2), [0, 0, 1, 1, 1, 1, 1, 0, 0]
    )


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.booleans(), min_size=0, max_size=60),
    st.integers(1, 6),
    st.integers(1, 6),
)
def test_debounce_properties(bits, min_stance, min_swing):
    s = np.array(bits, dtype=bool)
    out = debounce(s, min_stance=min_stance, min_swing=min_swing)
    starts, ends = stance_events(out)
    assert np.all(ends - starts >= min_stance)
    # interior swing gaps are at least min_swing long
    assert np.all(starts[1:] - ends[:-1] >= min_swing)
    # stance_events round trip
    rebuilt = np.zeros(s.size, bool)
    for a, b in zip(*stance_events(s)):
        rebuilt[a:b] = True
    np.testing.assert_array_equal(rebuilt, s)


# --------------------------------------------------------------------------- real labels


@needs_shared("dual_foot_vicon_hu2025")
@pytest.mark.parametrize("side,bound", [("Left", 0.90), ("Right", 0.85)])
def test_shoe_agrees_with_vicon_labels(side, bound):
    from bodyfusion.io.imu import read_imu_csv

    s = read_imu_csv(
        VICON / f"imuMeas{side}.csv", time_column="time_index", time_scale=1 / 60,
        acc_columns=["acc_x", "acc_y", "acc_z"], gyro_columns=["gyro_x", "gyro_y", "gyro_z"],
        stance_column="is_zero_vel",
    )
    det = shoe(s.acc_b, s.gyro_b)  # defaults: W=5, 0.01 m/s^2, 0.1 deg/s, gamma=0.3e5
    agreement = (det == s.stance).mean()
    assert agreement > bound, agreement  # measured 0.928 (left), 0.883 (right)
    # labelled stance is (almost) never missed
    assert (s.stance & ~det).sum() < 0.05 * s.stance.sum()  # measured 0.6 % / 2.2 %


# --------------------------------------------------------------------------- adaptive SHOE


def _statistic_of(stance_floor: float, swing: float, rate: float, stance_s: float, swing_s: float,
                  seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """A synthetic SHOE statistic: ``stance_floor`` during stance, ``swing`` during swing."""
    n = int(seconds * rate)
    t = np.arange(n) / rate
    in_stance = np.mod(t, stance_s + swing_s) < stance_s
    return np.where(in_stance, stance_floor, swing), in_stance


def test_adaptive_threshold_keeps_the_fixed_one_where_stance_is_still():
    stat, _ = _statistic_of(3e2, 1e7, 200.0, 0.6, 0.5)
    assert np.allclose(default_threshold(stat, np.full(stat.size, 1.1), 200.0), 3e4)


@pytest.mark.parametrize("floor", [5e4, 1.2e5, 3e5])
def test_adaptive_threshold_rises_to_a_running_stance_and_finds_it(floor):
    """Running stances whose least statistic is 0.5-3e5 (above any fixed walking threshold):
    each cycle's threshold sits half a decade above its own floor, and finds every stance."""
    stat, truth = _statistic_of(floor, 1e8, 200.0, 0.15, 0.55)
    gamma = default_threshold(stat, np.full(stat.size, 0.7), 200.0)
    assert np.all(gamma > 3e4) and np.all(gamma <= 1e7)
    np.testing.assert_array_equal(stat < gamma, truth)


def test_adaptive_threshold_never_makes_stance_of_aperiodic_motion():
    """A sensor that never rests and repeats nothing (RMS rate > 1 rad/s): no gait period is
    found, and nothing is stance."""
    from bodyfusion.nav.gait import stride_period

    rng = np.random.default_rng(0)
    gyro = rng.normal(0.0, 1.5, (4000, 3))
    acc = np.tile([0.0, 0.0, 9.81], (4000, 1)) + rng.normal(0.0, 2.0, (4000, 3))
    assert np.isnan(stride_period(np.linalg.norm(gyro, axis=1), 200.0)).all()
    assert not AdaptiveShoe().detect(acc, gyro, 200.0, 9.81).stance.any()


def test_adaptive_threshold_ignores_cycles_whose_floor_does_not_stand_out():
    """A cycle whose swing rises less than ``prominence_decades`` above its floor is no gait
    (fidgeting, a shuffle): only the fixed threshold applies there."""
    stat, _ = _statistic_of(2e5, 1e6, 200.0, 0.2, 0.5)  # 0.7 decades of swing
    assert np.allclose(default_threshold(stat, np.full(stat.size, 0.7), 200.0), 3e4)


def test_adaptive_shoe_window_spans_the_same_time_at_any_rate():

    for rate, w in ((60.0, 3), (200.0, 5), (400.0, 10)):
        n = int(5 * rate)
        acc = np.tile([0.0, 0.0, 9.81], (n, 1))
        d = AdaptiveShoe().detect(acc, np.zeros((n, 3)), rate, 9.81)
        assert d.stance.all() and d.gamma.size == n - w + 1 and d.period_s.size == n and d.statistic_window == w


def test_the_default_detector_holds_on_a_running_stance_that_never_rests(tmp_path):
    """Simulated running whose 0.15 s stance rolls heel to toe throughout: the fixed SHOE
    threshold misses most stances (the watchdog's fallbacks catch the foot, and say so); the
    adaptive default follows the gait and misses none."""
    from bodyfusion.core.layout import load_layout
    from bodyfusion.runner import run_layout
    from bodyfusion.sim import simulate

    cfg = simulate(ROOT / "configs" / "sim_running.yaml", tmp_path / "run", seed=1, overrides=[
        "gait.roll.heel_s=0.07", "gait.roll.toe_s=0.07", "path.laps=1", "systems={left_foot: {kind: foot_imu, "
        "foot: left, imu: {preset: icm20948}}}"]).config_path
    rmse, missed = {}, {}
    for kind in ("adaptive", "shoe"):
        result = run_layout(load_layout(cfg, [f"systems.left_foot.detector.kind={kind}"]))
        rmse[kind] = result.scores["left_foot"].metrics["horizontal_error_m"]["rmse"]
        missed[kind] = result.systems["left_foot"].diagnostics()["missed_stances"]
    assert missed["adaptive"] == 0 and missed["shoe"] > 20, missed
    assert rmse["adaptive"] < 0.1 and rmse["shoe"] < 0.3, rmse