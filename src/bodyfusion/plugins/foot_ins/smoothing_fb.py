"""The forward–backward smoothers FB and FB-RTS, one compiled call per segment ([Shen2025] §3):
the backward navigation's prior, the fusion of the two passes, the position recomputed from the
fused velocity (:mod:`bodyfusion.plugins.foot_ins.smoothing` says what each smoother is)."""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import FilterParams, inject
from bodyfusion.plugins.foot_ins.records import (FilterReplay, FilterRun, FilterState, ImuSamples, PassBuffers,
                                                 SmoothedOutput, SmoothedPass)
from bodyfusion.plugins.foot_ins.smoothing_replay import boxminus, filter_pass
from bodyfusion.plugins.foot_ins.smoothing_rts import (apply_smoothed, chol_solve, position_covariance, rts_block,
                                                       rts_block_after_position)

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


@numba.njit(inline="always")
def _pass(passes: PassBuffers, p: int) -> PassBuffers:
    """Pass p of two passes' buffers (a leading pass axis)."""
    xs, xp, Ppost, Pprior, Phi, dx, jump, yaw_reset = passes
    return PassBuffers(xs[p], xp[p], Ppost[p], Pprior[p], Phi[p], dx[p], jump[p], yaw_reset[p])


@numba.njit(cache=True, nogil=True)
def fb_segment(run: FilterRun, params_bw: FilterParams, a: int, b: int, P_a: np.ndarray, memory_a: np.ndarray,
               with_rts: bool, passes: PassBuffers, smoothing: SmoothedPass,
               out: SmoothedOutput) -> tuple[np.ndarray, float, int, int]:
    """FB or FB-RTS of the segment a … b of the filter's ``run``
    (:mod:`bodyfusion.plugins.foot_ins.smoothing`), one call:

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

    The pass buffers (``passes``, those of :func:`filter_pass`; ``dxs``, ``Ps`` and ``smoothed``
    of ``smoothing``, of :func:`rts_block` and :func:`apply_smoothed`) hold the forward pass at
    [0] and the backward one at [1]. Writes out_x[a … b] (16,) and out_var[a … b] (m²). Returns
    the forward covariance at b, the largest |replayed − recorded| forward nominal state
    element, and the RTS steps and fusions that failed."""
    (t, acc, gyro, stance), params, replay, P0 = run
    hist_x, _, _, _, _, gap_idx, gap_dP = replay
    xs, xp, Ppost, Pprior, Phi, dx, jump, yaw_reset = passes
    dxs, Ps, smoothed, fused_P = smoothing
    out_x, out_var = out
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
    samples_bw = ImuSamples(t_bw, acc_bw, gyro_bw, stance_bw)
    replay_bw = FilterReplay(hist_x, no_idx, np.empty((0, 15, 15)), no_idx, np.empty((0, 16)), gap_j, gap_dP_bw)
    no_phi = np.empty((0, 0))
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
        P_end = filter_pass(FilterState(x0, P_start, mem, no_phi), run.samples if fw else samples_bw,
                            params if fw else params_bw, a if fw else 0, b if fw else L, replay if fw else replay_bw,
                            True, _pass(passes, p))
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
                gain_failures += rts_block(_pass(passes, 0), L, zeros, Ppost[0, L].copy(), dxs[0], Ps[0])
            else:  # the backward pass's position is not wanted
                gain_failures += rts_block_after_position(_pass(passes, 1), L, zeros, Ppost[1, L].copy(), dxs[1],
                                                          Ps[1])
            apply_smoothed(xs[p], 0, L, dxs[p], smoothed[p], 0)
    fusion_failures = fuse_block(smoothed[0] if with_rts else xs[0], Ps[0] if with_rts else Ppost[0],
                                 smoothed[1] if with_rts else xp[1], Ps[1] if with_rts else Pprior[1], L, out_x,
                                 fused_P, a)
    position_covariance(Ps[0] if with_rts else fused_P, L, out_var, a)
    integrate_position(out_x, t, a, b, out_x[a, 0:3].copy(), jump[0])
    return P_b, error, gain_failures, fusion_failures
