"""The 1σ of a quaternion's components and of its ZYX Euler angles from the attitude error's
covariance: checked against the spread of attitudes drawn from that error (Monte Carlo, seeded)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.nav.attitude import quat_from_azimuth_pitch_roll
from bodyfusion.nav.attitude_uncertainty import euler_sd_deg, quaternion_sd, unpack_covariance


def _random_covariance(rng: np.random.Generator, scale_rad: float) -> np.ndarray:
    A = rng.normal(scale=scale_rad, size=(3, 3))
    return A @ A.T + np.diag(rng.uniform(0.1, 1.0, 3)) * scale_rad**2


@pytest.mark.parametrize("azimuth, pitch, roll", [(30.0, 10.0, -5.0), (200.0, -40.0, 25.0), (359.0, 70.0, 170.0)])
def test_the_sigmas_match_the_spread_of_attitudes_drawn_from_the_error(azimuth, pitch, roll):
    rng = np.random.default_rng(7)
    q = quat_from_azimuth_pitch_roll(*np.radians([azimuth, pitch, roll]))
    cov = _random_covariance(rng, np.radians(0.5))
    draws = rng.multivariate_normal(np.zeros(3), cov, size=200_000)
    # C_true = (I + [δθ×]) C: the error rotation applied on the navigation side
    true = Rotation.from_rotvec(draws) * Rotation.from_quat(q, scalar_first=True)
    q_true = true.as_quat(scalar_first=True)
    q_true *= np.sign(q_true @ q)[:, None]  # the same hemisphere as q
    euler = np.degrees(true.as_euler("ZYX"))  # yaw, pitch, roll
    euler[:, 0] = (euler[:, 0] - euler[:, 0].mean() + 180.0) % 360.0 - 180.0  # unwrap yaw about its mean
    np.testing.assert_allclose(quaternion_sd(q[None], cov[None])[0], q_true.std(axis=0), rtol=0.02, atol=1e-6)
    np.testing.assert_allclose(euler_sd_deg(q[None], cov[None])[0], euler[:, ::-1].std(axis=0), rtol=0.02)


def test_at_gimbal_lock_the_euler_sigmas_are_not_given():
    q = quat_from_azimuth_pitch_roll(0.3, np.pi / 2, 0.1)
    sd = euler_sd_deg(q[None], np.eye(3)[None] * 1e-4)
    assert np.isnan(sd).all()


def test_a_packed_covariance_unpacks_symmetric_in_its_order():
    packed = np.array([[1.0, 2.0, 3.0, 0.1, 0.2, 0.3]])
    np.testing.assert_array_equal(unpack_covariance(packed)[0], [[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]])
