"""The Kalman measurement update of every filter in the project: gated, Joseph form, with its
normalised innovation squared (NIS) and verdict.

For an error state of covariance P (n, n), a measurement of Jacobian H (m, n), noise covariance
R (m, m) and innovation y = z − h(x̂) (m,):

    S = H P Hᵀ + R,   NIS = yᵀ S⁻¹ y,   K = P Hᵀ S⁻¹,   δx = K y,
    P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ   (Joseph form: P stays a covariance for any gain),

made only when the NIS is within the chi-square ``gate`` (a consistent innovation of m
dimensions stays below :func:`~bodyfusion.nav.measurements.chi2_gate` with its probability); a
transition Φ the fuser accumulates is left-multiplied by (I − K H).

- :func:`kalman_update`: any H, R (compiled; the phone's filter, its bank of heading hypotheses).
- :func:`gated_update`: the same on a copy, for code that is not compiled (the fuser's aiding
  ranges and heading ties) — a :class:`KalmanUpdate` with the NIS, the verdict, δx and P*.
- :func:`selection_update`, :func:`update_selected`: the same update where H selects three
  consecutive states and adds a column on the heading error (a zero-velocity update, a position
  fix of the 15-state filter): its rank-3 form, S = H P Hᵀ + r I, written with M = P Hᵀ as
  P − K Mᵀ − M Kᵀ + K S Kᵀ, the foot filter's hot path. It equals :func:`kalman_update` to
  rounding (``tests/nav/test_kalman.py``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from bodyfusion.base.linalg_kernels import assign, left_multiply, symmetrise


class KalmanUpdate(NamedTuple):
    """A gated update's outcome: ``nis`` (yᵀ S⁻¹ y; NaN when S is not positive definite),
    ``accepted`` (within the gate), and, when accepted, the correction ``dx`` (n,) and the
    covariance ``P`` (n, n) after it (None otherwise)."""

    nis: float
    accepted: bool
    dx: np.ndarray | None
    P: np.ndarray | None


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
    left_multiply(A, P, work)  # P ← A P
    for i in range(n):  # work ← (A P) Aᵀ + K R Kᵀ
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += P[i, k] * A[j, k]
            r = 0.0
            for b in range(m):
                r += KR[i, b] * K[j, b]
            work[i, j] = s + r
    assign(P, work)
    symmetrise(P)
    if phi.shape[0] == n:
        left_multiply(A, phi, work)
    return q, logdet


@numba.njit(cache=True)
def correlated_update(P: np.ndarray, H: np.ndarray, R: np.ndarray, theta: np.ndarray, y: np.ndarray, gate: float,
                      dx: np.ndarray, phi: np.ndarray) -> float:
    """Gated Kalman update of P (n, n) by a 3-dimensional measurement whose noise (covariance R
    (3, 3)) is correlated with the process noise of the step before it, θ = E[w vᵀ] (n, 3): the
    form of :func:`kalman_update` for correlated noise (Simon, Optimal State Estimation, §7.1;
    FilterPy's ``update_correlated``), which the coloured-noise ZUPT needs
    (:mod:`bodyfusion.plugins.foot_ins.coloured`, [Xu2024] eqs. 11–14):

        S = H P Hᵀ + R + H θ + θᵀ Hᵀ,   K = (P Hᵀ + θ) S⁻¹,   dx = K y,
        P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ − (I − K H) θ Kᵀ − K θᵀ (I − K H)ᵀ  (symmetrised),

    Φ ← (I − K H) Φ when ``phi`` is (n, n). Returns the NIS yᵀ S⁻¹ y; with ``gate`` > 0 and
    NIS > gate nothing is changed. With θ = 0 it is :func:`kalman_update`'s update."""
    n = P.shape[0]
    # G = P Hᵀ + θ (n, 3); S = H G + R + θᵀ Hᵀ
    G = np.empty((n, 3))
    for r in range(n):
        for c in range(3):
            s = theta[r, c]
            for k in range(n):
                s += P[r, k] * H[c, k]
            G[r, c] = s
    S = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            s = R[r, c]
            for k in range(n):
                s += H[r, k] * G[k, c] + theta[k, r] * H[c, k]
            S[r, c] = s
    for r in range(3):
        for c in range(r + 1, 3):
            m = 0.5 * (S[r, c] + S[c, r])
            S[r, c] = m
            S[c, r] = m
    Si = inv3_sym(S)
    nis = 0.0
    for r in range(3):
        for c in range(3):
            nis += y[r] * Si[r, c] * y[c]
    if gate > 0.0 and nis > gate:
        return nis
    K = np.empty((n, 3))
    for r in range(n):
        for c in range(3):
            K[r, c] = G[r, 0] * Si[0, c] + G[r, 1] * Si[1, c] + G[r, 2] * Si[2, c]
    for r in range(n):
        dx[r] = K[r, 0] * y[0] + K[r, 1] * y[1] + K[r, 2] * y[2]
    # E = I − K H
    E = np.empty((n, n))
    for r in range(n):
        for c in range(n):
            E[r, c] = (1.0 if r == c else 0.0) - (K[r, 0] * H[0, c] + K[r, 1] * H[1, c] + K[r, 2] * H[2, c])
    if phi.shape[0] > 0:
        old = phi.copy()
        for r in range(n):
            for c in range(n):
                s = 0.0
                for k in range(n):
                    s += E[r, k] * old[k, c]
                phi[r, c] = s
    # P⁺ = W Eᵀ − (E θ − K R) Kᵀ with W = E P − K θᵀ
    W = np.empty((n, n))
    for r in range(n):
        for c in range(n):
            s = -(K[r, 0] * theta[c, 0] + K[r, 1] * theta[c, 1] + K[r, 2] * theta[c, 2])
            for k in range(n):
                s += E[r, k] * P[k, c]
            W[r, c] = s
    V = np.empty((n, 3))
    for r in range(n):
        for c in range(3):
            s = -(K[r, 0] * R[0, c] + K[r, 1] * R[1, c] + K[r, 2] * R[2, c])
            for k in range(n):
                s += E[r, k] * theta[k, c]
            V[r, c] = s
    for r in range(n):
        for c in range(r, n):
            s1 = 0.0
            for k in range(n):
                s1 += W[r, k] * E[c, k]
            s2 = 0.0
            for k in range(n):
                s2 += W[c, k] * E[r, k]
            a = s1 - (V[r, 0] * K[c, 0] + V[r, 1] * K[c, 1] + V[r, 2] * K[c, 2])
            b = s2 - (V[c, 0] * K[r, 0] + V[c, 1] * K[r, 1] + V[c, 2] * K[r, 2])
            v = 0.5 * (a + b)
            P[r, c] = v
            P[c, r] = v
    return nis


@numba.njit(cache=True)
def inverse3(s00: float, s01: float, s02: float, s11: float, s12: float,
             s22: float) -> tuple[float, float, float, float, float, float]:
    """The upper triangle (i00, i01, i02, i11, i12, i22) of the inverse of the symmetric
    positive-definite 3×3 matrix of upper triangle (s00, s01, s02, s11, s12, s22), by
    cofactors: S⁻¹ = adj(S) / det S."""
    A = s11 * s22 - s12 * s12
    B = s02 * s12 - s01 * s22
    C = s01 * s12 - s02 * s11
    det = s00 * A + s01 * B + s02 * C
    return A / det, B / det, C / det, (s00 * s22 - s02 * s02) / det, (s01 * s02 - s00 * s12) / det, \
        (s00 * s11 - s01 * s01) / det


@numba.njit(cache=True)
def inv3_sym_into(S: np.ndarray, out: np.ndarray) -> None:
    """``out`` (3, 3) ← the inverse of the symmetric positive-definite 3×3 matrix S (cofactors,
    :func:`inverse3`); ``out`` may be S."""
    i00, i01, i02, i11, i12, i22 = inverse3(S[0, 0], S[0, 1], S[0, 2], S[1, 1], S[1, 2], S[2, 2])
    out[0, 0], out[0, 1], out[0, 2] = i00, i01, i02
    out[1, 0], out[1, 1], out[1, 2] = i01, i11, i12
    out[2, 0], out[2, 1], out[2, 2] = i02, i12, i22


@numba.njit(cache=True)
def inv3_sym(S: np.ndarray) -> np.ndarray:
    """Inverse (3, 3) of a symmetric positive-definite 3×3 matrix, in a new array
    (:func:`inv3_sym_into` fills one)."""
    out = np.empty((3, 3))
    inv3_sym_into(S, out)
    return out


@numba.njit(cache=True)
def nis3(S: tuple[float, float, float, float, float, float], r_var: float, y: tuple[float, float, float]) -> float:
    """Normalised innovation squared yᵀ (S + r_var I)⁻¹ y of a 3-D innovation y with
    H P Hᵀ = S (its upper triangle (s00, s01, s02, s11, s12, s22)) and isotropic noise variance
    r_var (unit of y squared): the chi-square statistic of 3 degrees of freedom. The sum runs
    over the 9 terms y_r (S⁻¹)_rc y_c, row by row."""
    i00, i01, i02, i11, i12, i22 = inverse3(S[0] + r_var, S[1], S[2], S[3] + r_var, S[4], S[5] + r_var)
    y0, y1, y2 = y
    out = 0.0
    out += y0 * i00 * y0
    out += y0 * i01 * y1
    out += y0 * i02 * y2
    out += y1 * i01 * y0
    out += y1 * i11 * y1
    out += y1 * i12 * y2
    out += y2 * i02 * y0
    out += y2 * i12 * y1
    out += y2 * i22 * y2
    return out


@numba.njit(cache=True)
def selection_moments(P: np.ndarray, first: int, h: tuple[float, float, float],
                      work: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """The prior moments of a 3-D measurement δz = H δx whose Jacobian H (3, 15) selects the
    states first:first+3 (identity) and has the column h (3,) on the heading δψ (state 8;
    zeros: none; first:first+3 must not hold state 8 unless h is zero): M = P Hᵀ (15, 3),
    M[r] = P[r, first:first+3] + P[r, 8] h, written transposed to ``work[0:3]`` (``work``
    (15, 15) scratch; rows, so that the update's loops over the states read it contiguously),
    and the upper triangle of H P Hᵀ = H M, (H M)[r] = M[first + r] + h_r M[8]."""
    h0, h1, h2 = h
    for r in range(15):
        p8 = P[r, 8]
        work[0, r] = P[r, first] + p8 * h0
        work[1, r] = P[r, first + 1] + p8 * h1
        work[2, r] = P[r, first + 2] + p8 * h2
    a, b = first, first + 1
    c = first + 2
    return (work[0, a] + h0 * work[0, 8], work[1, a] + h0 * work[1, 8], work[2, a] + h0 * work[2, 8],
            work[1, b] + h1 * work[1, 8], work[2, b] + h1 * work[2, 8], work[2, c] + h2 * work[2, 8])


@numba.njit(cache=True)
def selection_update(P: np.ndarray, first: int, h: tuple[float, float, float],
                     S: tuple[float, float, float, float, float, float], r_var: float, y: tuple[float, float, float],
                     dx: np.ndarray, phi: np.ndarray, work: np.ndarray) -> float:
    """Kalman update of the measurement of :func:`selection_moments` (which wrote Mᵀ = H P to
    ``work[0:3]`` and returned H P Hᵀ = ``S``), innovation y (3,), isotropic noise variance
    r_var. Joseph form, P (15, 15) in place, written with M and S = H M + R:
    (I − K H) P (I − K H)ᵀ + K R Kᵀ = P − K Mᵀ − M Kᵀ + K S Kᵀ, K = M S⁻¹ (15, 3): rank-3
    terms, Kᵀ and (K S)ᵀ kept in ``work[3:6]``, ``work[6:9]``; the upper triangle, then
    mirrored. Writes dx = K y (15,) and returns the normalised innovation squared yᵀ S⁻¹ y.

    ``phi`` (15, 15), the error-state transition accumulated since the fuser's last sync,
    is left-multiplied by (I − K H) in place (H phi kept in ``work[9:12]``); pass an empty
    (0, 0) array when the fuser does not track cross-covariances."""
    s00, s01, s02 = S[0] + r_var, S[1], S[2]
    s11, s12, s22 = S[3] + r_var, S[4], S[5] + r_var
    i00, i01, i02, i11, i12, i22 = inverse3(s00, s01, s02, s11, s12, s22)
    y0, y1, y2 = y
    for r in range(15):
        m0, m1, m2 = work[0, r], work[1, r], work[2, r]
        k0 = m0 * i00 + m1 * i01 + m2 * i02
        k1 = m0 * i01 + m1 * i11 + m2 * i12
        k2 = m0 * i02 + m1 * i12 + m2 * i22
        work[3, r] = k0
        work[4, r] = k1
        work[5, r] = k2
        work[6, r] = k0 * s00 + k1 * s01 + k2 * s02
        work[7, r] = k0 * s01 + k1 * s11 + k2 * s12
        work[8, r] = k0 * s02 + k1 * s12 + k2 * s22
        dx[r] = k0 * y0 + k1 * y1 + k2 * y2
    if phi.shape[0] > 0:
        h0, h1, h2 = h
        for c in range(15):
            p8 = phi[8, c]
            work[9, c] = phi[first, c] + h0 * p8
            work[10, c] = phi[first + 1, c] + h1 * p8
            work[11, c] = phi[first + 2, c] + h2 * p8
        for r in range(15):
            k0, k1, k2 = work[3, r], work[4, r], work[5, r]
            for c in range(15):
                phi[r, c] -= k0 * work[9, c] + k1 * work[10, c] + k2 * work[11, c]
    for r in range(15):
        m0, m1, m2 = work[0, r], work[1, r], work[2, r]
        k0, k1, k2 = work[3, r], work[4, r], work[5, r]
        e0, e1, e2 = work[6, r], work[7, r], work[8, r]
        for c in range(r, 15):
            v = P[r, c]
            v += e0 * work[3, c] - k0 * work[0, c] - m0 * work[3, c]
            v += e1 * work[4, c] - k1 * work[1, c] - m1 * work[4, c]
            v += e2 * work[5, c] - k2 * work[2, c] - m2 * work[5, c]
            P[r, c] = v
    for r in range(15):
        for c in range(r + 1, 15):
            P[c, r] = P[r, c]
    return nis3(S, r_var, y)


@numba.njit(cache=True)
def nis_selected(P: np.ndarray, first: int, y: np.ndarray, r_var: float) -> float:
    """Normalised innovation squared yᵀ S⁻¹ y of a 3-D measurement selecting states
    first:first+3, S = P_sel + r_var I (the chi-square test statistic, 3 degrees of freedom)."""
    S = selection_moments(P, first, (0.0, 0.0, 0.0), np.empty((15, 15)))
    return nis3(S, r_var, (y[0], y[1], y[2]))


@numba.njit(cache=True)
def update_selected(P: np.ndarray, first: int, y: np.ndarray, r_var: float, dx: np.ndarray,
                    phi: np.ndarray) -> float:
    """:func:`selection_update` of a 3-D measurement that selects states first:first+3
    (H = [0 I 0]), innovation y (3,), with its own scratch."""
    work = np.empty((15, 15))
    h = (0.0, 0.0, 0.0)
    S = selection_moments(P, first, h, work)
    return selection_update(P, first, h, S, r_var, (y[0], y[1], y[2]), dx, phi, work)


NOT_TRACKED = np.empty((0, 0))
"""The ``phi`` to pass when no transition is accumulated."""


def gated_update(P: np.ndarray, H: np.ndarray, R: np.ndarray, y: np.ndarray, gate: float) -> KalmanUpdate:
    """:func:`kalman_update` of a copy of P (n, n) by H (m, n) or (n,) for a scalar, R (m, m) or a
    scalar variance, y (m,) or a scalar: P itself is left as it is."""
    H2 = np.atleast_2d(np.asarray(H, dtype=float))
    R2 = np.atleast_2d(np.asarray(R, dtype=float))
    y1 = np.atleast_1d(np.asarray(y, dtype=float))
    P_new = np.array(P, dtype=float)
    dx = np.zeros(P_new.shape[0])
    nis, _ = kalman_update(P_new, np.ascontiguousarray(H2), np.ascontiguousarray(R2), y1, float(gate), dx, NOT_TRACKED)
    accepted = bool(nis <= gate)
    return KalmanUpdate(float(nis), accepted, dx if accepted else None, P_new if accepted else None)
