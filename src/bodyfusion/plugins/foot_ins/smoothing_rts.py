"""The Rauch–Tung–Striebel backward sweep over a replayed block ([Shen2025] §3.2), in its
textbook form (the whole-run RTS sweeps in the Bryson–Frazier form:
:mod:`bodyfusion.plugins.foot_ins.smoothing_mbf`), and the smoothed states it gives."""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.nav.error_state import congruence_by_yaw_reset, inject
from bodyfusion.plugins.foot_ins.records import PassBuffers

AFTER_POSITION = 3
"""The first error state after position (δv), where the backward pass's RTS starts
(:func:`rts_block_after_position`: nothing depends on or measures position in that pass)."""


@numba.njit(cache=True)
def chol_solve(A: np.ndarray, B: np.ndarray, X: np.ndarray, Lw: np.ndarray) -> bool:
    """Solve A X = B for symmetric positive-definite A (n×n, top-left block used) and
    B (n×m, its shape gives n and m; X the same), Jacobi-scaled (A's diagonal may span many
    decades: diffuse and pinned states) before the Cholesky factorisation. ``Lw`` (n, n + 1) is
    scratch: the factor in its first n columns, the scaling in its last (no allocation per
    call). A tiny diagonal jitter is added when the factorisation meets a non-positive
    pivot; returns False if it still fails. (Sizes from the shapes, not arguments: integer
    constants at the call sites would each compile a signature of their own.)"""
    n, m = B.shape
    d = Lw[:, n]
    for r in range(n):
        if not A[r, r] > 0.0:
            return False
        d[r] = 1.0 / math.sqrt(A[r, r])
    for attempt in range(3):
        jitter = 0.0 if attempt == 0 else 1e-12 * (10.0 ** (4 * attempt))
        ok = True
        for r in range(n):
            for c in range(r + 1):
                s = A[r, c] * d[r] * d[c]
                if r == c:
                    s += jitter
                for k in range(c):
                    s -= Lw[r, k] * Lw[c, k]
                if r == c:
                    if s <= 0.0:
                        ok = False
                        break
                    Lw[r, r] = math.sqrt(s)
                else:
                    Lw[r, c] = s / Lw[c, c]
            if not ok:
                break
        if ok:
            # L Y = D B, then Lᵀ Z = Y, X = D Z, a row of all m columns at a time: every element
            # takes the same operations in the same order as one column at a time (vectorised)
            for r in range(n):
                for col in range(m):
                    X[r, col] = B[r, col] * d[r]
                for k in range(r):
                    lrk = Lw[r, k]
                    for col in range(m):
                        X[r, col] -= lrk * X[k, col]
                for col in range(m):
                    X[r, col] /= Lw[r, r]
            for r in range(n - 1, -1, -1):
                for k in range(r + 1, n):
                    lkr = Lw[k, r]
                    for col in range(m):
                        X[r, col] -= lkr * X[k, col]
                for col in range(m):
                    X[r, col] /= Lw[r, r]
            for r in range(n):
                for col in range(m):
                    X[r, col] *= d[r]
            return True
    return False


