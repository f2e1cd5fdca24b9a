"""Compiled pieces of the foot INS smoothers: the solve of the RTS gain (bodyfusion.plugins.foot_ins.smoothing_rts)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from bodyfusion.plugins.foot_ins.smoothing_rts import chol_solve


def _textbook_chol_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray | None:
    """The Jacobi-scaled Cholesky solve as the textbook row-by-row loops write it (Python
    floats: IEEE double, no fused multiply-add), with chol_solve's jitter retries."""
    n, m = B.shape
    if not all(A[r, r] > 0.0 for r in range(n)):
        return None
    d = [1.0 / math.sqrt(A[r, r]) for r in range(n)]
    for attempt in range(3):
        jitter = 0.0 if attempt == 0 else 1e-12 * (10.0 ** (4 * attempt))
        L = [[0.0] * n for _ in range(n)]
        ok = True
        for r in range(n):
            for c in range(r + 1):
                s = float(A[r, c]) * d[r] * d[c]
                if r == c:
                    s += jitter
                for k in range(c):
                    s -= L[r][k] * L[c][k]
                if r == c:
                    if s <= 0.0:
                        ok = False
                        break
                    L[r][r] = math.sqrt(s)
                else:
                    L[r][c] = s / L[c][c]
            if not ok:
                break
        if not ok:
            continue
        X = [[float(B[r, col]) * d[r] for col in range(m)] for r in range(n)]
        for col in range(m):
            for r in range(n):
                for k in range(r):
                    X[r][col] -= L[r][k] * X[k][col]
                X[r][col] /= L[r][r]
            for r in range(n - 1, -1, -1):
                for k in range(r + 1, n):
                    X[r][col] -= L[k][r] * X[k][col]
                X[r][col] /= L[r][r]
        return np.array([[X[r][col] * d[r] for col in range(m)] for r in range(n)])
    return None


def _spd(rng: np.random.Generator, n: int, decades: float) -> np.ndarray:
    """A symmetric positive-definite n × n matrix whose diagonal spans ``decades`` decades."""
    G = rng.standard_normal((n, n))
    A = G @ G.T + 0.1 * np.eye(n)
    s = np.logspace(-decades / 2, decades / 2, n)
    A = A * np.outer(s, s)
    return 0.5 * (A + A.T)


@pytest.mark.parametrize("n,m", [(15, 15), (15, 16), (11, 1), (11, 4), (11, 16), (6, 7)])
def test_cholesky_solve_is_the_textbook_loops_bit_for_bit(n, m):
    """The compiled solve keeps every element's operations in the textbook loops' order: the
    same bits (a rearrangement for speed must keep them)."""
    rng = np.random.default_rng(n * 100 + m)
    for _ in range(5):
        A, B = _spd(rng, n, 8.0), rng.standard_normal((n, m))
        X, Lw = np.empty((n, m)), np.empty((n, n + 1))
        assert chol_solve(A, B, X, Lw)
        assert np.array_equal(X, _textbook_chol_solve(A, B))
        np.testing.assert_allclose(A @ X, B, rtol=0, atol=1e-6 * np.abs(B).max())


def test_cholesky_solve_retries_a_singular_matrix_with_jitter_and_refuses_an_indefinite_one():
    rng = np.random.default_rng(7)
    B = rng.standard_normal((15, 3))
    X, Lw = np.empty((15, 3)), np.empty((15, 16))
    singular = np.eye(15)
    singular[3, 4] = singular[4, 3] = 1.0  # rows 3 and 4 equal: the pivot at 4 is exactly zero
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(singular)
    assert chol_solve(singular, B, X, Lw)  # with the jitter of the retry
    assert np.array_equal(X, _textbook_chol_solve(singular, B))
    indefinite = np.eye(15)
    indefinite[0, 14] = indefinite[14, 0] = 2.0
    assert _textbook_chol_solve(indefinite, B) is None
    assert not chol_solve(indefinite, B, X, Lw)
