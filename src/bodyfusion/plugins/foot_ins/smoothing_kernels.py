"""Compiled passes of the smoothers (:mod:`bodyfusion.plugins.foot_ins.smoothing`), [Shen2025] §3.

Every pass steps the filter's own per-sample recursion,
:func:`bodyfusion.plugins.foot_ins.kernels.ekf_step` (mechanisation, covariance propagation,
gated ZUPT/ZARU): the covariance rebuild of the forward filter and the backward navigation
cannot drift from the filter.

Block buffers (float64), j = 0 … L over the samples of one block in the pass's own time order
(forward j = i − a; backward j = b − i): ``xs`` (L+1, 16) posterior and ``xp`` (L+1, 16) prior
nominal states, ``Ppost`` / ``Pprior`` (L+1, 15, 15) posterior / prior covariances, ``Phi``
(L+1, 15, 15) the transition from j−1 to j, ``dx`` (L+1, 15) the correction injected at j
(posterior ⊖ prior nominal), ``jump`` (L+1, 3) the position moved by a correction made
outside the filter's loop. Only one block is held at a time: O(longest block) memory, never
N×15×15 (the whole-run RTS stores less: :mod:`bodyfusion.plugins.foot_ins.smoothing_mbf`).
Scalar loops only (array expressions cost numba compile time).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.nav.attitude import quat_multiply
from bodyfusion.nav.error_state import FilterParams, congruence_by_yaw_reset, inject, process_noise_diag
from bodyfusion.plugins.foot_ins.kernels import NO_STANCE, ekf_step

YAW = 8
"""Error-state index of the yaw (the rotation about Up, δθ_U): the one attitude direction a
foot INS cannot observe; the backward pass shares it with the forward pass."""
DIFFUSE_SCALE = 10.0
"""The backward pass's prior σ of each state but the yaw: this many times the larger of the
forward σ at the segment end and the filter's initial σ (information ≤ 1 % of the forward
pass's; :func:`backward_prior`)."""
FUSED = np.array([3, 4, 5, 6, 7, 9, 10, 11, 12, 13, 14], dtype=np.int64)
"""States the backward pass informs and the fusion takes from it: δv, roll and pitch,
δb_a, δb_g. Not position (no dynamics or update of the pass depends on it, so it learns
nothing of it) nor the shared yaw."""
AFTER_POSITION = 3
"""The first error state after position (δv), where the backward pass's RTS starts
(:func:`rts_block_after_position`: nothing depends on or measures position in that pass)."""


@numba.njit(cache=True)
def boxminus(xa: np.ndarray, xb: np.ndarray, out: np.ndarray) -> None:
    """out (15,) = xa ⊖ xb: the error state with inject(xb, out) = xa (attitude exact:
    the rotation vector of q_a ⊗ q_b⁻¹, navigation frame)."""
    for k in range(3):
        out[k] = xa[k] - xb[k]
        out[3 + k] = xa[3 + k] - xb[3 + k]
        out[9 + k] = xa[10 + k] - xb[10 + k]
        out[12 + k] = xa[13 + k] - xb[13 + k]
    d = quat_multiply((xa[6], xa[7], xa[8], xa[9]), (xb[6], -xb[7], -xb[8], -xb[9]))  # q_a ⊗ q_b⁻¹
    if d[0] < 0.0:
        d = (-d[0], -d[1], -d[2], -d[3])
    s = math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3])
    scale = 2.0 if s < 1e-12 else 2.0 * math.atan2(s, d[0]) / s
    for k in range(3):
        out[6 + k] = scale * d[1 + k]


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


