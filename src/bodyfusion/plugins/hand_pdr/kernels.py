"""Compiled per-call steps of the phone's filter: its covariance steps (one hypothesis of the
bank).

The filter's matrices are small (n = 9 or 10 error states, m ≤ 3 measurement rows) and its
transitions and Jacobians mostly zero: compiled, a step costs a few microseconds where the
numpy expression of :mod:`bodyfusion.plugins.hand_pdr.bank_filter` cost tens (one call per
product, a new array each). Zero entries of F and H are skipped, which leaves every sum
unchanged; the sums of the products run in index order, so results agree with the numpy
(BLAS) products to rounding. Two kernels, each of one signature: C-contiguous float64 arrays,
a float gate, ``phi`` (0, 0) when the fuser's transition Φ is not tracked; the product M ← A M
they both make twice is a kernel of its own (inlined at the four sites it cost 0.4–0.8 s more
of a cold start), the smaller helpers are inlined. The temporaries live in the compiled code
(no Python object per call).
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(inline="always")
def _assign(M: np.ndarray, work: np.ndarray) -> None:
    """M ← work element by element (n, n): a slice assignment would compile numba's
    shape-mismatch error message with it, string formatting that cost ~3 s of a cold start."""
    n = M.shape[0]
    for i in range(n):
        for j in range(n):
            M[i, j] = work[i, j]


@numba.njit(cache=True)
def _left_multiply(A: np.ndarray, M: np.ndarray, work: np.ndarray) -> None:
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
    _assign(M, work)


@numba.njit(inline="always")
def _symmetrise(P: np.ndarray) -> None:
    """P ← (P + Pᵀ) / 2 in place."""
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@numba.njit(cache=True)
def transition(P: np.ndarray, F: np.ndarray, Q: np.ndarray, phi: np.ndarray) -> None:
    """Time step of the error covariance in place: P ← (M + Mᵀ) / 2, M = F P Fᵀ + Q (all (n, n));
    and Φ ← F Φ when ``phi`` is (n, n) (the fuser's transition since its last sync)."""
    n = P.shape[0]
    work = np.empty((n, n))
    _left_multiply(F, P, work)  # P ← F P
    for i in range(n):  # work ← (F P) Fᵀ + Q
        for j in range(n):
            s = 0.0
            for k in range(n):
                f = F[j, k]
                if f != 0.0:
                    s += P[i, k] * f
            work[i, j] = s + Q[i, j]
    _assign(P, work)
    _symmetrise(P)
    if phi.shape[0] == n:
        _left_multiply(F, phi, work)


@numba.njit(cache=True)
def kalman_update(P: np.ndarray, H: np.ndarray, R: np.ndarray, y: np.ndarray, gate: float, dx: np.ndarray,
                  phi: np.ndarray) -> tuple[float, float]:
    """Gated Kalman update of the error covariance P (n, n) by innovation y (m,) of a measurement
    with Jacobian H (m, n) and noise covariance R (m, m): S = H P Hᵀ + R (Cholesky S = L Lᵀ),
    returns (NIS yᵀ S⁻¹ y, log det S). Only when NIS ≤ ``gate`` (NaN: not) the update is made:
    K = P Hᵀ S⁻¹, dx ← K y (n,), P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ (Joseph form, symmetrised),
    and Φ ← (I − K H) Φ when ``phi`` is (n, n). An S that is not positive definite gives NaN."""
    m, n = H.shape
    PHt = np.zeros((n, m))
    for a in range(m):
        for k in range(n):
            h = H[a, k]
            if h != 0.0:
                for i in range(n):
                    PHt[i, a] += P[i, k] * h
    L = np.zeros((m, m))  # S, then its Cholesky factor in the lower triangle
    for a in range(m):
        for b in range(a + 1):
            s = 0.0
            for k in range(n):
                h = H[a, k]
                if h != 0.0:
                    s += h * PHt[k, b]
            L[a, b] = s + R[a, b]
    logdet = 0.0
    for a in range(m):
        for b in range(a + 1):
            s = L[a, b]
            for c in range(b):
                s -= L[a, c] * L[b, c]
            if a == b:
                if not s > 0.0:
                    return math.nan, math.nan
                L[a, a] = math.sqrt(s)
                logdet += 2.0 * math.log(L[a, a])
            else:
                L[a, b] = s / L[b, b]
    Sinv = np.zeros((m, m))  # L⁻¹ in the lower triangle, then S⁻¹ = L⁻ᵀ L⁻¹
    for b in range(m):
        Sinv[b, b] = 1.0 / L[b, b]
        for a in range(b + 1, m):
            s = 0.0
            for c in range(b, a):
                s -= L[a, c] * Sinv[c, b]
            Sinv[a, b] = s / L[a, a]
    q = 0.0
    for a in range(m):  # ‖L⁻¹ y‖²
        s = 0.0
        for b in range(a + 1):
            s += Sinv[a, b] * y[b]
        q += s * s
    if not q <= gate:
        return q, logdet
    Linv = Sinv.copy()
    for a in range(m):
        for b in range(a + 1):
            s = 0.0
            for c in range(a, m):
                s += Linv[c, a] * Linv[c, b]
            Sinv[a, b] = s
            Sinv[b, a] = s
    K = np.zeros((n, m))
    for i in range(n):
        for a in range(m):
            s = 0.0
            for b in range(m):
                s += PHt[i, b] * Sinv[b, a]
            K[i, a] = s
    for i in range(n):
        s = 0.0
        for a in range(m):
            s += K[i, a] * y[a]
        dx[i] = s
    A = np.empty((n, n))  # I − K H
    for i in range(n):
        for k in range(n):
            A[i, k] = 1.0 if i == k else 0.0
            for a in range(m):
                A[i, k] -= K[i, a] * H[a, k]
    KR = np.zeros((n, m))
    for i in range(n):
        for b in range(m):
            for a in range(m):
                KR[i, b] += K[i, a] * R[a, b]
    work = np.empty((n, n))
    _left_multiply(A, P, work)  # P ← A P
    for i in range(n):  # work ← (A P) Aᵀ + K R Kᵀ
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += P[i, k] * A[j, k]
            r = 0.0
            for b in range(m):
                r += KR[i, b] * K[j, b]
            work[i, j] = s + r
    _assign(P, work)
    _symmetrise(P)
    if phi.shape[0] == n:
        _left_multiply(A, phi, work)
    return q, logdet
