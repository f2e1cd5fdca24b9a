"""Tests for bodyfusion.nav.error_state and bodyfusion.nav.zupt: the 15-state error model is the
linearisation of bodyfusion.nav.strapdown.mechanise, and the updates are the textbook KF.

Error convention (fusion/error_state.py): true minus estimated; attitude error δθ in the
navigation frame on the LEFT, C_true = (I + [δθ×]) C_est, applied by ``inject``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from bodyfusion.nav.error_state import (ERROR_SIZE, closed_loop_reset, filter_params,
                                       decay_biases, error_between, inject, process_noise_diag, propagate_covariance)
from bodyfusion.nav.kalman import inv3_sym, update_selected
from bodyfusion.nav.strapdown import mechanise
from bodyfusion.nav.zupt import zero_angular_rate_update, zero_velocity_update
from bodyfusion.testing import random_nominal_state

G = 9.8
NO_EARTH = np.zeros(3)


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])




def random_spd(rng: np.random.Generator, n: int = ERROR_SIZE, scale: float = 1.0) -> np.ndarray:
    A = rng.normal(0, 1, (n, n))
    return scale * (A @ A.T / n + 0.1 * np.eye(n))




def step(x: np.ndarray, acc: np.ndarray, gyro: np.ndarray, dt: float):
    x = x.copy()
    f_n, C = np.empty(3), np.empty((3, 3))
    mechanise(x, acc, gyro, dt, G, NO_EARTH, f_n, np.zeros(6), C)
    return x, C, f_n


def perturbed(x: np.ndarray, dx: np.ndarray) -> np.ndarray:
    out = x.copy()
    inject(out, np.ascontiguousarray(dx, dtype=np.float64))
    return out


def F_from_propagate(C: np.ndarray, f_n: np.ndarray, dt: float) -> np.ndarray:
    """Recover F = I + A dt column by column: with P = e_i e_iᵀ and Q = 0, F P Fᵀ = f_i f_iᵀ,
    whose column i is f_i · F[i, i] = f_i (A has a zero diagonal, so F[i, i] = 1)."""
    F = np.empty((ERROR_SIZE, ERROR_SIZE))
    for i in range(ERROR_SIZE):
        P = np.zeros((ERROR_SIZE, ERROR_SIZE))
        P[i, i] = 1.0
        propagate_covariance(P, C, f_n, dt, np.zeros(ERROR_SIZE))
        assert P[i, i] == pytest.approx(1.0, abs=1e-12)
        F[:, i] = P[:, i]
    return F


def F_finite_difference(x: np.ndarray, acc: np.ndarray, gyro: np.ndarray, dt: float, eps: float = 1e-6) -> np.ndarray:
    """Central differences of the error after one mechanisation step of true vs estimated state."""
    x_est1, _, _ = step(x, acc, gyro, dt)
    F = np.empty((ERROR_SIZE, ERROR_SIZE))
    for i in range(ERROR_SIZE):
        e = np.zeros(ERROR_SIZE)
        e[i] = eps
        xp, _, _ = step(perturbed(x, e), acc, gyro, dt)
        xm, _, _ = step(perturbed(x, -e), acc, gyro, dt)
        F[:, i] = (error_between(xp, x_est1) - error_between(xm, x_est1)) / (2 * eps)
    return F


def dense_A(C: np.ndarray, f_n: np.ndarray) -> np.ndarray:
    """A of the module docstring, dense."""
    A = np.zeros((ERROR_SIZE, ERROR_SIZE))
    A[0:3, 3:6] = np.eye(3)
    A[3:6, 6:9] = -skew(f_n)
    A[3:6, 9:12] = -C
    A[6:9, 12:15] = -C
    return A


IMU_CASES = [
    (np.array([0.3, -0.4, 9.9]), np.array([0.02, -0.01, 0.03])),     # near stance
    (np.array([4.0, -7.0, 15.0]), np.array([1.5, -3.0, 0.8])),      # swing, fast rotation
    (np.array([-2.0, 1.0, 3.0]), np.array([-0.2, 0.1, -2.5])),
]


# --------------------------------------------------------------------------- linearisation


@pytest.mark.parametrize("case", range(len(IMU_CASES)))
def test_transition_matrix_is_the_linearisation_of_mechanise(case):
    rng = np.random.default_rng(10 + case)
    acc, gyro = IMU_CASES[case]
    x = random_nominal_state(rng)
    dt = 0.01
    _, C, f_n = step(x, acc, gyro, dt)
    F = F_from_propagate(C, f_n, dt)
    F_num = F_finite_difference(x, acc, gyro, dt)
    first_order = np.abs(F - np.eye(ERROR_SIZE)).max()
    assert first_order > 0.02  # the comparison below is not trivially satisfied by F = I
    # The model is first order in dt: what it leaves out is O(dt²) (trapezoidal position,
    # rotation within the step), i.e. a small fraction of the O(dt) part it keeps.
    assert np.abs(F_num - F).max() < 0.02 * first_order
    # every non-zero block of the model has the right sign and size
    np.testing.assert_allclose(F[3:6, 6:9], F_num[3:6, 6:9], rtol=0, atol=0.02 * np.abs(F[3:6, 6:9]).max())
    # −C δb_a and −C δb_g: C is taken at the start of the step, so they differ from the
    # mean over the step by about |ω| dt / 2 (relative)
    np.testing.assert_allclose(F[3:6, 9:12], F_num[3:6, 9:12], rtol=0, atol=0.03 * dt)
    np.testing.assert_allclose(F[6:9, 12:15], F_num[6:9, 12:15], rtol=0, atol=0.03 * dt)
    np.testing.assert_allclose(F[0:3, 3:6], F_num[0:3, 3:6], rtol=0, atol=1e-8)


def test_linearisation_residual_is_second_order_in_dt():
    """Halving dt divides the model's residual ‖F_num − F‖ by about 4 (first-order F is exact
    to first order), while F − I halves."""
    rng = np.random.default_rng(3)
    x = random_nominal_state(rng)
    acc, gyro = IMU_CASES[1]
    res, lin = [], []
    for dt in (0.02, 0.01, 0.005):
        _, C, f_n = step(x, acc, gyro, dt)
        F = F_from_propagate(C, f_n, dt)
        res.append(np.abs(F_finite_difference(x, acc, gyro, dt) - F).max())
        lin.append(np.abs(F - np.eye(ERROR_SIZE)).max())
    assert lin[0] / lin[1] == pytest.approx(2.0, rel=0.05)
    assert lin[1] / lin[2] == pytest.approx(2.0, rel=0.05)
    assert 3.0 < res[0] / res[1] < 5.0
    assert 3.0 < res[1] / res[2] < 5.0


def test_propagated_covariance_matches_finite_difference_transition():
    rng = np.random.default_rng(21)
    x = random_nominal_state(rng)
    acc, gyro = IMU_CASES[1]
    dt = 0.005
    _, C, f_n = step(x, acc, gyro, dt)
    P = random_spd(rng, scale=1e-2)
    P_prop = P.copy()
    propagate_covariance(P_prop, C, f_n, dt, np.zeros(ERROR_SIZE))
    F_num = F_finite_difference(x, acc, gyro, dt)
    expected = F_num @ P @ F_num.T
    change = np.abs(expected - P).max()
    assert np.abs(P_prop - expected).max() < 0.05 * change


def test_propagate_covariance_equals_dense_F_P_Ft_plus_Q():
    rng = np.random.default_rng(1)
    C = Rotation.random(random_state=4).as_matrix()
    f_n = np.array([1.5, -3.0, 11.0])
    dt = 0.01
    q = np.abs(rng.normal(0, 1e-2, ERROR_SIZE))
    P = random_spd(rng)
    F = np.eye(ERROR_SIZE) + dense_A(C, f_n) * dt
    expected = F @ P @ F.T + np.diag(q * dt)
    got = P.copy()
    propagate_covariance(got, np.ascontiguousarray(C), f_n, dt, q)
    np.testing.assert_allclose(got, expected, atol=1e-13, rtol=0)


def test_propagate_covariance_with_gauss_markov_biases_equals_dense_F_P_Ft_plus_Q():
    """Bias rows of A are −β on the diagonal (β = 1/τ), the process model carrying β_a, β_g
    after the 15 densities²."""
    rng = np.random.default_rng(5)
    C = Rotation.random(random_state=8).as_matrix()
    f_n = np.array([-0.5, 2.0, 9.0])
    dt, beta_a, beta_g = 0.01, 1 / 100.0, 1 / 30.0
    q = np.concatenate([np.abs(rng.normal(0, 1e-2, ERROR_SIZE)), [beta_a, beta_g]])
    P = random_spd(rng)
    A = dense_A(C, f_n)
    A[9:12, 9:12] = -beta_a * np.eye(3)
    A[12:15, 12:15] = -beta_g * np.eye(3)
    F = np.eye(ERROR_SIZE) + A * dt
    got = P.copy()
    propagate_covariance(got, np.ascontiguousarray(C), f_n, dt, q)
    np.testing.assert_allclose(got, F @ P @ F.T + np.diag(q[:ERROR_SIZE] * dt), atol=1e-13, rtol=0)


def test_an_unobserved_gauss_markov_bias_settles_at_its_stationary_variance():
    """Driving density σ √(2/τ) and decay 1/τ: the bias variance tends to σ² (first-order
    discretisation: σ² / (1 − β dt / 2)), and the estimate decays as e^(−t/τ)."""
    sigma, tau, dt = 6e-5, 100.0, 0.01
    params = filter_params(gyro_bias_walk=sigma * np.sqrt(2.0 / tau), gyro_bias_decay=1.0 / tau)
    q = process_noise_diag(params)
    P = np.zeros((ERROR_SIZE, ERROR_SIZE))
    x = np.zeros(16)
    x[6] = 1.0
    x[13:16] = 1e-3
    C = np.eye(3)
    f_n = np.array([0.0, 0.0, G])
    for _ in range(int(10 * tau / dt)):
        propagate_covariance(P, C, f_n, dt, q)
    decay_biases(x, q, 100.0 * dt)
    np.testing.assert_allclose(np.diag(P)[12:15], sigma**2 / (1 - 0.5 * dt / tau), rtol=1e-3)
    assert np.all(np.diag(P)[9:12] == 0.0)
    np.testing.assert_allclose(x[13:16], 1e-3 * (1 - 1.0 / tau), rtol=1e-12)
    np.testing.assert_array_equal(x[10:13], 0.0)


def test_propagate_covariance_keeps_P_symmetric_psd_over_many_steps():
    rng = np.random.default_rng(2)
    P = random_spd(rng, scale=1e-3)
    q = np.concatenate([np.zeros(3), np.full(3, 0.02**2), np.full(3, 0.002**2), np.full(3, 1e-8),
                        np.full(3, 1e-10)])
    Cs = Rotation.random(2000, random_state=7).as_matrix()
    for k in range(2000):
        C = np.ascontiguousarray(Cs[k])
        f_n = rng.normal(0, 5, 3) + [0, 0, G]
        propagate_covariance(P, C, f_n, 0.01, q)
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0.0
    assert np.all(np.diag(P) > 0)


# --------------------------------------------------------------------------- inject


def test_inject_rotates_attitude_on_the_left_in_the_nav_frame():
    rng = np.random.default_rng(5)
    x = random_nominal_state(rng)
    dx = rng.normal(0, 0.1, ERROR_SIZE)
    dx[6:9] = [0.2, -0.1, 0.3]
    out = x.copy()
    inject(out, dx)
    expected = Rotation.from_rotvec(dx[6:9]) * Rotation.from_quat(x[6:10], scalar_first=True)
    got = Rotation.from_quat(out[6:10], scalar_first=True)
    assert (got * expected.inv()).magnitude() < 1e-14
    np.testing.assert_allclose(out[0:6], x[0:6] + dx[0:6], atol=1e-15)
    np.testing.assert_allclose(out[10:13], x[10:13] + dx[9:12], atol=1e-15)
    np.testing.assert_allclose(out[13:16], x[13:16] + dx[12:15], atol=1e-15)
    assert np.linalg.norm(out[6:10]) == pytest.approx(1.0, abs=1e-15)


def test_inject_small_angle_matches_documented_first_order_dcm():
    """C_true = (I + [δθ×]) C_est to first order."""
    rng = np.random.default_rng(6)
    x = random_nominal_state(rng)
    dth = np.array([1e-5, -2e-5, 3e-5])
    dx = np.zeros(ERROR_SIZE)
    dx[6:9] = dth
    out = x.copy()
    inject(out, dx)
    C0 = Rotation.from_quat(x[6:10], scalar_first=True).as_matrix()
    C1 = Rotation.from_quat(out[6:10], scalar_first=True).as_matrix()
    np.testing.assert_allclose(C1, (np.eye(3) + skew(dth)) @ C0, atol=1e-9)


def test_closed_loop_reset_injects_and_takes_the_symmetric_part_even_in_place():
    """The reset after an outside correction: x as :func:`inject` leaves it, P the symmetric part
    ½ (P* + P*ᵀ) of the covariance handed in (an asymmetric one from a Joseph update in
    floating point), the same when that covariance is the filter's own array."""
    rng = np.random.default_rng(9)
    x = random_nominal_state(rng)
    dx = rng.normal(0, 1e-2, ERROR_SIZE)
    A = rng.normal(size=(ERROR_SIZE, ERROR_SIZE))
    P_new = A @ A.T + 1e-6 * rng.normal(size=(ERROR_SIZE, ERROR_SIZE))
    x_reset, P = x.copy(), np.zeros((ERROR_SIZE, ERROR_SIZE))
    closed_loop_reset(x_reset, P, dx, P_new)
    x_injected = x.copy()
    inject(x_injected, dx)
    np.testing.assert_array_equal(x_reset, x_injected)
    np.testing.assert_array_equal(P, 0.5 * (P_new + P_new.T))
    own = P_new.copy()
    closed_loop_reset(x.copy(), own, dx, own)
    np.testing.assert_array_equal(own, P)