@numba.njit(cache=True, nogil=True)
def filter_pass(x0: np.ndarray, P0: np.ndarray, memory0: np.ndarray, t: np.ndarray, acc: np.ndarray,
                gyro: np.ndarray, stance: np.ndarray, params: FilterParams, i0: int, i1: int, recorded_x: np.ndarray,
                ov_idx: np.ndarray, ov_P: np.ndarray, kept_idx: np.ndarray, kept_x: np.ndarray,
                gap_idx: np.ndarray, gap_dP: np.ndarray, store: bool, xs: np.ndarray, xp: np.ndarray, Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray,
                dx: np.ndarray, jump: np.ndarray, yaw_reset: np.ndarray) -> np.ndarray:
    """The ekf over i0 < i ≤ i1 (:func:`~bodyfusion.plugins.foot_ins.kernels.ekf_step`) from
    the nominal state x0 (16,), covariance P0 (15, 15) and mechanisation memory ``memory0``
    (6,) at i0, replaying what the filter did outside its compiled loop:

    * before the step to a gap sample (``gap_idx``, sorted), P += ``gap_dP`` (the gap policy's
      inflation: process noise of the step across the gap);
    * after the step at an override sample (``ov_idx``, sorted: fuser corrections, position
      fixes, the ckf's coloured updates), the state becomes the recorded one
      (``recorded_x[i]``) and the covariance the one the correction left (the last ``ov_P``
      at i); where one of them was a kept correction (``kept_idx``, :func:`replay_corrections`)
      ``dx`` is the update up to the state before it (``kept_x``).

    From the filter's recorded state and memory at i0 this is the filter itself, bit for
    bit; on time-reversed samples it is the backward navigation. With ``store`` the block
    buffers (j = i − i0) are filled, ``jump`` (L+1, 3) with the position the overrides
    moved (m, zero elsewhere) and ``yaw_reset`` (L+1, 2) with the east and north velocity
    rows a = e_z × Δv of the heading reset G = I + a e_ψᵀ the stance update made at j
    (:func:`bodyfusion.nav.error_state.keep_yaw_unobservable`; Δv the update's velocity
    correction, zero off stance). Returns the covariance at i1."""
    q_diag = process_noise_diag(params)
    work = np.empty((15, 15))
    f_n = np.empty(3)
    C_nb = np.empty((3, 3))
    scratch = np.empty(15)
    x = x0.copy()
    P = P0.copy()
    memory = memory0.copy()
    no_phi = np.empty((0, 0))
    x_prior = np.empty(16)
    ptr = np.searchsorted(ov_idx, i0 + 1)
    kptr = np.searchsorted(kept_idx, i0 + 1)
    gptr = np.searchsorted(gap_idx, i0 + 1)
    moved = np.empty(3)
    if store:
        for k in range(16):
            xs[0, k] = x[k]
            xp[0, k] = x[k]
        for k in range(15):
            dx[0, k] = 0.0
        for k in range(3):
            jump[0, k] = 0.0
        yaw_reset[0, 0] = yaw_reset[0, 1] = 0.0
        for r in range(15):
            for c in range(15):
                Ppost[0, r, c] = P[r, c]
                Pprior[0, r, c] = P[r, c]
                Phi[0, r, c] = 1.0 if r == c else 0.0
    for i in range(i0 + 1, i1 + 1):
        while gptr < gap_idx.shape[0] and gap_idx[gptr] == i:
            for r in range(15):
                for c in range(15):
                    P[r, c] += gap_dP[gptr, r, c]
            gptr += 1
        j = i - i0
        # storing, the step writes its prior and transition straight into the block buffers;
        # not storing, it skips them (an empty transition)
        x_prior_j, P_prior_j, Phi_j = (xp[j], Pprior[j], Phi[j]) if store else (x_prior, no_phi, no_phi)
        nis = ekf_step(x, P, t, acc, gyro, stance, i, params, q_diag, f_n, memory, no_phi, work, scratch, C_nb,
                       x_prior_j, P_prior_j, Phi_j)
        if store:
            stanced = nis != NO_STANCE
            yaw_reset[j, 0] = -(x[4] - x_prior_j[4]) if stanced else 0.0
            yaw_reset[j, 1] = (x[3] - x_prior_j[3]) if stanced else 0.0
        ptr, kptr = replay_corrections(i, x, P, x_prior_j, recorded_x, ov_idx, ov_P, kept_idx, kept_x, ptr, kptr,
                                       store, scratch, moved)
        if store:
            for k in range(3):
                jump[j, k] = moved[k]
            for k in range(16):
                xs[j, k] = x[k]
            for r in range(15):
                for c in range(15):
                    Ppost[j, r, c] = P[r, c]
            for k in range(15):
                dx[j, k] = scratch[k]
    return P


