"""The phone filter's compiled covariance steps against their numpy expressions."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.plugins.hand_pdr.kernels import kalman_update, transition

NOT_TRACKED = np.zeros((0, 0))


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def _close(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


@pytest.mark.parametrize("n", [9, 10])
def test_transition_is_f_p_ft_plus_q_and_chains_phi(n):
    rng = np.random.default_rng(n)
    P, Q, phi = _spd(rng, n), np.diag(rng.uniform(0.0, 1.0, n)), rng.normal(size=(n, n))
    F = np.eye(n)
    F[3, 5], F[5, 5], F[0, 3], F[1, 8], F[4, 4] = -0.01, 0.99, 0.7, 0.3, 0.0
    expected, phi_expected = F @ P @ F.T + Q, F @ phi
    transition(P, F, Q, phi)
    _close(P, 0.5 * (expected + expected.T))
    assert np.array_equal(P, P.T)
    _close(phi, phi_expected)


@pytest.mark.parametrize("rows", [[3], [0, 1, 2]])
def test_kalman_update_is_the_joseph_form(rows):
    n = 10
    rng = np.random.default_rng(len(rows))
    P0 = _spd(rng, n)
    H = np.eye(n)[rows]
    H[0, -1] = -0.4  # a second non-zero entry in a row (the GNSS σ√ρ β, the magnetometer's −δo)
    R = np.diag(rng.uniform(0.1, 1.0, len(rows)))
    y = rng.normal(size=len(rows))
    S = H @ P0 @ H.T + R
    K = P0 @ H.T @ np.linalg.inv(S)
    IKH = np.eye(n) - K @ H
    expected = IKH @ P0 @ IKH.T + K @ R @ K.T
    P, dx, phi = P0.copy(), np.zeros(n), np.eye(n)
    q, logdet = kalman_update(P, H, R, y, np.inf, dx, phi)
    assert q == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-12)
    assert logdet == pytest.approx(np.linalg.slogdet(S)[1], rel=1e-12)
    _close(dx, K @ y)
    _close(P, 0.5 * (expected + expected.T))
    _close(phi, IKH)


def test_kalman_update_beyond_the_gate_changes_nothing():
    n = 9
    rng = np.random.default_rng(3)
    P0 = _spd(rng, n)
    H, R, y = np.eye(n)[[0, 1, 2]], np.eye(3), np.array([50.0, 0.0, 0.0])
    P, dx = P0.copy(), np.zeros(n)
    q, _ = kalman_update(P, H, R, y, 9.0, dx, NOT_TRACKED)
    assert q > 9.0 and np.array_equal(P, P0) and not dx.any()
    q_alone, _ = kalman_update(P, H, R, y, -np.inf, dx, NOT_TRACKED)  # the NIS alone
    assert q_alone == q and np.array_equal(P, P0)


def test_kalman_update_of_an_indefinite_innovation_covariance_is_nan_and_changes_nothing():
    n = 9
    P0 = np.zeros((n, n))
    P, dx = P0.copy(), np.zeros(n)
    q, logdet = kalman_update(P, np.eye(n)[[3]], np.array([[-1.0]]), np.array([0.1]), np.inf, dx, NOT_TRACKED)
    assert np.isnan(q) and np.isnan(logdet) and np.array_equal(P, P0) and not dx.any()
