"""Heading stays unobservable through the stance updates (observability-constrained EKF,
bodyfusion.nav.zupt): a rotation of the whole state about Up, N(x̂) = [·; e_z × v̂; e_z; 0; 0],
is hidden by the ZUPT's Jacobian, carried from sample to sample by the propagation and across
a correction by the closed-loop reset, so the information along it never grows."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.nav.error_state import ERROR_SIZE, accumulate_propagation
from bodyfusion.nav.kalman import selection_moments, selection_update
from bodyfusion.nav.strapdown import mechanise
from bodyfusion.nav.zupt import zero_angular_rate_update, zero_velocity_update
from bodyfusion.plugins.foot_ins.coloured import coloured_zero_velocity_update
from bodyfusion.plugins.foot_ins.records import FilterState, StepScratch
from bodyfusion.testing import random_nominal_state

EMPTY = np.empty((0, 0))
WORK = np.empty((ERROR_SIZE, ERROR_SIZE))


def random_spd(rng: np.random.Generator, scale: float = 1e-3) -> np.ndarray:
    A = rng.normal(0, 1, (ERROR_SIZE, ERROR_SIZE))
    return scale * (A @ A.T / ERROR_SIZE + 0.1 * np.eye(ERROR_SIZE))


def heading_direction(x: np.ndarray) -> np.ndarray:
    """N(x) without its position part (a translation, unobservable by itself): the error-state
    change of a small rotation of the whole state about Up, per radian."""
    n = np.zeros(ERROR_SIZE)
    n[3:6] = np.cross([0.0, 0.0, 1.0], x[3:6])
    n[8] = 1.0
    return n


def information(P: np.ndarray, n: np.ndarray) -> float:
    return float(n @ np.linalg.solve(P, n))


def moving_state(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    x = random_nominal_state(rng)
    x[3:6] = [0.03, -0.02, 0.01]
    return x, random_spd(rng)


def test_selection_update_equals_the_textbook_joseph_update():
    """H = [0 I h 0 0] (velocity states and a heading column h, as the ZUPT's)."""
    rng = np.random.default_rng(1)
    P = random_spd(rng, 1.0)
    h = rng.normal(0, 1, 3)
    H = np.zeros((3, ERROR_SIZE))
    H[:, 3:6] = np.eye(3)
    H[:, 8] = h
    y, r_var = rng.normal(0, 1, 3), 0.2**2
    S = H @ P @ H.T + r_var * np.eye(3)
    K = P @ H.T @ np.linalg.inv(S)
    IKH = np.eye(ERROR_SIZE) - K @ H
    got, dx, phi = P.copy(), np.empty(ERROR_SIZE), np.eye(ERROR_SIZE)
    S0 = selection_moments(got, 3, tuple(h), WORK)
    np.testing.assert_allclose(np.array(S0), (H @ P @ H.T)[np.triu_indices(3)], atol=1e-12, rtol=0)
    nis = selection_update(got, 3, tuple(h), S0, r_var, tuple(y), dx, phi, WORK)
    np.testing.assert_allclose(got, IKH @ P @ IKH.T + r_var * K @ K.T, atol=1e-12, rtol=0)
    np.testing.assert_allclose(dx, K @ y, atol=1e-12, rtol=0)
    np.testing.assert_allclose(phi, IKH, atol=1e-12, rtol=0)
    np.testing.assert_array_equal(got, got.T)
    assert nis == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-12)


def test_the_plain_zupt_at_a_moving_prior_would_measure_heading():
    """H = [0 I 0 0 0] at v̂ ≠ 0 sees a rotation about Up (H N = e_z × v̂): that is the
    information the constrained update leaves out."""
    x, P = moving_state(np.random.default_rng(2))
    n = heading_direction(x)
    H = np.zeros((3, ERROR_SIZE))
    H[:, 3:6] = np.eye(3)
    P_plain = np.linalg.inv(np.linalg.inv(P) + H.T @ H / 1e-4**2)
    assert information(P_plain, n) > 10 * information(P, n)


@pytest.mark.parametrize("gate", [0.0, 1.0])
def test_zupt_and_reset_add_no_information_about_a_rotation_about_up(gate):
    """Before: N(x̂⁻) with P⁻; after: N(x̂⁺) with P⁺ — the same information, whether the
    update is consistent or de-weighted by the gate (gate 1: every update is beyond it)."""
    x, P = moving_state(np.random.default_rng(3))
    before = information(P, heading_direction(x))
    zero_velocity_update(x, P, 1e-4, gate, np.empty(ERROR_SIZE), EMPTY, WORK)
    assert np.linalg.norm(x[3:6]) < 0.03
    assert information(P, heading_direction(x)) == pytest.approx(before, rel=1e-7)
    np.testing.assert_array_equal(P, P.T)


def test_zaru_adds_no_information_about_a_rotation_about_up():
    x, P = moving_state(np.random.default_rng(4))
    before = information(P, heading_direction(x))
    zero_angular_rate_update(x, P, np.array([0.01, -0.02, 0.005]), 1e-3, np.empty(ERROR_SIZE), EMPTY, WORK)
    assert information(P, heading_direction(x)) == pytest.approx(before, rel=1e-7)


def test_coloured_update_adds_no_information_about_a_rotation_about_up():
    """The cKF's differenced update (without process noise, so that it is a plain update of
    H̄ = H − α H F⁻¹) at a moving prior."""
    rng = np.random.default_rng(5)
    x, P = moving_state(rng)
    before = information(P, heading_direction(x))
    C = Rotation.random(random_state=6).as_matrix()
    step = StepScratch(np.zeros(17), np.array([0.3, -0.2, 9.8]), C, np.empty((15, 15)), np.empty(ERROR_SIZE))
    coloured_zero_velocity_update(FilterState(x, P, np.zeros(6), EMPTY), np.array([0.02, -0.01, 0.0]), step, 0.01,
                                  0.8, 1e-3, 0.0)
    assert information(P, heading_direction(x)) == pytest.approx(before, rel=1e-7)


@pytest.mark.parametrize("seed", range(3))
def test_propagation_carries_the_rotation_about_up_to_the_next_sample(seed):
    """F N(x̂_k) = N(x̂_{k+1}) (velocity and attitude exactly; F's δv column makes a position
    change, a translation): f_n dt is the mechanisation's own velocity increment."""
    rng = np.random.default_rng(10 + seed)
    x = random_nominal_state(rng)
    acc, gyro, dt = rng.normal(0, 5, 3) + [0, 0, 9.8], rng.normal(0, 2, 3), 0.01
    n0 = heading_direction(x)
    f_n, C = np.empty(3), np.empty((3, 3))
    mechanise(x, acc, gyro, dt, 9.8, np.zeros(3), f_n, rng.normal(0, 0.01, 6), C)
    F = np.eye(ERROR_SIZE)
    accumulate_propagation(F, C, f_n, dt)
    carried = F @ n0
    np.testing.assert_allclose(carried[3:], heading_direction(x)[3:], atol=1e-14, rtol=0)
    np.testing.assert_allclose(carried[0:3], dt * n0[3:6], atol=1e-15, rtol=0)