@numba.njit(cache=True)
def replay_corrections(i: int, x: np.ndarray, P: np.ndarray, x_prior: np.ndarray, recorded_x: np.ndarray,
                       ov_idx: np.ndarray, ov_P: np.ndarray, kept_idx: np.ndarray, kept_x: np.ndarray, ptr: int,
                       kptr: int, want_dx: bool, dx: np.ndarray, moved: np.ndarray) -> tuple[int, int]:
    """After the filter's step to sample i (x, P its posterior in place, x_prior its prior): the
    corrections the filter made outside its loop at i, from the pointers ``ptr`` into the
    sorted ``ov_idx`` and ``kptr`` into the sorted ``kept_idx``. With an override at i the
    state becomes the recorded one and the covariance the last one left at i; ``moved`` (3,)
    gets the position it moved (m; zero without one). With ``want_dx``, ``dx`` (15,) gets the
    update the smoothers step through at i: posterior ⊖ prior; where a kept correction was made
    at i — one derived from other systems' estimates (a distance constraint), which a
    per-system smoother cannot re-derive from their smoothed estimates and so keeps as the
    filter made it — the state before it (``kept_x``) ⊖ prior: the jump is then a known input
    of the smoothed model, not information. Returns the advanced pointers."""
    for k in range(3):
        moved[k] = 0.0
    if ptr < ov_idx.shape[0] and ov_idx[ptr] == i:
        while ptr < ov_idx.shape[0] and ov_idx[ptr] == i:
            ptr += 1
        for k in range(3):
            moved[k] = recorded_x[i, k] - x[k]
        for k in range(16):
            x[k] = recorded_x[i, k]
        for r in range(15):
            for c in range(15):
                P[r, c] = ov_P[ptr - 1, r, c]
    kept = kptr < kept_idx.shape[0] and kept_idx[kptr] == i
    if want_dx:
        boxminus(kept_x[kptr] if kept else x, x_prior, dx)
    while kptr < kept_idx.shape[0] and kept_idx[kptr] == i:
        kptr += 1
    return ptr, kptr


@numba.njit(inline="always")
def _rts_sweep(Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray, yaw_reset: np.ndarray, L: int,
               dx_end: np.ndarray, P_end: np.ndarray, first: int, dxs: np.ndarray, Ps: np.ndarray) -> int:
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
def rts_block(Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray, yaw_reset: np.ndarray, L: int,
              dx_end: np.ndarray, P_end: np.ndarray, dxs: np.ndarray, Ps: np.ndarray) -> int:
    """:func:`_rts_sweep` of all the error states."""
    return _rts_sweep(Ppost, Pprior, Phi, dx, yaw_reset, L, dx_end, P_end, 0, dxs, Ps)


@numba.njit(cache=True)
def rts_block_after_position(Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray,
                             yaw_reset: np.ndarray, L: int, dx_end: np.ndarray, P_end: np.ndarray, dxs: np.ndarray,
                             Ps: np.ndarray) -> int:
    """:func:`_rts_sweep` of the error states from :data:`AFTER_POSITION` (a kernel of its own:
    the sizes constant in each, 12³ products instead of 15³)."""
    return _rts_sweep(Ppost, Pprior, Phi, dx, yaw_reset, L, dx_end, P_end, AFTER_POSITION, dxs, Ps)


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


