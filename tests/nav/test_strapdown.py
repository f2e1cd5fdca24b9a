"""Tests for bodyfusion.nav.strapdown (mechanisation) and bodyfusion.nav.attitude (conventions).

Conventions under test (fusion/quaternion.py): scalar-first Hamilton quaternions,
q_nb maps body vectors into ENU, azimuth clockwise from North.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.nav.attitude import (
    azimuth_pitch_roll,
    levelling,
    quat_from_azimuth_pitch_roll,
    quat_from_rotvec,
    quat_multiply,
    quat_normalised,
    quat_to_dcm,
)
from bodyfusion.nav.earth import EARTH_RATE, earth_rate_enu
from bodyfusion.nav.strapdown import NOMINAL_SIZE, integrate, mechanise

G = 9.8
NO_EARTH = np.zeros(3)


def nominal(q=(1.0, 0.0, 0.0, 0.0), p=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0)) -> np.ndarray:
    x = np.zeros(NOMINAL_SIZE)
    x[0:3] = p
    x[3:6] = v
    x[6:10] = q
    return x


def const_imu(n: int, rate_hz: float, acc, gyro) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) / rate_hz
    acc_b = np.ascontiguousarray(np.tile(np.asarray(acc, float), (n, 1)))
    gyro_b = np.ascontiguousarray(np.tile(np.asarray(gyro, float), (n, 1)))
    return t, acc_b, gyro_b


def rotation_angle_between(q1: np.ndarray, q2: np.ndarray) -> float:
    r = Rotation.from_quat(q1, scalar_first=True) * Rotation.from_quat(q2, scalar_first=True).inv()
    return float(r.magnitude())


# --------------------------------------------------------------------------- mechanisation


def test_static_levelled_imu_stays_put_for_60_s():
    t, acc, gyro = const_imu(6001, 100.0, [0.0, 0.0, G], [0.0, 0.0, 0.0])
    x0 = nominal(p=(1.0, -2.0, 0.5))
    out = integrate(x0, t, acc, gyro, G, NO_EARTH)
    assert out.shape == (6001, NOMINAL_SIZE)
    assert np.max(np.abs(out[:, 0:3] - x0[0:3])) < 1e-9
    assert np.max(np.abs(out[:, 3:6])) < 1e-9
    np.testing.assert_allclose(out[-1, 6:10], x0[6:10], atol=1e-15)


def test_constant_rotation_about_one_axis_matches_scipy_exactly():
    rate = 0.7  # rad/s about body z
    n, fs = 2001, 200.0
    t, acc, gyro = const_imu(n, fs, [0.0, 0.0, G], [0.0, 0.0, rate])
    out = integrate(nominal(), t, acc, gyro, G, NO_EARTH)
    for i in (1, 100, n - 1):
        expected = Rotation.from_rotvec([0.0, 0.0, rate * (t[i] - t[0])]).as_quat(scalar_first=True)
        q = out[i, 6:10]
        q = q if np.dot(q, expected) >= 0 else -q
        np.testing.assert_allclose(q, expected, atol=1e-12, rtol=0)
    # total angle is 7 rad: more than one full turn, not a small-angle coincidence
    assert rate * t[-1] > 2 * np.pi


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_constant_rotation_about_each_body_axis_from_tilted_start(axis):
    rate = np.zeros(3)
    rate[axis] = -1.3
    q0 = Rotation.from_euler("ZYX", [0.4, -0.3, 0.2]).as_quat(scalar_first=True)
    n, fs = 1001, 100.0
    t, acc, gyro = const_imu(n, fs, [0.0, 0.0, 0.0], rate)
    out = integrate(nominal(q0), t, acc, gyro, 0.0, NO_EARTH)
    # body rate: q_nb(t) = q_nb(0) ⊗ exp(ω t)
    expected = (Rotation.from_quat(q0, scalar_first=True) * Rotation.from_rotvec(rate * t[-1])).as_quat(
        scalar_first=True)
    q = out[-1, 6:10]
    q = q if np.dot(q, expected) >= 0 else -q
    np.testing.assert_allclose(q, expected, atol=1e-12, rtol=0)


def test_constant_nav_acceleration_gives_half_a_t_squared():
    a = np.array([0.3, -0.2, 0.1])
    n, fs = 1001, 100.0
    t, acc, gyro = const_imu(n, fs, a + [0.0, 0.0, G], [0.0, 0.0, 0.0])
    out = integrate(nominal(), t, acc, gyro, G, NO_EARTH)
    T = t - t[0]
    np.testing.assert_allclose(out[:, 0:3], 0.5 * np.outer(T**2, a), atol=1e-9, rtol=0)
    np.testing.assert_allclose(out[:, 3:6], np.outer(T, a), atol=1e-10, rtol=0)


@pytest.mark.parametrize("azimuth,pitch,roll", [(0.3, 0.4, -0.6), (2.5, -1.1, 0.9), (-1.0, 0.05, 2.8)])
def test_tilted_static_imu_stays_put(azimuth, pitch, roll):
    q = quat_from_azimuth_pitch_roll(azimuth, pitch, roll)
    C_bn = Rotation.from_quat(q, scalar_first=True).as_matrix().T
    f_b = C_bn @ np.array([0.0, 0.0, G])
    t, acc, gyro = const_imu(6001, 100.0, f_b, [0.0, 0.0, 0.0])
    out = integrate(nominal(q), t, acc, gyro, G, NO_EARTH)
    assert np.max(np.abs(out[:, 0:3])) < 1e-9
    assert np.max(np.abs(out[:, 3:6])) < 1e-10
    assert rotation_angle_between(out[-1, 6:10], q) < 1e-12


def test_biases_are_subtracted_from_the_measurements():
    b_a = np.array([0.05, -0.03, 0.02])
    b_g = np.array([0.01, 0.002, -0.004])
    t, acc, gyro = const_imu(3001, 100.0, np.array([0.0, 0.0, G]) + b_a, b_g)
    x0 = nominal()
    x0[10:13] = b_a
    x0[13:16] = b_g
    out = integrate(x0, t, acc, gyro, G, NO_EARTH)
    assert np.max(np.abs(out[:, 0:6])) < 1e-9
    assert rotation_angle_between(out[-1, 6:10], x0[6:10]) < 1e-12
    np.testing.assert_array_equal(out[-1, 10:16], x0[10:16])


def test_quaternion_stays_unit_norm_over_1e5_random_steps():
    rng = np.random.default_rng(7)
    n = 100_000
    t = np.cumsum(rng.uniform(0.002, 0.02, n))
    acc = np.ascontiguousarray(rng.normal(0.0, 20.0, (n, 3)))
    gyro = np.ascontiguousarray(rng.normal(0.0, 8.0, (n, 3)))
    q0 = Rotation.random(random_state=3).as_quat(scalar_first=True)
    out = integrate(nominal(q0), t, acc, gyro, G, earth_rate_enu(50.0))
    norms = np.linalg.norm(out[:, 6:10], axis=1)
    assert np.max(np.abs(norms - 1.0)) < 1e-12
    assert np.all(np.isfinite(out))


def test_mechanise_returns_start_dcm_and_mean_nav_specific_force():
    q = quat_from_azimuth_pitch_roll(1.0, 0.2, -0.3)
    x = nominal(q)
    f_n = np.empty(3)
    acc = np.array([0.4, -0.1, 9.9])
    gyro = np.zeros(3)
    C = np.empty((3, 3))
    mechanise(x, acc, gyro, 0.01, G, NO_EARTH, f_n, np.zeros(6), C)
    C_ref = Rotation.from_quat(q, scalar_first=True).as_matrix()
    np.testing.assert_allclose(C, C_ref, atol=1e-14)
    np.testing.assert_allclose(f_n, C_ref @ acc, atol=1e-12)


def _static_with_earth_rate(lat: float = 48.0, n: int = 6001):
    w_ie_n = earth_rate_enu(lat)
    q = quat_from_azimuth_pitch_roll(0.8, 0.15, -0.25)
    C_bn = Rotation.from_quat(q, scalar_first=True).as_matrix().T
    f_b = C_bn @ np.array([0.0, 0.0, G])
    w_b = C_bn @ w_ie_n
    t, acc, gyro = const_imu(n, 100.0, f_b, w_b)
    return q, t, acc, gyro, w_ie_n


def test_static_imu_measuring_earth_rate_keeps_attitude_with_earth_rate_on():
    q, t, acc, gyro, w_ie_n = _static_with_earth_rate()
    out = integrate(nominal(q), t, acc, gyro, G, w_ie_n)
    angles = [rotation_angle_between(out[i, 6:10], q) for i in range(0, len(t), 500)]
    assert max(angles) < 1e-11
    # the test has teeth: without the option the same data turns the attitude by ω_ie t
    off = integrate(nominal(q), t, acc, gyro, G, NO_EARTH)
    drift = rotation_angle_between(off[-1, 6:10], q)
    assert drift == pytest.approx(EARTH_RATE * 60.0, rel=1e-6)


def test_static_imu_measuring_earth_rate_stays_put_in_position_with_earth_rate_on():
    q, t, acc, gyro, w_ie_n = _static_with_earth_rate()
    out = integrate(nominal(q), t, acc, gyro, G, w_ie_n)
    assert np.max(np.abs(out[:, 3:6])) < 1e-8
    assert np.max(np.abs(out[:, 0:3])) < 1e-7


def test_earth_rate_coriolis_term_on_a_moving_body():
    """v̇ = C f + g − 2 ω_ie × v: a levelled IMU moving East at 10 m/s, no specific force
    beyond gravity support, is deflected by −2 ω_ie × v (plus the −½ (ω_ie dt) × Δv_n
    rotation of the navigation frame over the step)."""
    w = earth_rate_enu(45.0)
    x = nominal(v=(10.0, 0.0, 0.0))
    f_n = np.empty(3)
    dt = 0.01
    mechanise(x, np.array([0.0, 0.0, G]), np.zeros(3), dt, G, w, f_n, np.zeros(6), np.empty((3, 3)))
    expected_dv = -2.0 * np.cross(w, [10.0, 0.0, 0.0]) * dt - 0.5 * dt * np.cross(w, [0.0, 0.0, G * dt])
    np.testing.assert_allclose(x[3:6] - [10.0, 0.0, 0.0], expected_dv, atol=1e-15)


# --------------------------------------------------------------------------- quaternion helpers


def test_quat_to_dcm_matches_scipy():
    for q in Rotation.random(20, random_state=1).as_quat(scalar_first=True):
        np.testing.assert_allclose(quat_to_dcm(q), Rotation.from_quat(q, scalar_first=True).as_matrix(),
                                   atol=1e-14)


def test_quat_multiply_is_hamilton_product_matching_scipy_composition():
    ra, rb = Rotation.random(2, random_state=2)
    a, b = ra.as_quat(scalar_first=True), rb.as_quat(scalar_first=True)
    expected = (ra * rb).as_quat(scalar_first=True)
    got = np.array(quat_multiply(tuple(a), tuple(b)))  # the kernels' quaternions are 4-tuples
    got = got if np.dot(got, expected) >= 0 else -got
    np.testing.assert_allclose(got, expected, atol=1e-15)
    # i ⊗ j = k (Hamilton, not JPL)
    assert quat_multiply((0.0, 1.0, 0.0, 0.0), (0.0, 0.0, 1.0, 0.0)) == (0.0, 0.0, 0.0, 1.0)


@pytest.mark.parametrize("rotvec", [[0.3, -1.2, 2.0], [1e-3, 2e-3, -5e-4], [3e-9, -1e-9, 2e-9], [0.0, 0.0, 0.0],
                                    [0.0, 0.0, np.pi]])
def test_quat_from_rotvec_matches_scipy_including_small_angles(rotvec):
    r = np.asarray(rotvec, float)
    expected = Rotation.from_rotvec(r).as_quat(scalar_first=True)
    np.testing.assert_allclose(quat_from_rotvec(tuple(r)), expected, atol=1e-16, rtol=1e-15)


def test_quat_normalised_has_unit_norm_and_the_same_direction():
    q = (2.1, 0.1, 0.1, 0.1)
    unit = np.array(quat_normalised(q))
    assert np.linalg.norm(unit) == pytest.approx(1.0, abs=1e-15)
    np.testing.assert_allclose(unit * np.linalg.norm(q), q, rtol=1e-15)


def test_mechanise_writes_c_nb_at_the_start_of_the_step_into_the_callers_buffer():
    x = nominal(q=Rotation.from_rotvec([0.1, -0.2, 0.3]).as_quat(scalar_first=True))
    C_start = Rotation.from_quat(x[6:10], scalar_first=True).as_matrix()
    C = np.full((3, 3), np.nan)
    mechanise(x, np.array([0.4, -0.1, 9.9]), np.array([0.01, 0.02, -0.03]), 0.01, G, NO_EARTH, np.empty(3),
              np.zeros(6), C)
    np.testing.assert_allclose(C, C_start, atol=1e-14)


ALLOCATIONS = """
import numba, numpy as np
from numba.core.runtime import rtsys
from bodyfusion.nav.strapdown import mechanise

