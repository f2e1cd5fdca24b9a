"""The hand-held PDR/GNSS system on a simulated walk whose truth is known."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fusion.config import load_layout, read_yaml
from fusion.run import run_layout
from fusion.sim import simulate
from fusion.testing import CHECKS, check_system, default_context, with_value
from fusion_plugins.hand_pdr import HandPdr

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
SHORT = ["path.length_m=30", "path.width_m=20", "path.laps=1"]


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Path:
    """The foot + hand scenario on a shorter rectangle (about 100 m, 80 s)."""
    out = tmp_path_factory.mktemp("foot_hand")
    return simulate(CONFIGS / "foot_hand_gnss_outage.yaml", out, seed=1,
                    overrides=[*SHORT, "systems.hand_phone.gnss.outages=[{start_s: 40, duration_s: 20}]"]).config_path


def test_hand_pdr_conforms(walk):
    section = read_yaml(walk)["systems"]["hand_phone"]
    report = check_system(HandPdr, section, name="hand_phone", context=default_context(walk.parent), stochastic=False,
                          checks=[c for c in CHECKS if c != "chunking"], bad_configs=[(with_value(section, "step.weinberg_k", 0.0), "step.weinberg_k"),
                                       (with_value(section, "gnss.format", "morse"), "gnss.format")])
    assert report.failed == []


@pytest.mark.xfail(strict=True, reason="heading and bias covariance are propagated between events in one "
                   "step of Δt: split at other sample times the discretisation differs (~1e-6 m); bit-exact "
                   "chunking needs the propagation on the sample grid")
def test_hand_pdr_chunking_is_bit_exact(walk):
    section = read_yaml(walk)["systems"]["hand_phone"]
    check_system(HandPdr, section, name="hand_phone", context=default_context(walk.parent), stochastic=False,
                 checks=["chunking"])


def test_steps_are_found_one_for_one(walk):
    result = run_layout(load_layout(walk, ["fuser.method=none"]))
    hand = result.systems["hand_phone"]
    truth_steps = np.flatnonzero(np.loadtxt(walk.parent / "hand_phone_imu.csv", delimiter=",", skiprows=1)[:, -1])
    assert len(hand.step_index) == len(truth_steps)
    assert np.abs(hand.step_index - truth_steps).max() <= 5


def test_outage_masks_fixes_and_gnss_bounds_the_error(walk):
    result = run_layout(load_layout(walk, ["fuser.method=none"]))
    hand = result.systems["hand_phone"]
    assert hand.gnss_counts["masked"] == 20
    score = result.scores["hand_phone"]
    assert score.metrics["horizontal_error_m"]["rmse"] < 6.0  # GNSS: 1.5 m white + 3 m Gauss–Markov


def test_the_foot_constraint_holds_the_hand_during_the_outage(walk):
    free = run_layout(load_layout(walk, ["fuser.method=none"]))
    fused = run_layout(load_layout(walk))
    assert fused.fuser.activations > 0 and fused.fuser.max_violation_after_m < 1e-6
    window = lambda s: (s.t > 40) & (s.t < 60)  # noqa: E731
    err = {k: r.scores["hand_phone"].horizontal_error_m[window(r.scores["hand_phone"])].mean()
           for k, r in (("free", free), ("fused", fused))}
    assert err["fused"] < err["free"]


def test_cross_covariance_transition_forgets_the_previous_step_length(walk):
    loaded = load_layout(walk)
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(walk.parent))
    hand.track_transition()
    hand.advance(hand.t[hand.step_index[3]])
    phi = hand.transition_since_sync()
    assert np.all(phi[:, 4] == 0.0)  # δS of earlier steps does not carry over
    np.testing.assert_array_equal(hand.transition_since_sync(), np.eye(9))


def test_gnss_calibrates_the_step_scale_of_an_uncalibrated_step_model(tmp_path):
    """The default K (0.48) overestimates this walker's steps (~0.43): with the scale state
    on, 80 s of GNSS (1.5 m white, 3 m Gauss–Markov) remove most of the scale error and
    the estimate is consistent with its own σ."""
    res = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path, seed=2,
                   overrides=[*SHORT, "systems.hand_phone.gnss.outages=[]"])
    loaded = load_layout(res.config_path, ["systems.hand_phone.filter.step_scale_sd=0.1"])
    hand = HandPdr("hand_phone", loaded.system_configs["hand_phone"], default_context(tmp_path))
    hand.advance(hand.t_end)
    true_scale = res.distance_m / hand.step_length_m.sum()
    assert abs(true_scale - 1.0) > 0.05  # the model is off
    scale, sd = hand.x[7], np.sqrt(hand.P[8, 8])
    assert abs(scale - true_scale) < 0.5 * abs(1.0 - true_scale)
    assert abs(scale - true_scale) < 2 * sd
    assert hand.diagnostics()["step_scale"] == scale


def test_weinberg_k_calibrated_on_one_walk_measures_another_to_three_percent(tmp_path):
    """Calibrate K on a walk of known length (seed 0), then measure a different walk (seed 1,
    other noise, other hand sway): mean step length within 3 % of the true 0.70 m."""
    from fusion.readers import read_imu_csv
    from fusion_plugins.hand_pdr.config import StepConfig
    from fusion_plugins.hand_pdr.pdr import calibrate_weinberg_k, detect_steps, step_lengths

    def imu(seed):
        res = simulate(CONFIGS / "foot_hand_gnss_outage.yaml", tmp_path / str(seed), seed=seed, overrides=SHORT)
        s = read_imu_csv(res.out_dir / "hand_phone_imu.csv", acc_columns=("acc_x", "acc_y", "acc_z"),
                         gyro_columns=("gyro_x", "gyro_y", "gyro_z"), time_column="t")
        return s, res.distance_m

    cal, distance = imu(0)
    k = calibrate_weinberg_k(cal.t, cal.acc_b, distance, StepConfig(), 9.80665)
    cfg = StepConfig(weinberg_k=k)
    test, _ = imu(1)
    lengths = step_lengths(test.t, test.acc_b, detect_steps(test.t, test.acc_b, cfg, 9.80665), cfg)
    assert abs(lengths.mean() - 0.70) / 0.70 < 0.03