def test_error_between_inverts_inject():
    rng = np.random.default_rng(8)
    x = random_nominal_state(rng)
    dx = rng.normal(0, 1e-3, ERROR_SIZE)
    np.testing.assert_allclose(error_between(perturbed(x, dx), x), dx, atol=1e-14)


# --------------------------------------------------------------------------- updates


def test_inv3_sym_matches_numpy():
    rng = np.random.default_rng(9)
    for _ in range(50):
        A = rng.normal(0, 1, (3, 3))
        S = A @ A.T + 0.01 * np.eye(3)
        np.testing.assert_allclose(inv3_sym(S), np.linalg.inv(S), rtol=1e-9, atol=1e-12)
    S = np.diag([1e-6, 2.0, 3e4])
    np.testing.assert_allclose(inv3_sym(S), np.diag(1 / np.diag(S)), rtol=1e-15)


@pytest.mark.parametrize("first", [0, 3, 6, 9, 12])
def test_update_selected_equals_textbook_joseph_update(first):
    rng = np.random.default_rng(100 + first)
    P = random_spd(rng)
    y = rng.normal(0, 1, 3)
    r_var = 0.3**2
    H = np.zeros((3, ERROR_SIZE))
    H[:, first:first + 3] = np.eye(3)
    R = r_var * np.eye(3)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    IKH = np.eye(ERROR_SIZE) - K @ H
    P_expected = IKH @ P @ IKH.T + K @ R @ K.T
    dx_expected = K @ y
    nis_expected = float(y @ np.linalg.solve(S, y))

    P_got = P.copy()
    dx = np.empty(ERROR_SIZE)
    nis = update_selected(P_got, first, y, r_var, dx, np.empty((0, 0)))
    np.testing.assert_allclose(P_got, P_expected, atol=1e-12, rtol=0)
    np.testing.assert_allclose(dx, dx_expected, atol=1e-12, rtol=0)
    assert nis == pytest.approx(nis_expected, rel=1e-12)
    np.testing.assert_array_equal(P_got, P_got.T)
    assert np.linalg.eigvalsh(P_got).min() > 0