@numba.njit(inline="always")
def _rts_sweep(buffers: PassBuffers, L: int, dx_end: np.ndarray, P_end: np.ndarray, first: int, dxs: np.ndarray,
               Ps: np.ndarray) -> int:
    """Rauch–Tung–Striebel backward sweep over a block of a closed-loop error-state filter
    ([Shen2025] §3.2), of the error states ``first`` … 14 (0: all; :data:`AFTER_POSITION`: all
    but position, which no other state, stance update or heading reset depends on: where nothing
    measures position either, as in the backward pass, the sweep of the others is the whole
    model's on them, to rounding).

    The filter's own error estimates are zero after every injection, so with dxs[j] the
    smoothed error relative to the posterior nominal at j:

        K_j = P⁺_j Φ_{j+1}ᵀ (P⁻_{j+1})⁻¹
        dxs_j = K_j (dxs_{j+1} + dx_{j+1})          (dx_{j+1}: correction injected at j+1)
        Ps_j = P⁺_j + K_j (Ps_{j+1} − P⁻_{j+1}) K_jᵀ

    starting from dxs_L = dx_end, Ps_L = P_end (zeros and P⁺_L for a block smoothed on
    its own). A stance update's heading reset G_{j+1} = I + a e_ψᵀ (``yaw_reset``, see
    :func:`filter_pass`) changed the coordinates of the error after it: dxs_{j+1} and
    Ps_{j+1} are taken back to the update's by G⁻¹ = I − a e_ψᵀ (e_ψᵀ a = 0) before the
    step. Of the states before ``first``, dxs is zero and Ps left unwritten below L. Returns
    the number of steps whose gain could not be formed (then dxs_j = 0, Ps_j = P⁺_j)."""
    _, _, Ppost, Pprior, Phi, dx, _, yaw_reset = buffers
    n = 15 - first
    A = np.empty((n, n))
    M = np.empty((n, n))
    Kt = np.empty((n, n))
    Lw = np.empty((n, n + 1))
    KD = np.empty((n, n))
    D = np.zeros((15, 15))  # the states before first stay zero: the heading reset leaves them so
    e = np.empty(15)
    failed = 0
    for k in range(15):
        dxs[L, k] = dx_end[k]
        for c in range(15):
            Ps[L, k, c] = P_end[k, c]
    # Every product below runs a row at a time over contiguous columns (vectorised); each element
    # still sums its terms in the index order of the textbook loop, so the result is that loop's.
    for j in range(L - 1, -1, -1):
        for r in range(15):  # the states before first stay zero, and all where the gain fails
            dxs[j, r] = 0.0
        # M = Φ_{j+1} P⁺_j over the non-zero entries of Φ (block-sparse: a zero term adds nothing;
        # no state after first depends on one before it); P⁻ Kᵀ = M
        for r in range(n):
            for c in range(n):
                M[r, c] = 0.0
            for k in range(first, 15):
                f = Phi[j + 1, first + r, k]
                if f != 0.0:
                    for c in range(n):
                        M[r, c] += f * Ppost[j, k, first + c]
        if first > 0:  # the block of the states swept, contiguous (all of them: the prior itself)
            for r in range(n):
                for c in range(n):
                    A[r, c] = Pprior[j + 1, first + r, first + c]
        if not chol_solve(Pprior[j + 1] if first == 0 else A, M, Kt, Lw):
            failed += 1
            for r in range(first, 15):
                for c in range(first, 15):
                    Ps[j, r, c] = Ppost[j, r, c]
            continue
        a0, a1 = yaw_reset[j + 1, 0], yaw_reset[j + 1, 1]
        for r in range(first, 15):
            for c in range(first, 15):
                D[r, c] = Ps[j + 1, r, c]
        if a0 != 0.0 or a1 != 0.0:  # G⁻¹ Ps G⁻ᵀ
            congruence_by_yaw_reset(D, -a0, -a1)
        for k in range(first, 15):
            e[k] = dxs[j + 1, k] + dx[j + 1, k]
        e[3] -= a0 * dxs[j + 1, 8]
        e[4] -= a1 * dxs[j + 1, 8]
        for k in range(n):
            ek = e[first + k]
            for r in range(n):
                dxs[j, first + r] += Kt[k, r] * ek
        for r in range(first, 15):
            for c in range(first, 15):
                D[r, c] -= Pprior[j + 1, r, c]
        # KD = K D, then Ps = P⁺ + (K D) Kᵀ (upper triangle mirrored): three columns at a time in
        # registers (n is 15 or 12)
        for r in range(n):
            for c0 in range(0, n, 3):
                s0 = s1 = s2 = 0.0
                for k in range(n):
                    kr = Kt[k, r]
                    s0 += kr * D[first + k, first + c0]
                    s1 += kr * D[first + k, first + c0 + 1]
                    s2 += kr * D[first + k, first + c0 + 2]
                KD[r, c0], KD[r, c0 + 1], KD[r, c0 + 2] = s0, s1, s2
        for r in range(n):
            for c0 in range(3 * (r // 3), n, 3):
                s0 = s1 = s2 = 0.0
                for k in range(n):
                    kdr = KD[r, k]
                    s0 += kdr * Kt[k, c0]
                    s1 += kdr * Kt[k, c0 + 1]
                    s2 += kdr * Kt[k, c0 + 2]
                M[r, c0], M[r, c0 + 1], M[r, c0 + 2] = s0, s1, s2
            for c in range(r, n):
                v = Ppost[j, first + r, first + c] + M[r, c]
                Ps[j, first + r, first + c] = v
                Ps[j, first + c, first + r] = v
    return failed


@numba.njit(cache=True)
def rts_block(buffers: PassBuffers, L: int, dx_end: np.ndarray, P_end: np.ndarray, dxs: np.ndarray,
              Ps: np.ndarray) -> int:
    """:func:`_rts_sweep` of all the error states."""
    return _rts_sweep(buffers, L, dx_end, P_end, 0, dxs, Ps)


@numba.njit(cache=True)
def rts_block_after_position(buffers: PassBuffers, L: int, dx_end: np.ndarray, P_end: np.ndarray, dxs: np.ndarray,
                             Ps: np.ndarray) -> int:
    """:func:`_rts_sweep` of the error states from :data:`AFTER_POSITION` (a kernel of its own:
    the sizes constant in each, 12³ products instead of 15³)."""
    return _rts_sweep(buffers, L, dx_end, P_end, AFTER_POSITION, dxs, Ps)


@numba.njit(cache=True)
def apply_smoothed(x: np.ndarray, a: int, L: int, dxs: np.ndarray, out_x: np.ndarray, out_a: int) -> None:
    """out_x[out_a + j] = x[a + j] ⊞ dxs[j], 0 ≤ j ≤ L."""
    y = np.empty(16)
    d = np.empty(15)
    for j in range(L + 1):
        for k in range(16):
            y[k] = x[a + j, k]
        for k in range(15):
            d[k] = dxs[j, k]
        inject(y, d)
        for k in range(16):
            out_x[out_a + j, k] = y[k]


@numba.njit(cache=True)
def position_covariance(P: np.ndarray, L: int, out_var: np.ndarray, out_a: int) -> None:
    """out_var[out_a + j] = (var east, var north, var up, cov east–north) of P[j], m²."""
    for j in range(L + 1):
        for k in range(3):
            out_var[out_a + j, k] = P[j, k, k]
        out_var[out_a + j, 3] = P[j, 0, 1]