@numba.njit(cache=True)
def fuse_block(xf: np.ndarray, Pf: np.ndarray, xb: np.ndarray, Pb: np.ndarray, L: int, out_x: np.ndarray,
               out_P: np.ndarray, a: int) -> int:
    """Covariance-weighted fusion of the forward (j = i − a) and backward (j = b − i,
    backward form: velocity and gyro bias negated) estimates of one segment, [Shen2025] §3.3,
    P_g = (P_f⁻¹ + P_b⁻¹)⁻¹, x_g = P_g (P_f⁻¹ x_f + P_b⁻¹ x_b), with the shared part removed.

    The backward pass starts from the forward yaw, so both carry the same yaw error e_ψ:
    e_f = g e_ψ + n_f with n_f independent of it, and the difference of the passes holds no
    e_ψ. The forward covariance is therefore conditioned on the yaw, N_f = P_f −
    P_f[:, ψ] P_f[ψ, :] / P_f[ψ, ψ] (the covariance of n_f), and over the :data:`FUSED` states
    S:  x_g = x_f ⊞ N_f[:, S] (N_f + P_b)_SS⁻¹ (x_b ⊖ x_f)_S,
        P_g = P_f − N_f[:, S] (N_f + P_b)_SS⁻¹ N_f[S, :].
    The yaw and its σ stay the forward ones; position moves with its forward cross-covariances.
    Writes out_x[a + j] (16,) and the leading m × m block of P_g into out_P[j] (·, m, m; m = 3
    the position block, 0 none: the solve then takes the state's column alone). Returns the
    number of samples where the fusion failed (the forward estimate is kept there)."""
    n = FUSED.shape[0]
    m = out_P.shape[1]
    S = np.empty((n, n))
    Lw = np.empty((n, n + 1))
    Z = np.empty((n, m + 1))
    B = np.empty((n, m + 1))
    N = np.empty((15, 15))
    xbf = np.empty(16)
    d = np.empty(15)
    x = np.empty(16)
    sign = np.ones(15)
    for k in range(3):
        sign[3 + k] = -1.0
        sign[12 + k] = -1.0
    failed = 0
    for j in range(L + 1):
        jb = L - j
        for k in range(16):
            xbf[k] = xb[jb, k]
            x[k] = xf[j, k]
        for k in range(3):
            xbf[3 + k] = -xbf[3 + k]
            xbf[13 + k] = -xbf[13 + k]
        boxminus(xbf, x, d)
        # N_f on the columns the fusion reads: the FUSED ones and the first m
        pyy = Pf[j, YAW, YAW]
        for r in range(15):
            for q in range(n + m):
                c = FUSED[q] if q < n else q - n
                N[r, c] = Pf[j, r, c] - (Pf[j, r, YAW] * Pf[j, YAW, c] / pyy if pyy > 0.0 else 0.0)
        for r in range(n):
            fr = FUSED[r]
            for c in range(n):
                fc = FUSED[c]
                S[r, c] = N[fr, fc] + sign[fr] * sign[fc] * Pb[jb, fr, fc]
            for c in range(m):
                B[r, c] = N[fr, c]
            B[r, m] = d[fr]
        ok = chol_solve(S, B, Z, Lw)
        for r in range(15):
            d[r] = 0.0
        for r in range(m):
            for c in range(m):
                out_P[j, r, c] = Pf[j, r, c]
        if ok:
            # δ = N[:, S] Z[:, m];  P_g = P_f − N[:, S] Z[:, :m]
            for r in range(15):
                s = 0.0
                for k in range(n):
                    s += N[r, FUSED[k]] * Z[k, m]
                d[r] = s
            for r in range(m):
                for c in range(r, m):
                    s = 0.0
                    for k in range(n):
                        s += N[r, FUSED[k]] * Z[k, c]
                    out_P[j, r, c] = Pf[j, r, c] - s
                    out_P[j, c, r] = out_P[j, r, c]
        else:
            failed += 1
        inject(x, d)
        for k in range(16):
            out_x[a + j, k] = x[k]
    return failed


