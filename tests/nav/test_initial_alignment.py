"""Initial alignment from the data: the first still interval, TRIAD levelling with a named heading
axis, and a foot INS whose recording starts in motion (navigated backward from its first still
interval) or never rests (levelled on its quietest window, uncertainty inflated, warned)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.core.layout import load_layout
from bodyfusion.runner import run_layout
from bodyfusion.nav.attitude import azimuth_pitch_roll
from bodyfusion.nav.initial_alignment import (
    attitude_from_specific_force,
    find_still_interval,
    heading_axis,
    mean_standard_error,
    window_spreads,
)
from bodyfusion.sim import simulate

G = 9.80665


def noisy_rest(n: int, rng: np.random.Generator, f_b=(0.0, 0.0, G)) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(f_b) + rng.normal(0, 0.03, (n, 3)), rng.normal(0, 0.005, (n, 3)) + [0.01, -0.02, 0.003]


def test_window_spreads_are_the_moving_standard_deviations():
    rng = np.random.default_rng(1)
    acc, gyro = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    s_f, s_w = window_spreads(acc, gyro, 7)
    k = 11
    assert s_f[k] == pytest.approx(np.sqrt(acc[k:k + 7].var(axis=0).sum()))
    assert s_w[k] == pytest.approx(np.sqrt(gyro[k:k + 7].var(axis=0).sum()))


def test_the_first_still_interval_is_found_after_motion_and_grown_to_its_end():
    rng = np.random.default_rng(2)
    moving = (rng.normal(0, 3.0, (200, 3)), rng.normal(0, 2.0, (200, 3)))
    still = noisy_rest(300, rng)
    later = noisy_rest(400, rng)
    acc = np.vstack([moving[0], still[0], moving[0], later[0]])
    gyro = np.vstack([moving[1], still[1], moving[1], later[1]])
    st = find_still_interval(acc, gyro, 50, 0.2, 0.05)
    assert st.still and st.start == 200 and st.stop == 500
    assert st.acc_spread_mps2 < 0.1 and st.gyro_spread_radps < 0.02


def test_shuffling_before_the_walk_is_not_taken_for_rest():
    """Spreads within the absolute limits but well above the sensor's noise floor (a foot
    shifting before the walk) are not still: their mean rate would pass for gyro bias."""
    rng = np.random.default_rng(3)
    rest = noisy_rest(300, rng)
    shuffle = (rest[0] + rng.normal(0, 0.1, (300, 3)), rest[1] + rng.normal(0, 0.03, (300, 3)) + 0.01)
    st = find_still_interval(np.vstack([rest[0], shuffle[0]]), np.vstack([rest[1], shuffle[1]]), 50, 0.2, 0.05)
    assert st.still and st.start == 0 and st.stop < 320


def test_a_foot_slowly_turning_before_the_walk_is_not_taken_for_rest():
    """A foot shifting its weight turns slowly (a few 10 mrad/s, within the sensor's noise
    sample by sample): the window spreads pass, but its batch means drift; its mean rate
    would pass for gyro bias. The later window that does not drift is taken."""
    rng = np.random.default_rng(5)
    fidget = noisy_rest(300, rng)
    turning = 0.03 * np.sin(np.linspace(0.0, 2.0 * np.pi, 300))[:, None] * [1.0, -0.5, 1.0]
    moving = (rng.normal(0, 3.0, (200, 3)), rng.normal(0, 2.0, (200, 3)))
    rest = noisy_rest(300, rng)
    acc = np.vstack([fidget[0], moving[0], rest[0]])
    gyro = np.vstack([fidget[1] + turning, moving[1], rest[1]])
    st = find_still_interval(acc, gyro, 100, 0.2, 0.05)
    assert st.still and st.start >= 500
    assert np.allclose(gyro[st.start:st.stop].mean(axis=0), [0.01, -0.02, 0.003], atol=2e-3)


def test_window_drifts_see_a_slow_rotation_the_spreads_hide():
    from bodyfusion.nav.initial_alignment import window_drifts

    rng = np.random.default_rng(6)
    _, still = noisy_rest(400, rng)
    turning = still + 0.02 * np.linspace(-1.0, 1.0, 400)[:, None]
    d_still, d_turning = window_drifts(still, 100), window_drifts(turning, 100)
    assert d_still.shape == (301,) and np.all(d_turning > 2.0 * np.median(d_still))


def test_without_rest_the_quietest_window_is_flagged_not_still():
    rng = np.random.default_rng(4)
    acc, gyro = rng.normal(0, 2.0, (600, 3)), rng.normal(0, 1.0, (600, 3))
    acc[300:350] = rng.normal(0, 0.5, (50, 3))
    gyro[300:350] = rng.normal(0, 0.2, (50, 3))
    st = find_still_interval(acc, gyro, 50, 0.2, 0.05)
    assert not st.still and 290 <= st.start <= 300 and 350 <= st.stop <= 360


@pytest.mark.parametrize("seed", range(5))
def test_triad_levelling_recovers_a_random_attitude(seed):
    rng = np.random.default_rng(seed)
    q_nb = Rotation.from_euler("ZYX", [rng.uniform(-np.pi, np.pi), rng.uniform(-1.2, 1.2), rng.uniform(-np.pi, np.pi)])
    f_b = q_nb.inv().apply([0.0, 0.0, G])
    azimuth = azimuth_pitch_roll(q_nb.as_quat(scalar_first=True))[0]
    q = attitude_from_specific_force(f_b, azimuth, "x")
    assert (Rotation.from_quat(q, scalar_first=True) * q_nb.inv()).magnitude() < 1e-9


def test_a_sensor_mounted_x_up_gets_the_heading_of_a_horizontal_axis():
    f_b = np.array([G, 0.0, 0.0])  # x points up
    assert heading_axis(f_b, "x") == "y" or heading_axis(f_b, "x") == "z"
    axis = heading_axis(f_b, "x")
    q = attitude_from_specific_force(f_b, np.radians(40.0), axis)
    C = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(C @ [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    a_n = C @ np.eye(3)["xyz".index(axis)]
    assert np.degrees(np.arctan2(a_n[0], a_n[1])) == pytest.approx(40.0)
    assert heading_axis(np.array([0.1, 0.2, 9.8]), "x") == "x"


# --------------------------------------------------------------------------- the foot INS


SCENARIO = """
name: start_in_motion
rate_hz: 100
gravity_mps2: 9.80665
path: {{kind: out_and_back, length_m: 25, repeats: 1, turn: right, start_heading_deg: 30, turn_radius_m: 0.75}}
gait: {{stride_m: 1.4, cadence_steps_per_min: 108, stance_fraction: 0.6, start_still_s: {still}}}
systems:
  foot: {{kind: foot_imu, foot: left, imu: {{preset: icm20948}}}}
