"""Compiled per-sample loops of the smoothers (:mod:`bodyfusion.plugins.foot_ins.smoothing`).

All kernels work on one *block* of samples a ≤ i ≤ b at a time and on block-local
buffers indexed in the filter's own time order, j = 0 … L (L = b − a):

* forward pass: j = i − a;   backward pass: j = b − i.

Buffers (float64): ``Ppost`` (L+1, 15, 15) a-posteriori covariance, ``Pprior``
(L+1, 15, 15) a-priori covariance, ``Phi`` (L+1, 15, 15) the transition from j−1 to j,
``dx`` (L+1, 15) the correction injected at j (posterior ⊖ prior nominal). Only one
block is held at a time, so memory is O(longest block), never N×15×15.

Scalar loops only (array expressions cost numba compile time); the mechanisation and
the error model are those of the forward filter (:func:`bodyfusion.nav.strapdown.mechanise`,
:mod:`bodyfusion.nav.error_state`, :mod:`bodyfusion.nav.zupt`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.nav.error_state import (P_GRAVITY, P_ZARU_SIGMA, P_ZUPT_GATE, P_ZUPT_SIGMA, _apply_A_left, inject,
                                process_noise_diag, propagate_covariance, update_selected)
from bodyfusion.nav.attitude import quat_multiply
from bodyfusion.nav.strapdown import mechanise
from bodyfusion.nav.zupt import gated_noise_variance, stance_update

@numba.njit(cache=True)
def _copy15(dst: np.ndarray, src: np.ndarray) -> None:
    """dst[:, :] = src for 15×15 matrices (element loops: no slice assignment in kernels)."""
    for r in range(15):
        for c in range(15):
            dst[r, c] = src[r, c]


@numba.njit(cache=True)
def boxminus(xa: np.ndarray, xb: np.ndarray, out: np.ndarray) -> None:
    """out (15,) = xa ⊖ xb: the error state with inject(xb, out) = xa (attitude exact:
    the rotation vector of q_a ⊗ q_b⁻¹, navigation frame)."""
    for k in range(3):
        out[k] = xa[k] - xb[k]
        out[3 + k] = xa[3 + k] - xb[3 + k]
        out[9 + k] = xa[10 + k] - xb[10 + k]
        out[12 + k] = xa[13 + k] - xb[13 + k]
    qb_conj = np.empty(4)
    qb_conj[0] = xb[6]
    for k in range(3):
        qb_conj[1 + k] = -xb[7 + k]
    d = quat_multiply(xa[6:10], qb_conj)
    if d[0] < 0.0:
        for k in range(4):
            d[k] = -d[k]
    s = math.sqrt(d[1] * d[1] + d[2] * d[2] + d[3] * d[3])
    scale = 2.0 if s < 1e-12 else 2.0 * math.atan2(s, d[0]) / s
    for k in range(3):
        out[6 + k] = scale * d[1 + k]


@numba.njit(cache=True)
def transition(C: np.ndarray, f_n: np.ndarray, dt: float, Phi: np.ndarray, work: np.ndarray) -> None:
    """Phi (15, 15) = I + A dt (the filter's first-order transition)."""
    for r in range(15):
        for c in range(15):
            work[r, c] = 1.0 if r == c else 0.0
    _apply_A_left(work, C, f_n, Phi)
    for r in range(15):
        for c in range(15):
            Phi[r, c] = (1.0 if r == c else 0.0) + dt * Phi[r, c]


@numba.njit(cache=True)
def chol_solve(A: np.ndarray, B: np.ndarray, X: np.ndarray, n: int, m: int, Lw: np.ndarray) -> bool:
    """Solve A X = B for symmetric positive-definite A (n×n, top-left block used) and
    B (n×m); Cholesky in ``Lw`` (n×n scratch). A tiny diagonal jitter is added when the
    factorisation meets a non-positive pivot; returns False if it still fails."""
    for attempt in range(3):
        jitter = 0.0 if attempt == 0 else 1e-12 * (10.0 ** (4 * attempt))
        ok = True
        for r in range(n):
            for c in range(r + 1):
                s = A[r, c]
                if r == c:
                    s += jitter * max(abs(A[r, r]), 1e-30)
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
            for col in range(m):
                for r in range(n):
                    s = B[r, col]
                    for k in range(r):
                        s -= Lw[r, k] * X[k, col]
                    X[r, col] = s / Lw[r, r]
                for r in range(n - 1, -1, -1):
                    s = X[r, col]
                    for k in range(r + 1, n):
                        s -= Lw[k, r] * X[k, col]
                    X[r, col] = s / Lw[r, r]
            return True
    return False


@numba.njit(cache=True)
def _prior_from_history(hist_x: np.ndarray, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, i: int,
                        g: float, w_ie: np.ndarray, xprior: np.ndarray, f_n: np.ndarray) -> np.ndarray:
    """Re-mechanise the recorded posterior at i−1 to the prior at i, exactly as the filter
    did (the two-sample memory rebuilt from sample i−1 and the biases at i−2)."""
    prev = np.zeros(6)
    if i >= 2:
        dtp = t[i - 1] - t[i - 2]
        for k in range(3):
            prev[k] = (gyro[i - 1, k] - hist_x[i - 2, 13 + k]) * dtp
            prev[3 + k] = (acc[i - 1, k] - hist_x[i - 2, 10 + k]) * dtp
    for k in range(16):
        xprior[k] = hist_x[i - 1, k]
    return mechanise(xprior, acc[i], gyro[i], t[i] - t[i - 1], g, w_ie, f_n, prev)


@numba.njit(cache=True)
def forward_block(hist_x: np.ndarray, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, stance: np.ndarray,
                  params: np.ndarray, a: int, b: int, P_a: np.ndarray, ov_idx: np.ndarray, ov_P: np.ndarray,
                  store: bool, Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """Rebuild the forward filter's covariances over a < i ≤ b from P_a (the posterior at a)
    and the recorded nominal history: the same propagation, ZUPT/ZARU Joseph updates at
    stance samples, and at sample indices in ``ov_idx`` (sorted) the covariance the fuser
    or a position fix left (``ov_P``). With ``store`` the block buffers are filled
    (j = i − a). Returns the posterior covariance at b."""
    q_diag = process_noise_diag(params)
    g = params[P_GRAVITY]
    w_ie = params[7:10].copy()
    zs = params[P_ZUPT_SIGMA]
    zr = params[P_ZARU_SIGMA]
    P = P_a.copy()
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    xprior = np.empty(16)
    tmp = np.empty(15)
    y = np.zeros(3)
    v = np.empty(3)
    gate = params[P_ZUPT_GATE]
    empty = np.empty((0, 0))
    ptr = np.searchsorted(ov_idx, a + 1)
    if store:
        _copy15(Ppost[0], P)
    for i in range(a + 1, b + 1):
        dt = t[i] - t[i - 1]
        C = _prior_from_history(hist_x, t, acc, gyro, i, g, w_ie, xprior, f_n)
        propagate_covariance(P, C, f_n, dt, q_diag, work)
        j = i - a
        if store:
            transition(C, f_n, dt, Phi[j], work[0])
            _copy15(Pprior[j], P)
        if stance[i]:  # the filter's gated ZUPT: its noise from the prior velocity, as the filter had it
            for k in range(3):
                v[k] = -xprior[3 + k]
            r_var = gated_noise_variance(P, np.int64(3), v, zs * zs, gate)
            update_selected(P, np.int64(3), y, r_var, tmp, empty)
            if zr > 0 and r_var == zs * zs:
                update_selected(P, np.int64(12), y, zr * zr, tmp, empty)
        while ptr < ov_idx.shape[0] and ov_idx[ptr] == i:
            for r in range(15):
                for c in range(15):
                    P[r, c] = ov_P[ptr, r, c]
            ptr += 1
        if store:
            boxminus(hist_x[i], xprior, dx[j])
            _copy15(Ppost[j], P)
    return P


@numba.njit(cache=True)
def forward_rerun_block(x_a: np.ndarray, P_a: np.ndarray, hist_x: np.ndarray, t: np.ndarray, acc: np.ndarray,
                        gyro: np.ndarray, stance: np.ndarray, params: np.ndarray, a: int, b: int,
                        Porig_a: np.ndarray, ov_idx: np.ndarray, ov_P: np.ndarray, xf: np.ndarray,
                        Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray,
                        Porig_b: np.ndarray) -> None:
    """Forward filter re-run over a ≤ i ≤ b from the seed x_a / P_a (FB, FB-RTS: the previous
    segment's fused end state), j = i − a.

    The filter's steps: mechanisation (two-sample memory started from sample a with the
    seed's biases), covariance propagation, ZUPT/ZARU (state and covariance) at stance
    samples. Corrections made outside the compiled loop (fuser constraints, position fixes;
    sample indices ``ov_idx``) are carried over: the original filter's correction there,
    recorded posterior ⊖ (recorded prior after its own ZUPT/ZARU), is injected into the
    re-run state and the covariance becomes the one the correction left (``ov_P``). For
    that, the original filter's covariance is rebuilt alongside from ``Porig_a`` (as in
    :func:`forward_block`); its value at b goes to ``Porig_b``.

    Fills ``xf`` (nominal states), ``Ppost``, ``Pprior``, ``Phi``, ``dx`` (0 … L)."""
    q_diag = process_noise_diag(params)
    g = params[P_GRAVITY]
    w_ie = params[7:10].copy()
    x = x_a.copy()
    P = P_a.copy()
    Po = Porig_a.copy()
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    fo = np.empty(3)
    xprior = np.empty(16)
    xo = np.empty(16)
    tmp = np.empty(15)
    dext = np.empty(15)
    empty = np.empty((0, 0))
    prev = np.zeros(6)
    if a >= 1:
        dtp = t[a] - t[a - 1]
        for k in range(3):
            prev[k] = (gyro[a, k] - x[13 + k]) * dtp
            prev[3 + k] = (acc[a, k] - x[10 + k]) * dtp
    ptr = np.searchsorted(ov_idx, a + 1)
    for k in range(16):
        xf[0, k] = x[k]
    _copy15(Ppost[0], P)
    for i in range(a + 1, b + 1):
        j = i - a
        dt = t[i] - t[i - 1]
        C = mechanise(x, acc[i], gyro[i], dt, g, w_ie, f_n, prev)
        transition(C, f_n, dt, Phi[j], work[0])
        propagate_covariance(P, C, f_n, dt, q_diag, work)
        _copy15(Pprior[j], P)
        for k in range(16):
            xprior[k] = x[k]
        Co = _prior_from_history(hist_x, t, acc, gyro, i, g, w_ie, xo, fo)
        propagate_covariance(Po, Co, fo, dt, q_diag, work)
        if stance[i]:
            stance_update(x, P, gyro[i], params, tmp, empty)
            stance_update(xo, Po, gyro[i], params, tmp, empty)
        if ptr < ov_idx.shape[0] and ov_idx[ptr] == i:
            boxminus(hist_x[i], xo, dext)
            inject(x, dext)
            while ptr < ov_idx.shape[0] and ov_idx[ptr] == i:
                ptr += 1
            for r in range(15):
                for c in range(15):
                    P[r, c] = ov_P[ptr - 1, r, c]
                    Po[r, c] = ov_P[ptr - 1, r, c]
        boxminus(x, xprior, dx[j])
        for k in range(16):
            xf[j, k] = x[k]
        _copy15(Ppost[j], P)
    _copy15(Porig_b, Po)


@numba.njit(cache=True)
def backward_block(x_end: np.ndarray, P_end: np.ndarray, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                   stance: np.ndarray, params: np.ndarray, a: int, b: int, xb: np.ndarray, Ppost: np.ndarray,
                   Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray, counters: np.ndarray) -> None:
    """Backward navigation with its own error filter over b ≥ i ≥ a (j = b − i).

    Started from the forward state x_end / P_end at b, expressed in backward form: velocity
    and gyro bias negated (so are the matching rows/columns of P). Each step runs
    :func:`bodyfusion.nav.strapdown.mechanise` from t_i to t_{i−1} on sample i with the angular
    rate negated, the same specific force, the Earth rate negated; the error model has the
    same form (paper §3.1). ZUPT (and ZARU on the negated rate) at stance samples.
    ``xb`` (L+1, 16) receives the backward nominal states (backward form).
    counters[0] += ZUPTs applied."""
    q_diag = process_noise_diag(params)
    g = params[P_GRAVITY]
    w_neg = np.empty(3)
    for k in range(3):
        w_neg[k] = -params[7 + k]
    x = x_end.copy()
    for k in range(3):
        x[3 + k] = -x[3 + k]
        x[13 + k] = -x[13 + k]
    P = P_end.copy()
    for r in range(15):
        sr = -1.0 if (3 <= r < 6 or r >= 12) else 1.0
        for c in range(15):
            sc = -1.0 if (3 <= c < 6 or c >= 12) else 1.0
            P[r, c] *= sr * sc
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    prev = np.zeros(6)
    gneg = np.empty(3)
    tmp = np.empty(15)
    empty = np.empty((0, 0))
    xprior = np.empty(16)
    for k in range(16):
        xb[0, k] = x[k]
    _copy15(Ppost[0], P)
    for i in range(b, a, -1):
        j = b - i + 1
        dt = t[i] - t[i - 1]
        for k in range(3):
            gneg[k] = -gyro[i, k]
        C = mechanise(x, acc[i], gneg, dt, g, w_neg, f_n, prev)
        transition(C, f_n, dt, Phi[j], work[0])
        propagate_covariance(P, C, f_n, dt, q_diag, work)
        _copy15(Pprior[j], P)
        for k in range(16):
            xprior[k] = x[k]
        if stance[i - 1]:
            for k in range(3):
                gneg[k] = -gyro[i - 1, k]
            stance_update(x, P, gneg, params, tmp, empty)
            counters[0] += 1
        boxminus(x, xprior, dx[j])
        for k in range(16):
            xb[j, k] = x[k]
        _copy15(Ppost[j], P)


@numba.njit(cache=True)
def rts_block(Ppost: np.ndarray, Pprior: np.ndarray, Phi: np.ndarray, dx: np.ndarray, L: int,
              dx_end: np.ndarray, P_end: np.ndarray, dxs: np.ndarray, Ps: np.ndarray) -> int:
    """Rauch–Tung–Striebel backward sweep over a block of a closed-loop error-state filter.

    The filter's own error estimates are zero after every injection, so with dxs[j] the
    smoothed error relative to the posterior nominal at j:

        K_j = P⁺_j Φ_{j+1}ᵀ (P⁻_{j+1})⁻¹
        dxs_j = K_j (dxs_{j+1} + dx_{j+1})          (dx_{j+1}: correction injected at j+1)
        Ps_j = P⁺_j + K_j (Ps_{j+1} − P⁻_{j+1}) K_jᵀ

    starting from dxs_L = dx_end, Ps_L = P_end (zeros and P⁺_L for a block smoothed on
    its own). Returns the number of steps whose gain could not be formed (then
    dxs_j = 0, Ps_j = P⁺_j)."""
    M = np.empty((15, 15))
    Kt = np.empty((15, 15))
    Lw = np.empty((15, 15))
    D = np.empty((15, 15))
    KD = np.empty((15, 15))
    e = np.empty(15)
    failed = 0
    for k in range(15):
        dxs[L, k] = dx_end[k]
        for c in range(15):
            Ps[L, k, c] = P_end[k, c]
    for j in range(L - 1, -1, -1):
        # M = Φ_{j+1} P⁺_j ;  P⁻ Kᵀ = M
        for r in range(15):
            for c in range(15):
                s = 0.0
                for k in range(15):
                    s += Phi[j + 1, r, k] * Ppost[j, k, c]
                M[r, c] = s
        if not chol_solve(Pprior[j + 1], M, Kt, 15, 15, Lw):
            failed += 1
            for r in range(15):
                dxs[j, r] = 0.0
                for c in range(15):
                    Ps[j, r, c] = Ppost[j, r, c]
            continue
        for k in range(15):
            e[k] = dxs[j + 1, k] + dx[j + 1, k]
        for r in range(15):
            s = 0.0
            for k in range(15):
                s += Kt[k, r] * e[k]
            dxs[j, r] = s
        for r in range(15):
            for c in range(15):
                D[r, c] = Ps[j + 1, r, c] - Pprior[j + 1, r, c]
        # KD = K D
        for r in range(15):
            for c in range(15):
                s = 0.0
                for k in range(15):
                    s += Kt[k, r] * D[k, c]
                KD[r, c] = s
        for r in range(15):
            for c in range(r, 15):
                s = 0.0
                for k in range(15):
                    s += KD[r, k] * Kt[k, c]
                v = Ppost[j, r, c] + s
                Ps[j, r, c] = v
                Ps[j, c, r] = v
    return failed


@numba.njit(cache=True)
def apply_smoothed(hist_x: np.ndarray, a: int, L: int, dxs: np.ndarray, Ps: np.ndarray,
                   out_x: np.ndarray, out_var: np.ndarray, out_a: int) -> None:
    """out_x[out_a+j] = hist_x[a+j] ⊞ dxs[j]; out_var[out_a+j] = the position variances and the
    east–north covariance of Ps[j], 0 ≤ j ≤ L."""
    x = np.empty(16)
    d = np.empty(15)
    for j in range(L + 1):
        for k in range(16):
            x[k] = hist_x[a + j, k]
        for k in range(15):
            d[k] = dxs[j, k]
        inject(x, d)
        for k in range(16):
            out_x[out_a + j, k] = x[k]
        for k in range(3):
            out_var[out_a + j, k] = Ps[j, k, k]
        out_var[out_a + j, 3] = Ps[j, 0, 1]


@numba.njit(cache=True)
def fuse_block(xf: np.ndarray, Pf: np.ndarray, xb: np.ndarray, Pb: np.ndarray, L: int, a: int,
               out_x: np.ndarray, out_var: np.ndarray, P_end: np.ndarray) -> int:
    """Covariance-weighted fusion of the forward (j = i − a) and backward (j = b − i)
    estimates (paper §3.3), the backward pass's δp, δv, δθ taken as a measurement of the
    forward state's:

        P_g = (P_f⁻¹ + P_b⁻¹)⁻¹,  x_g = P_g (P_f⁻¹ x_f + P_b⁻¹ x_b)   (over p, v, θ)

    computed as x_g = x_f ⊞ P_f[:, nav] S⁻¹ (x_b ⊖ x_f)_nav, P_g = P_f − P_f[:, nav] S⁻¹
    P_f[nav, :] with S = P_f + P_b over the nine navigation states; the biases move with
    their forward cross-covariances. Writes the fused states out_x[a:a+L+1], their
    position variances, and the fused 15×15 covariance at the end (j = L, the next
    segment's seed) to ``P_end``. Returns the number of samples where the fusion failed
    (the forward estimate is kept there)."""
    S = np.empty((9, 9))
    Lw = np.empty((9, 9))
    Z = np.empty((9, 16))
    B = np.empty((9, 16))
    xbf = np.empty(16)
    d = np.empty(15)
    x = np.empty(16)
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
        for r in range(9):
            sr = -1.0 if 3 <= r < 6 else 1.0
            for c in range(9):
                sc = -1.0 if 3 <= c < 6 else 1.0
                S[r, c] = Pf[j, r, c] + sr * sc * Pb[jb, r, c]
            for c in range(15):
                B[r, c] = Pf[j, r, c]
            B[r, 15] = d[r]
        ok = chol_solve(S, B, Z, 9, 16, Lw)
        for k in range(15):
            d[k] = 0.0
        if ok:
            # δ = P_f[:, nav] Z[:, 15];  P_g = P_f − P_f[:, nav] Z[:, :15]
            for r in range(15):
                s = 0.0
                for k in range(9):
                    s += Pf[j, r, k] * Z[k, 15]
                d[r] = s
            for r in range(3):
                s = 0.0
                for k in range(9):
                    s += Pf[j, r, k] * Z[k, r]
                out_var[a + j, r] = Pf[j, r, r] - s
        else:
            failed += 1
            for r in range(3):
                out_var[a + j, r] = Pf[j, r, r]
        if j == L:
            for r in range(15):
                for c in range(15):
                    s = 0.0
                    if ok:
                        for k in range(9):
                            s += Pf[j, r, k] * Z[k, c]
                    P_end[r, c] = Pf[j, r, c] - s
            for r in range(15):
                for c in range(r + 1, 15):
                    v = 0.5 * (P_end[r, c] + P_end[c, r])
                    P_end[r, c] = v
                    P_end[c, r] = v
        inject(x, d)
        for k in range(16):
            out_x[a + j, k] = x[k]
    return failed
