"""The simulated foot IMU tells its filter its own error model: Gauss–Markov biases with their
correlation time when that is all the bias is, the ZUPT σ of the simulated stance, and the
gyro-bias σ the still-window average leaves."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from bodyfusion.plugins.foot_ins.simulation import STILL_ZUPT_SIGMA_MPS
from bodyfusion.sim import simulate
from bodyfusion.sim.imu import SensorErrors

SCENARIO = """
name: model
rate_hz: 100
path: {kind: polyline, waypoints_m: [[0, 0], [0, 5]]}
gait: {start_still_s: 1, end_still_s: 0.5}
systems:
  still:    {kind: foot_imu, foot: left,  imu: {preset: icm20948}}
  turn_on:  {kind: foot_imu, foot: right, imu: {preset: icm20948, acc_bias_mps2: [0.01, 0, 0]}}
  drifting: {kind: foot_imu, foot: left,  imu: {preset: icm20948, gyro_bias_random_walk: 1e-5},
             stance_noise: {colour_factor: 0.9, sigma_mps: 0.005}}
"""


@pytest.fixture(scope="module")
def filters(tmp_path_factory) -> dict[str, dict]:
    folder = tmp_path_factory.mktemp("model")
    (folder / "model.yaml").write_text(SCENARIO)
    config = simulate(folder / "model.yaml", folder / "out", seed=0).config_path
    return {name: section["filter"] for name, section in yaml.safe_load(config.read_text())["systems"].items()}


def test_gauss_markov_biases_are_told_with_their_correlation_time(filters):
    """ICM-20948: both biases are Gauss–Markov, τ = 100 s, driven by σ √(2/τ)."""
    still = filters["still"]
    assert still["acc_bias_tau_s"] == still["gyro_bias_tau_s"] == 100.0
    assert still["gyro_bias_random_walk"] == pytest.approx(13.0 * math.pi / 180 / 3600 * math.sqrt(2 / 100))


def test_a_bias_with_more_than_a_gauss_markov_part_stays_a_random_walk(filters):
    """A turn-on accelerometer bias, or a gyro random walk beside the Gauss–Markov bias: the
    filter keeps the random walk (a decaying estimate would forget the constant part)."""
    assert "acc_bias_tau_s" not in filters["turn_on"] and filters["turn_on"]["gyro_bias_tau_s"] == 100.0
    assert "gyro_bias_tau_s" not in filters["drifting"] and filters["drifting"]["acc_bias_tau_s"] == 100.0


def test_zupt_sigma_is_that_of_the_simulated_stance(filters):
    """At rest the zero velocity is exact (the floor); an AR(1) stance drift gives its
    stationary σ_ξ / √(1 − α²)."""
    assert filters["still"]["zupt_sigma_mps"] == STILL_ZUPT_SIGMA_MPS
    assert filters["drifting"]["zupt_sigma_mps"] == pytest.approx(0.005 / math.sqrt(1 - 0.9**2))


@pytest.mark.parametrize("window_s", [0.5, 3.0, 300.0])
def test_still_window_gyro_bias_sigma_is_what_the_average_leaves(window_s):
    """var(b_0 − mean of b over [0, T]) of a Gauss–Markov bias, by quadrature of its
    autocorrelation σ² e^(−|t−s|/τ), beside the average's white-noise error N/√T."""
    errors = SensorErrors(noise_density=1e-4, bias_instability=5e-5, bias_tau_s=100.0)
    s = np.linspace(0.0, window_s, 2001)
    rho = np.exp(-np.abs(s[:, None] - s[None, :]) / errors.bias_tau_s)
    var_gm = errors.bias_instability**2 * (1.0 - 2.0 * np.trapezoid(rho[0], s) / window_s
                                           + np.trapezoid(np.trapezoid(rho, s), s) / window_s**2)
    want = math.sqrt(var_gm + errors.noise_density**2 / window_s)
    assert errors.initial_bias_sd(window_s) == pytest.approx(want, rel=1e-5)