"""


def simulated_run(tmp_path, still_s: float, overrides=()):
    scn = tmp_path / "scn.yaml"
    scn.write_text(SCENARIO.format(still=still_s))
    res = simulate(scn, tmp_path / f"sim{still_s}", seed=3)
    return run_layout(load_layout(res.config_path, list(overrides)))


def test_a_walk_that_starts_moving_is_navigated_back_from_its_first_stance(tmp_path):
    """The walker sets off 0.1 s after the logger starts: no still second at t = 0. The first
    still interval is the first flat stance; the swing before it is navigated backward, and
    the walk is as accurate as one that starts after 3 s of rest."""
    rested = simulated_run(tmp_path, 3.0)
    hurried = simulated_run(tmp_path, 0.1)
    init = hurried.systems["foot"].diagnostics()["initialisation"]
    assert init["still"] and init["backward_s"] > 0.1
    assert rested.systems["foot"].diagnostics()["initialisation"].get("backward_s") is None
    rmse = {k: r.scores["foot"].metrics["horizontal_error_m"]["rmse"] for k, r in (("rested", rested),
                                                                                   ("hurried", hurried))}
    assert rmse["hurried"] < max(2.0 * rmse["rested"], 0.3), rmse
    assert hurried.trajectories["foot"].t[0] == pytest.approx(0.0)  # navigated from the first sample


def test_a_recording_that_never_rests_is_warned_and_its_priors_inflated(tmp_path, caplog, write_yaml):
    rng = np.random.default_rng(5)
    n = 1500
    t = np.arange(n) / 100.0
    acc = np.column_stack([2.0 * np.sin(3 * t), 1.5 * np.cos(2 * t), G + np.sin(5 * t)]) + rng.normal(0, 0.05, (n, 3))
    gyro = np.column_stack([0.8 * np.sin(4 * t), 0.5 * np.cos(3 * t), 0.3 * np.sin(t)])
    np.savetxt(tmp_path / "imu.csv", np.column_stack([t, acc, gyro]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="")
    result = run_layout(load_layout(write_yaml({"systems": {"foot": {"plugin": "foot_ins", "data": {
        "path": "imu.csv", "time_column": "t", "acc_columns": ["ax", "ay", "az"],
        "gyro_columns": ["gx", "gy", "gz"]}}}})))
    init = result.systems["foot"].diagnostics()["initialisation"]
    assert not init["still"]
    # a smooth motion does not average out over the window: the means' standard errors are
    # about the spreads, far above the priors for a still sensor (1°, 1e-3 rad/s)
    assert init["level_sd_deg"] > 1.0 and init["gyro_bias_sd_radps"] > 0.2 * init["gyro_spread_radps"] > 1e-3
    assert any("no still interval" in w for w in result.input_report.warnings)
    assert any("no still interval" in r.message for r in caplog.records)


def test_the_initial_heading_is_the_heading_at_the_first_sample(tmp_path):
    """The simulator writes the true heading at t = 0; with backward navigation from a later
    still interval the estimate starts with that heading (within the filter's drift)."""
    result = simulated_run(tmp_path, 0.1)
    foot = result.systems["foot"]
    x0 = foot.hist_x[0]
    azimuth = np.degrees(azimuth_pitch_roll(x0[6:10])[0])
    assert (azimuth - foot.config.initial.heading_deg + 180) % 360 - 180 == pytest.approx(0.0, abs=1e-6)


def test_without_rest_the_earliest_of_the_quietest_windows_is_taken():
    """A foot that jitters in every stance (no window within the absolute limits): of the
    equally quiet stances the first is taken, so the least is navigated backward."""
    rng = np.random.default_rng(6)
    acc, gyro = rng.normal(0, 2.0, (800, 3)), rng.normal(0, 1.0, (800, 3))
    for a in (100, 500):
        acc[a:a + 60] = rng.normal(0, 0.5, (60, 3))
        gyro[a:a + 60] = rng.normal(0, 0.01, (60, 3))
    acc[500:560] *= 0.9  # the later stance a little quieter still
    st = find_still_interval(acc, gyro, 50, 0.2, 0.05)
    assert not st.still and 100 <= st.start <= 110


def test_the_standard_error_of_a_window_mean_counts_only_independent_samples():
    rng = np.random.default_rng(7)
    white = rng.normal(0, 1.0, (400, 3))
    assert mean_standard_error(white) == pytest.approx(np.sqrt(3 / 400), rel=0.35)
    smooth = np.column_stack([np.sin(np.linspace(0, 3, 400))] * 3)  # one slow swing: no averaging
    assert mean_standard_error(smooth) > 0.2 * np.sqrt(3) * smooth[:, 0].std()  # of the spread's order, not /√400
