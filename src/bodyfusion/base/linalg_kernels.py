"""Compiled small dense linear algebra shared by the kernels of several packages."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def cholesky(S: np.ndarray, L: np.ndarray) -> bool:
    """Lower-triangular L with S = L Lᵀ (S's lower triangle is read); False unless S ≻ 0
    (a pivot not positive, or not a number)."""
    n = S.shape[0]
    for j in range(n):
        for i in range(j):
            L[i, j] = 0.0
        s = S[j, j]
        for t in range(j):
            s -= L[j, t] * L[j, t]
        if not s > 0.0:
            return False
        ljj = math.sqrt(s)
        L[j, j] = ljj
        for i in range(j + 1, n):
            acc = S[i, j]
            for t in range(j):
                acc -= L[i, t] * L[j, t]
            L[i, j] = acc / ljj
    return True


@numba.njit(inline="always")
def assign(M: np.ndarray, work: np.ndarray) -> None:
    """M ← work element by element (n, n): a slice assignment would compile numba's
    shape-mismatch error message with it, string formatting that cost ~3 s of a cold start."""
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            M[i, j] = work[i, j]


@numba.njit(cache=True)
def left_multiply(A: np.ndarray, M: np.ndarray, work: np.ndarray) -> None:
    """M ← A M in place (n, n), through ``work`` (n, n); zero entries of A skipped."""
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            work[i, j] = 0.0
        for k in range(n):
            a = A[i, k]
            if a != 0.0:
                for j in range(n):
                    work[i, j] += a * M[k, j]
    assign(M, work)


@numba.njit(inline="always")
def symmetrise(P: np.ndarray) -> None:
    """P ← (P + Pᵀ) / 2 in place."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v
