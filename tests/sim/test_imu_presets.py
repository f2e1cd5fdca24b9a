"""The named IMU presets: their figures pinned by name, in the units they are quoted in."""

from __future__ import annotations

import math

import pytest

from bodyfusion.sim.imu import PRESETS, ImuErrorConfig

G = 9.80665
DEG = math.pi / 180.0
UG = 1e-6 * G


def test_consumer_preset_figures():
    """Consumer-grade MEMS (MPU-6050 class): ARW 1 °/√h, 100 °/h bias instability (τ 100 s),
    1 °/s turn-on; 400 µg/√Hz, 2 mg bias instability (τ 100 s), 20 mg turn-on."""
    e = ImuErrorConfig(preset="consumer").resolve()
    assert e.gyro.noise_density == pytest.approx(1.0 * DEG / 60.0)
    assert e.gyro.bias_instability == pytest.approx(100.0 * DEG / 3600.0)
    assert e.gyro.bias_tau_s == 100.0
    assert e.gyro.bias_sd == pytest.approx(1.0 * DEG)
    assert e.acc.noise_density == pytest.approx(400.0 * UG)
    assert e.acc.bias_instability == pytest.approx(2000.0 * UG)
    assert e.acc.bias_tau_s == 100.0
    assert e.acc.bias_sd == pytest.approx(20000.0 * UG)
    assert e.gyro.bias_random_walk == e.acc.bias_random_walk == 0.0
    assert e.gyro.bias == e.acc.bias == (0.0, 0.0, 0.0)


def test_consumer_is_an_order_worse_than_icm20948_in_bias_instability():
    consumer = ImuErrorConfig(preset="consumer").resolve()
    icm = ImuErrorConfig(preset="icm20948").resolve()
    assert consumer.gyro.bias_instability / icm.gyro.bias_instability > 7
    assert consumer.acc.bias_instability / icm.acc.bias_instability > 10
    assert consumer.gyro.noise_density > icm.gyro.noise_density
    assert consumer.acc.noise_density > icm.acc.noise_density


def test_every_preset_is_selectable_by_name():
    for name in PRESETS:
        ImuErrorConfig(preset=name).resolve()