@numba.njit(cache=True)
def integrate_position(x: np.ndarray, t: np.ndarray, a: int, b: int, p_a: np.ndarray, jump: np.ndarray) -> None:
    """Position recomputed from the velocity ([Shen2025] §3.3, the re-forward navigation of the
    fused state) by the mechanisation's own trapezoid (:mod:`bodyfusion.nav.strapdown`):
    x[a, 0:3] = p_a, x[i, 0:3] = x[i−1, 0:3] + ½ (v_{i−1} + v_i)(t_i − t_{i−1}) + jump[i − a] for
    a < i ≤ b, ``jump`` (m) the position the filter's corrections outside its loop moved there
    (fuser constraints, position fixes: measurements the velocity does not carry)."""
    for k in range(3):
        x[a, k] = p_a[k]
    for i in range(a + 1, b + 1):
        dt = t[i] - t[i - 1]
        for k in range(3):
            x[i, k] = x[i - 1, k] + 0.5 * (x[i - 1, 3 + k] + x[i, 3 + k]) * dt + jump[i - a, k]


@numba.njit(inline="always")
def _backward_sign(k: int) -> float:
    """The error-state sign of the backward form: velocity and gyro bias negated."""
    return -1.0 if 3 <= k < 6 or k >= 12 else 1.0


@numba.njit(inline="always")
def backward_prior(P_end: np.ndarray, P0: np.ndarray) -> np.ndarray:
    """The backward pass's prior covariance (15, 15) at a segment end, backward form: diagonal,
    each σ :data:`DIFFUSE_SCALE` times the larger of the forward pass's σ there (``P_end``) and
    the filter's initial σ (``P0``) — diffuse around the forward nominal state, which is only
    the backward pass's linearisation point — but the yaw's zero: the backward pass starts from
    the forward yaw and shares its error, which the fusion removes (:func:`fuse_block`).
    Diagonal, so the backward form's signs leave it as it is."""
    P = np.zeros((15, 15))
    for k in range(15):
        P[k, k] = DIFFUSE_SCALE**2 * max(P_end[k, k], P0[k, k]) if k != YAW else 0.0
    return P