def test_update_selected_joseph_form_stays_psd_with_tiny_measurement_noise():
    rng = np.random.default_rng(11)
    P = random_spd(rng)
    dx = np.empty(ERROR_SIZE)
    for _ in range(200):
        update_selected(P, 3, rng.normal(0, 1e-3, 3), 1e-10, dx, np.empty((0, 0)))
    assert np.linalg.eigvalsh(P).min() > -1e-12
    assert np.abs(P - P.T).max() == 0.0
    assert np.all(np.diag(P)[3:6] < 1e-9)


def test_zupt_drives_velocity_to_zero_and_returns_the_nis():
    rng = np.random.default_rng(12)
    x = random_nominal_state(rng)
    x[3:6] = [0.03, -0.02, 0.01]  # a stance sample's drift, m/s
    P = random_spd(rng, scale=1e-2)
    P[3:6, 3:6] += np.eye(3)
    sigma = 1e-3
    v = x[3:6].copy()
    H = np.zeros((3, ERROR_SIZE))  # δv and the heading column that hides a rotation about Up
    H[:, 3:6] = np.eye(3)
    H[:, 8] = -np.cross([0.0, 0.0, 1.0], v)
    S = H @ P @ H.T + sigma**2 * np.eye(3)
    nis_expected = float(v @ np.linalg.solve(S, v))  # y = 0 − v̂
    P_before = P.copy()
    dx = np.empty(ERROR_SIZE)
    nis = zero_velocity_update(x, P, sigma, 0.0, dx, np.empty((0, 0)), np.empty((15, 15)))
    assert nis == pytest.approx(nis_expected, rel=1e-12)
    # the posterior explains the innovation: what velocity is left is the heading correction's
    # share, H_v dx_v + H_ψ dx_ψ = −v̂
    np.testing.assert_allclose(H @ dx, -v, rtol=1e-5)
    np.testing.assert_allclose(x[3:6], -H[:, 8] * dx[8], atol=1e-5 * np.linalg.norm(v))
    # Joseph update with that H, then the reset G = I + a e_ψᵀ, a = e_z × dv in the velocity rows
    K = P_before @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(ERROR_SIZE) - K @ H
    P_joseph = I_KH @ P_before @ I_KH.T + sigma**2 * K @ K.T
    G = np.eye(ERROR_SIZE)
    G[3:6, 8] = np.cross([0.0, 0.0, 1.0], dx[3:6])
    np.testing.assert_allclose(P, G @ P_joseph @ G.T, rtol=1e-9, atol=1e-15)
    assert np.all(np.diag(H @ P_joseph @ H.T) < sigma**2)
    assert np.linalg.norm(x[6:10]) == pytest.approx(1.0, abs=1e-15)


def test_zaru_pulls_gyro_bias_to_the_stance_rate():
    rng = np.random.default_rng(13)
    x = random_nominal_state(rng)
    P = random_spd(rng, scale=1e-4)
    P[12:15, 12:15] += 1e-2 * np.eye(3)
    gyro = np.array([0.01, -0.02, 0.005])
    dx = np.empty(ERROR_SIZE)
    y = gyro - x[13:16]
    S = P[12:15, 12:15] + 1e-8 * np.eye(3)
    nis_expected = float(y @ np.linalg.solve(S, y))
    nis = zero_angular_rate_update(x, P, gyro, 1e-4, dx, np.empty((0, 0)), np.empty((15, 15)))
    assert nis == pytest.approx(nis_expected, rel=1e-12)
    np.testing.assert_allclose(x[13:16], gyro, atol=1e-5)
