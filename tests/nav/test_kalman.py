"""The one Kalman measurement update: the Joseph form, its gate and NIS, its selection form, its
form for noise correlated with the process noise (the coloured-noise ZUPT)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bodyfusion.nav.kalman import (NOT_TRACKED, correlated_update, gated_update, kalman_update, selection_moments,
                                   selection_update, update_selected)


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + 0.1 * np.eye(n)


def _close(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


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


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), first=st.sampled_from([0, 3]), scale=st.floats(1e-6, 1e3),
       with_heading=st.booleans())
def test_the_selection_form_is_the_general_update_to_rounding(seed, first, scale, with_heading):
    """H = [0 I h 0] over states first:first+3 with a heading column h (a ZUPT), or without (a
    position fix), isotropic noise: the rank-3 form and the general kernel agree."""
    rng = np.random.default_rng(seed)
    P0 = _spd(rng, 15) * scale
    h = tuple(rng.normal(size=3) * (1.0 if with_heading else 0.0))
    H = np.zeros((3, 15))
    H[:, first:first + 3] = np.eye(3)
    H[:, 8] += h
    r_var = float(rng.uniform(0.01, 1.0)) * scale
    y = rng.normal(size=3) * np.sqrt(scale)
    general, dx_general, phi_general = P0.copy(), np.zeros(15), np.eye(15)
    nis_general, _ = kalman_update(general, H, r_var * np.eye(3), y, np.inf, dx_general, phi_general)
    work = np.empty((15, 15))
    selected, dx_selected, phi_selected = P0.copy(), np.zeros(15), np.eye(15)
    S = selection_moments(selected, first, h, work)
    nis_selected = selection_update(selected, first, h, S, r_var, tuple(y), dx_selected, phi_selected, work)
    assert nis_selected == pytest.approx(nis_general, rel=1e-9)
    np.testing.assert_allclose(selected, general, rtol=1e-9, atol=1e-9 * np.abs(P0).max())
    np.testing.assert_allclose(dx_selected, dx_general, rtol=1e-9, atol=1e-9 * np.abs(dx_general).max())
    np.testing.assert_allclose(phi_selected, phi_general, rtol=1e-9, atol=1e-9)
    if not with_heading:
        plain, dx_plain = P0.copy(), np.zeros(15)
        update_selected(plain, first, y, r_var, dx_plain, NOT_TRACKED)
        np.testing.assert_allclose(plain, general, rtol=1e-9, atol=1e-9 * np.abs(P0).max())


def test_a_gated_update_leaves_its_input_alone_and_says_its_verdict():
    rng = np.random.default_rng(5)
    P0 = _spd(rng, 6)
    H = np.zeros(6)
    H[2] = 1.0
    within = gated_update(P0, H, 0.5, 0.1, gate=6.63)
    assert within.accepted and within.nis == pytest.approx(0.01 / (P0[2, 2] + 0.5))
    assert np.array_equal(P0, P0.T) and within.P is not None and within.dx is not None
    K = P0[:, 2] / (P0[2, 2] + 0.5)
    _close(within.dx, K * 0.1)
    beyond = gated_update(P0, H, 0.5, 100.0, gate=6.63)
    assert not beyond.accepted and beyond.nis > 6.63 and beyond.dx is None and beyond.P is None
    indefinite = gated_update(np.zeros((6, 6)), H, -1.0, 0.1, gate=np.inf)
    assert np.isnan(indefinite.nis) and not indefinite.accepted


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), correlated=st.booleans())
def test_the_correlated_form_is_the_textbook_update_and_the_general_one_without_correlation(seed, correlated):
    """With θ = E[w vᵀ] the gain is (P Hᵀ + θ) S⁻¹, S = H P Hᵀ + R + H θ + θᵀ Hᵀ, and P⁺ the
    Joseph form with the θ terms (Simon 2006, §7.1); with θ = 0 it is :func:`kalman_update`'s."""
    n = 15
    rng = np.random.default_rng(seed)
    P0 = _spd(rng, n)
    H = rng.normal(size=(3, n))
    R = _spd(rng, 3)
    theta = 0.1 * rng.normal(size=(n, 3)) if correlated else np.zeros((n, 3))
    y = rng.normal(size=3)
    S = H @ P0 @ H.T + R + H @ theta + theta.T @ H.T
    K = (P0 @ H.T + theta) @ np.linalg.inv(S)
    E = np.eye(n) - K @ H
    expected = E @ P0 @ E.T + K @ R @ K.T - E @ theta @ K.T - K @ theta.T @ E.T
    P, dx, phi = P0.copy(), np.zeros(n), np.eye(n)
    nis = correlated_update(P, H, R, theta, y, 0.0, dx, phi)
    assert nis == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-9)
    np.testing.assert_allclose(dx, K @ y, rtol=1e-9, atol=1e-9 * np.abs(K @ y).max())
    np.testing.assert_allclose(P, 0.5 * (expected + expected.T), rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(phi, E, rtol=1e-9, atol=1e-9)
    if not correlated:
        P_general, dx_general = P0.copy(), np.zeros(n)
        kalman_update(P_general, H, R, y, np.inf, dx_general, np.empty((0, 0)))
        np.testing.assert_allclose(P, P_general, rtol=1e-9, atol=1e-9 * np.abs(P_general).max())
        np.testing.assert_allclose(dx, dx_general, rtol=1e-9, atol=1e-12)