@numba.njit
def steps(x, acc, gyro, w_ie_n, n):
    f_n, prev, C = np.empty(3), np.zeros(6), np.empty((3, 3))
    for _ in range(n):
        mechanise(x, acc, gyro, 0.01, 9.8, w_ie_n, f_n, prev, C)

x = np.zeros(16)
x[6] = 1.0
acc, gyro, w_ie_n = np.array([0.4, -0.1, 9.9]), np.array([0.01, 0.02, -0.03]), np.array([0.0, 5e-5, 4e-5])
steps(x, acc, gyro, w_ie_n, 1)
counts = []
for n in (10, 1000):
    before = rtsys.get_allocation_stats().alloc
    steps(x, acc, gyro, w_ie_n, n)
    counts.append(rtsys.get_allocation_stats().alloc - before)
print(counts[1] - counts[0])
"""


def test_a_strapdown_step_allocates_no_array():
    """The per-sample step allocates nothing (3-vectors are scalars, quaternions 4-tuples, C_nb
    the caller's buffer): numba's allocation counter (``NUMBA_NRT_STATS``) moves as much for a
    call of a thousand steps as for one of ten."""
    import os
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", ALLOCATIONS], capture_output=True, text=True, check=True,
                         env={**os.environ, "NUMBA_NRT_STATS": "1"})
    assert int(out.stdout.strip().splitlines()[-1]) == 0


def test_azimuth_pitch_roll_round_trip_and_scipy_agreement():
    rng = np.random.default_rng(4)
    for _ in range(50):
        az = rng.uniform(0, 2 * np.pi)
        pitch = rng.uniform(-1.4, 1.4)
        roll = rng.uniform(-3.0, 3.0)
        q = quat_from_azimuth_pitch_roll(az, pitch, roll)
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        ref = Rotation.from_euler("ZYX", [np.pi / 2 - az, pitch, roll]).as_matrix()
        np.testing.assert_allclose(quat_to_dcm(q), ref, atol=1e-14)
        got = azimuth_pitch_roll(q)
        np.testing.assert_allclose(got, [az, pitch, roll], atol=1e-10)


def test_azimuth_pitch_roll_is_vectorised_over_rows():
    angles = np.array([[0.1, 0.2, 0.3], [4.0, -0.5, -1.0], [6.0, 1.0, 2.0]])
    qs = np.array([quat_from_azimuth_pitch_roll(*a) for a in angles])
    got = azimuth_pitch_roll(qs)
    assert got.shape == (3, 3)
    np.testing.assert_allclose(got.T, angles, atol=1e-10)


@pytest.mark.parametrize("azimuth_deg,body_x_enu", [(0.0, [0, 1, 0]), (90.0, [1, 0, 0]), (180.0, [0, -1, 0]),
                                                    (270.0, [-1, 0, 0])])
def test_azimuth_is_clockwise_from_north(azimuth_deg, body_x_enu):
    q = quat_from_azimuth_pitch_roll(np.deg2rad(azimuth_deg), 0.0, 0.0)
    np.testing.assert_allclose(quat_to_dcm(q) @ [1.0, 0.0, 0.0], body_x_enu, atol=1e-15)
    np.testing.assert_allclose(quat_to_dcm(q) @ [0.0, 0.0, 1.0], [0, 0, 1], atol=1e-15)
    assert azimuth_pitch_roll(q)[0] == pytest.approx(np.deg2rad(azimuth_deg) % (2 * np.pi), abs=1e-12)


def test_levelling_recovers_pitch_and_roll_of_a_static_imu():
    rng = np.random.default_rng(5)
    for _ in range(50):
        az, pitch, roll = rng.uniform(0, 6.2), rng.uniform(-1.4, 1.4), rng.uniform(-3.0, 3.0)
        q = quat_from_azimuth_pitch_roll(az, pitch, roll)
        f_b = Rotation.from_quat(q, scalar_first=True).as_matrix().T @ [0.0, 0.0, 9.81]
        p_est, r_est = levelling(f_b)
        assert p_est == pytest.approx(pitch, abs=1e-12)
        assert r_est == pytest.approx(roll, abs=1e-12)
        # levelled attitude with the true azimuth reproduces the true attitude
        q_lev = quat_from_azimuth_pitch_roll(az, p_est, r_est)
        assert rotation_angle_between(q_lev, q) < 1e-11