@numba.njit(cache=True, nogil=True)
def fb_segment(hist_x: np.ndarray, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, stance: np.ndarray,
               params: FilterParams, params_bw: FilterParams, P0: np.ndarray, ov_idx: np.ndarray, ov_P: np.ndarray,
               kept_idx: np.ndarray, kept_x: np.ndarray, gap_idx: np.ndarray, gap_dP: np.ndarray, a: int, b: int,
               P_a: np.ndarray, memory_a: np.ndarray, with_rts: bool, xs: np.ndarray, xp: np.ndarray, Ppost: np.ndarray,
               Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray, jump: np.ndarray, yaw_reset: np.ndarray,
               dxs: np.ndarray, Ps: np.ndarray, smoothed: np.ndarray, fused_P: np.ndarray, out_x: np.ndarray,
               out_var: np.ndarray) -> tuple[np.ndarray, float, int, int]:
    """FB or FB-RTS of the segment a … b (:mod:`bodyfusion.plugins.foot_ins.smoothing`), one call:

    1. the forward pass: the filter replayed (:func:`filter_pass`) from its recorded state at
       a, the covariance ``P_a`` and its mechanisation memory there (``memory_a`` (6,));
    2. the backward navigation: the filter's step on the time-reversed samples (j = b − i: step
       j covers (t_i, t_{i+1}] with sample i + 1's specific force and negated angular rate,
       ``params_bw`` with the Earth rate negated, the stance update at j sample i's, the gaps'
       inflations in the backward form) from the forward nominal state at b (velocity and gyro
       bias negated) and the prior of :func:`backward_prior`;
    3. with ``with_rts`` both passes RTS-smoothed over the segment (:func:`rts_block`; the backward
       one :func:`rts_block_after_position`);
    4. the fusion (:func:`fuse_block`, the fused covariance's leading block into ``fused_P``
       (·, m, m)): of the smoothed passes, the reported position covariance the forward RTS one
       (m = 0: none formed); without RTS of the forward posterior and the backward prior, the
       position covariance the fused one (m = 3);
    5. the position recomputed from the fused velocity (:func:`integrate_position`).

    The pass buffers (those of :func:`filter_pass`, ``dxs``, ``Ps`` and ``smoothed`` of
    :func:`rts_block` and :func:`apply_smoothed`) hold the forward pass at [0] and the backward
    one at [1]. Writes out_x[a … b] (16,) and out_var[a … b] (m²). Returns the forward
    covariance at b, the largest |replayed − recorded| forward nominal state element, and the
    RTS steps and fusions that failed."""
    L = b - a
    # the backward pass's inputs, reversed
    t_bw = np.empty(L + 1)
    acc_bw = np.empty((L + 1, 3))
    gyro_bw = np.empty((L + 1, 3))
    stance_bw = np.empty(L + 1, dtype=np.bool_)
    for j in range(L + 1):
        i = b - j
        src = min(i + 1, b)
        t_bw[j] = -t[i]
        stance_bw[j] = stance[i]
        for k in range(3):
            acc_bw[j, k] = acc[src, k]
            gyro_bw[j, k] = -gyro[src, k]
    g0 = np.searchsorted(gap_idx, a + 1)
    g1 = np.searchsorted(gap_idx, b + 1)
    gap_j = np.empty(g1 - g0, dtype=np.int64)
    gap_dP_bw = np.empty((g1 - g0, 15, 15))
    for g in range(g1 - g0):
        src = g1 - 1 - g
        gap_j[g] = b - gap_idx[src] + 1
        for r in range(15):
            for c in range(15):
                gap_dP_bw[g, r, c] = gap_dP[src, r, c] * (_backward_sign(r) * _backward_sign(c))
    no_idx = np.empty(0, dtype=np.int64)
    no_P = np.empty((0, 15, 15))
    no_x = np.empty((0, 16))
    P_b = P_a
    for p in range(2):
        if p == 0:
            x0, P_start, mem = hist_x[a].copy(), P_a, memory_a
        else:
            x0, P_start, mem = hist_x[b].copy(), backward_prior(P_b, P0), np.zeros(6)
            for k in range(3):
                x0[3 + k] = -x0[3 + k]
                x0[13 + k] = -x0[13 + k]
        fw = p == 0
        P_end = filter_pass(x0, P_start, mem, t if fw else t_bw, acc if fw else acc_bw, gyro if fw else gyro_bw,
                            stance if fw else stance_bw, params if fw else params_bw, a if fw else 0, b if fw else L,
                            hist_x, ov_idx if fw else no_idx, ov_P if fw else no_P, kept_idx if fw else no_idx,
                            kept_x if fw else no_x, gap_idx if fw else gap_j, gap_dP if fw else gap_dP_bw, True,
                            xs[p], xp[p], Ppost[p], Pprior[p], Phi[p], dx[p], jump[p], yaw_reset[p])
        if fw:
            P_b = P_end
    error = 0.0
    for j in range(L + 1):
        for k in range(16):
            error = max(error, abs(xs[0, j, k] - hist_x[a + j, k]))
    gain_failures = 0
    if with_rts:
        zeros = np.zeros(15)
        for p in range(2):
            if p == 0:
                gain_failures += rts_block(Ppost[0], Pprior[0], Phi[0], dx[0], yaw_reset[0], L, zeros,
                                           Ppost[0, L].copy(), dxs[0], Ps[0])
            else:  # the backward pass's position is not wanted
                gain_failures += rts_block_after_position(Ppost[1], Pprior[1], Phi[1], dx[1], yaw_reset[1], L, zeros,
                                                          Ppost[1, L].copy(), dxs[1], Ps[1])
            apply_smoothed(xs[p], 0, L, dxs[p], smoothed[p], 0)
    fusion_failures = fuse_block(smoothed[0] if with_rts else xs[0], Ps[0] if with_rts else Ppost[0],
                                 smoothed[1] if with_rts else xp[1], Ps[1] if with_rts else Pprior[1], L, out_x,
                                 fused_P, a)
    position_covariance(Ps[0] if with_rts else fused_P, L, out_var, a)
    integrate_position(out_x, t, a, b, out_x[a, 0:3].copy(), jump[0])
    return P_b, error, gain_failures, fusion_failures
