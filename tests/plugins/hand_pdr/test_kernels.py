"""The phone filter's compiled covariance time step against its numpy expression."""

from __future__ import annotations

import numpy as np
import pytest

from bodyfusion.plugins.hand_pdr.kernels import transition

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
