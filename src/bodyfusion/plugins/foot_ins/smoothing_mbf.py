"""The whole-run RTS of the foot INS in the modified Bryson–Frazier form
(:mod:`bodyfusion.plugins.foot_ins.smoothing`, ``smoother.kind: rts``).

:func:`record_pass` replays the filter (its own compiled step,
:func:`bodyfusion.plugins.foot_ins.kernels.ekf_step`, bit for bit) and stores compactly what
the backward sweep needs: the packed posterior covariance and the step's specific force per
sample, the ZUPT's four prior covariance columns per stance sample, the prior covariance and
the injected correction at the few samples corrected outside the filter's loop. :func:`mbf_sweep`
sweeps it back carrying the adjoint (lam, Lam) (G. J. Bierman, Factorization Methods for
Discrete Sequential Estimation, 1977): no covariance inverse but at those few samples, no
process noise, and the transition rebuilt from the recorded state and the stored specific
force. In exact arithmetic it is the textbook RTS sweep of
:func:`~bodyfusion.plugins.foot_ins.smoothing_rts.rts_block`; in floating point it agrees
to rounding. :func:`block_sweep` runs the two block by block from the run's end, from the
filter's covariance at each block start, so that the record holds one block. Scalar loops
only (array expressions cost numba compile time).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from bodyfusion.nav.attitude import quat_to_dcm_into
from bodyfusion.nav.error_state import (FilterParams, Q_DECAY, congruence_by_yaw_reset,
                                       inject, process_noise_diag, transition_transpose_left)
from bodyfusion.nav.kalman import inv3_sym_into
from bodyfusion.nav.zupt import ZUPT_COLUMNS, gated_variance, stance_velocity_sigma
from bodyfusion.plugins.foot_ins.kernels import NO_STANCE, ekf_step, record_posterior, record_stance
from bodyfusion.plugins.foot_ins.records import (CrossTerms, FilterRun, FilterState, SmoothedOutput, StepScratch,
                                                 SweepRecord)
from bodyfusion.plugins.foot_ins.smoothing_replay import replay_corrections
from bodyfusion.plugins.foot_ins.smoothing_rts import chol_solve


@numba.njit(cache=True)
def _transition_adjoint(C: np.ndarray, f_n: np.ndarray, dt: float, q_diag: np.ndarray, lam: np.ndarray,
                        Lam: np.ndarray, X: np.ndarray) -> None:
    """lam ← Φᵀ lam, Lam ← Φᵀ Lam Φ and the cross block X ← Φᵀ X (15, m) in place (Lam (15, 15)
    symmetric; the result's lower triangle mirrored) for the transition of one step (C_nb, f_n
    m/s², dt s and the bias decay of the process model ``q_diag``:
    :func:`~bodyfusion.plugins.foot_ins.kernels.transition`), from its non-zero entries
    (:func:`bodyfusion.nav.error_state.transition_transpose_left`) rather than a dense Φ:
    V = Φᵀ Lam, then Φᵀ Vᵀ = (V Φ)ᵀ, whose lower triangle is that of Φᵀ Lam Φ."""
    da = (1.0 - dt * q_diag[Q_DECAY]) - 1.0
    dg = (1.0 - dt * q_diag[Q_DECAY + 1]) - 1.0
    # np.bool_, not a bare True/False: numba types a constant argument as a literal, one
    # compilation per value
    transition_transpose_left(lam.reshape((15, 1)), C, f_n, dt, da, dg, np.bool_(False))
    if X.shape[1] > 0:
        transition_transpose_left(X, C, f_n, dt, da, dg, np.bool_(False))
    transition_transpose_left(Lam, C, f_n, dt, da, dg, np.bool_(False))
    for r in range(15):
        for c in range(r + 1, 15):
            v = Lam[r, c]
            Lam[r, c] = Lam[c, r]
            Lam[c, r] = v
    transition_transpose_left(Lam, C, f_n, dt, da, dg, np.bool_(True))
    for r in range(15):
        for c in range(r + 1, 15):
            Lam[r, c] = Lam[c, r]


class ZuptScratch(NamedTuple):
    """Working arrays of :func:`_zupt_adjoint`: the ZUPT's Jacobian on its columns ``Hc`` (3, 4),
    gain ``K`` (15, 3), ``W`` (15, 4), innovation covariance ``S`` and its inverse ``Si`` (3, 3)."""

    Hc: np.ndarray
    K: np.ndarray
    W: np.ndarray
    S: np.ndarray
    Si: np.ndarray


@numba.njit(cache=True)
def _zupt_innovation(Pc: np.ndarray, Hc: np.ndarray, S: np.ndarray) -> None:
    """``S`` (3, 3) ← H P⁻ Hᵀ of the ZUPT from the prior's columns ``Pc`` (15, 4) at
    :data:`~bodyfusion.nav.zupt.ZUPT_COLUMNS`: the sums of
    :func:`bodyfusion.nav.kalman.selection_moments` (their zero terms too, which add
    nothing), so the same number and the same gate decision as the filter's."""
    for r in range(3):
        for c in range(r, 3):
            s = 0.0
            for a in range(4):
                row = 0.0
                for b in range(4):
                    row += Pc[ZUPT_COLUMNS[a], b] * Hc[c, b]
                s += Hc[r, a] * row
            S[r, c] = s
            S[c, r] = s


@numba.njit(cache=True)
def zupt_gain(v: np.ndarray, Pc: np.ndarray, params: FilterParams, Hc: np.ndarray, K: np.ndarray, S: np.ndarray,
              Si: np.ndarray) -> None:
    """The gated ZUPT of a stance sample as the filter made it
    (:func:`bodyfusion.nav.zupt.zero_velocity_update`), from the prior velocity and the ZUPT's
    σ_v² (``v`` (6,): v⁻ m/s, the heading reset's a, σ_v²) and the prior covariance's columns
    ``Pc`` (15, 4) at ZUPT_COLUMNS: its Jacobian on those columns ``Hc`` (3, 4), the innovation
    covariance with the gated noise ``S`` (3, 3), its inverse ``Si`` and the gain
    K = P⁻ Hᵀ S⁻¹ (15, 3)."""
    y = (-v[0], -v[1], -v[2])
    for k in range(3):
        for m in range(3):
            Hc[k, m] = 1.0 if k == m else 0.0
    Hc[0, 3] = v[1]  # the heading column, bodyfusion.nav.zupt.unobservable_yaw_column
    Hc[1, 3] = -v[0]
    Hc[2, 3] = 0.0
    _zupt_innovation(Pc, Hc, S)
    r_var = gated_variance((S[0, 0], S[0, 1], S[0, 2], S[1, 1], S[1, 2], S[2, 2]), y, v[5], params.zupt_gate)
    for k in range(3):
        S[k, k] += r_var
    inv3_sym_into(S, Si)
    for r in range(15):
        m0 = Pc[r, 0] + Pc[r, 3] * Hc[0, 3]
        m1 = Pc[r, 1] + Pc[r, 3] * Hc[1, 3]
        m2 = Pc[r, 2]
        K[r, 0] = m0 * Si[0, 0] + m1 * Si[1, 0] + m2 * Si[2, 0]
        K[r, 1] = m0 * Si[0, 1] + m1 * Si[1, 1] + m2 * Si[2, 1]
        K[r, 2] = m0 * Si[0, 2] + m1 * Si[1, 2] + m2 * Si[2, 2]


@numba.njit(cache=True)
def _zupt_adjoint(v: np.ndarray, Pc: np.ndarray, params: FilterParams, lam: np.ndarray, Lam: np.ndarray,
                  X: np.ndarray, scratch: ZuptScratch) -> None:
    """(lam, Lam) and the cross block X (15, m) in place from after a sample's stance update to
    before it: the heading reset G = I + a e_ψᵀ undone (lam ← Gᵀ lam, Lam ← Gᵀ Lam G, X ← Gᵀ X;
    ``v`` (6,): the prior velocity v⁻ (m/s), a = (v[3], v[4]) on the east and north velocity
    rows and the ZUPT's σ_v² v[5]), then the adjoint of the gated ZUPT as the filter made it
    (:func:`zupt_gain`): with H its Jacobian, S its innovation covariance, K = P⁻ Hᵀ S⁻¹,
    C = I − K H and y = −v⁻,
    lam ← Cᵀ lam − Hᵀ S⁻¹ y,  Lam ← Cᵀ Lam C + Hᵀ S⁻¹ H,  X ← Cᵀ X.
    ``scratch``: :class:`ZuptScratch`."""
    Hc, K, W, S, Si = scratch
    a0, a1 = v[3], v[4]
    lam[8] += a0 * lam[3] + a1 * lam[4]
    for r in range(15):
        Lam[r, 8] += a0 * Lam[r, 3] + a1 * Lam[r, 4]
    for c in range(15):
        Lam[8, c] += a0 * Lam[3, c] + a1 * Lam[4, c]
    for c in range(X.shape[1]):
        X[8, c] += a0 * X[3, c] + a1 * X[4, c]
    zupt_gain(v, Pc, params, Hc, K, S, Si)
    y = (-v[0], -v[1], -v[2])
    u0 = Si[0, 0] * y[0] + Si[0, 1] * y[1] + Si[0, 2] * y[2]
    u1 = Si[1, 0] * y[0] + Si[1, 1] * y[1] + Si[1, 2] * y[2]
    u2 = Si[2, 0] * y[0] + Si[2, 1] * y[1] + Si[2, 2] * y[2]
    for r in range(15):
        u0 += K[r, 0] * lam[r]
        u1 += K[r, 1] * lam[r]
        u2 += K[r, 2] * lam[r]
    for c in range(X.shape[1]):  # X ← X − Hᵀ (Kᵀ X)
        w0 = w1 = w2 = 0.0
        for r in range(15):
            w0 += K[r, 0] * X[r, c]
            w1 += K[r, 1] * X[r, c]
            w2 += K[r, 2] * X[r, c]
        for m in range(4):
            X[ZUPT_COLUMNS[m], c] -= Hc[0, m] * w0 + Hc[1, m] * w1 + Hc[2, m] * w2
    # W = Lam K (the columns of Lam H come with Hᵀ), Z = Kᵀ Lam K + S⁻¹ (into S); W a row of
    # Lam (symmetric) at a time, each element summed over k in the order of a row times a column
    for r in range(15):
        W[r, 0] = W[r, 1] = W[r, 2] = 0.0
    for k in range(15):
        k0, k1, k2 = K[k, 0], K[k, 1], K[k, 2]
        for r in range(15):
            lrk = Lam[k, r]
            W[r, 0] += lrk * k0
            W[r, 1] += lrk * k1
            W[r, 2] += lrk * k2
    for r in range(15):
        W[r, 3] = W[r, 0] * Hc[0, 3] + W[r, 1] * Hc[1, 3]
    Z = S
    for r in range(3):
        for c in range(3):
            s = Si[r, c]
            for k in range(15):
                s += K[k, r] * W[k, c]
            Z[r, c] = s
    lam[3] -= u0  # lam ← lam − Hᵀ u
    lam[4] -= u1
    lam[5] -= u2
    lam[8] -= Hc[0, 3] * u0 + Hc[1, 3] * u1
    for m in range(4):  # Lam ← Lam − W H − (W H)ᵀ
        col = ZUPT_COLUMNS[m]
        for r in range(15):
            Lam[r, col] -= W[r, m]
            Lam[col, r] -= W[r, m]
    ZH = W  # + Hᵀ Z H on the columns 3, 4, 5, 8 (Z H into the first rows of W)
    for r in range(3):
        for m in range(4):
            ZH[r, m] = Z[r, 0] * Hc[0, m] + Z[r, 1] * Hc[1, m] + Z[r, 2] * Hc[2, m]
    for n in range(4):
        for m in range(4):
            Lam[ZUPT_COLUMNS[n], ZUPT_COLUMNS[m]] += Hc[0, n] * ZH[0, m] + Hc[1, n] * ZH[1, m] + Hc[2, n] * ZH[2, m]


@numba.njit(cache=True)
def _general_adjoint(P_post: np.ndarray, P_prior: np.ndarray, dxs: np.ndarray, dx: np.ndarray, a0: float, a1: float,
                     lam: np.ndarray, Lam: np.ndarray) -> bool:
    """(lam, Lam) in place from after a sample to before its update, whatever the update was
    (a correction outside the filter's loop, a ZARU): the smoothed error dxs = −P⁺ lam and
    covariance Ps = P⁺ − P⁺ Lam P⁺ there, taken to the prior by the heading reset's G⁻¹ and
    the injected correction dx (as
    :func:`~bodyfusion.plugins.foot_ins.smoothing_rts.rts_block`), give lam = −(P⁻)⁻¹ e
    and Lam = (P⁻)⁻¹ (P⁻ − G⁻¹ Ps G⁻ᵀ) (P⁻)⁻¹. False when P⁻ cannot be factorised."""
    PL = np.empty((15, 15))
    D = np.empty((15, 15))
    for r in range(15):
        for c in range(15):
            PL[r, c] = 0.0
        for k in range(15):
            prk = P_post[r, k]
            for c in range(15):
                PL[r, c] += prk * Lam[k, c]
    for r in range(15):
        for c in range(15):
            D[r, c] = 0.0
        for k in range(15):
            lrk = PL[r, k]
            for c in range(15):
                D[r, c] += lrk * P_post[k, c]
        for c in range(15):
            D[r, c] = P_post[r, c] - D[r, c]
    congruence_by_yaw_reset(D, -a0, -a1)  # G⁻¹ D G⁻ᵀ
    B = np.empty((15, 16))
    for r in range(15):
        for c in range(15):
            B[r, c] = P_prior[r, c] - D[r, c]
        B[r, 15] = dxs[r] + dx[r]
    B[3, 15] -= a0 * dxs[8]
    B[4, 15] -= a1 * dxs[8]
    X = np.empty((15, 16))
    Lw = np.empty((15, 16))
    if not chol_solve(P_prior, B, X, Lw):
        return False
    for r in range(15):
        lam[r] = -X[r, 15]
        for c in range(15):
            D[r, c] = X[c, r]
    if not chol_solve(P_prior, D, PL, Lw):
        return False
    for r in range(15):
        for c in range(r, 15):
            v = 0.5 * (PL[r, c] + PL[c, r])
            Lam[r, c] = v
            Lam[c, r] = v
    return True


@numba.njit(cache=True)
def _cross_through_general(P_post: np.ndarray, P_prior: np.ndarray, a0: float, a1: float, X: np.ndarray) -> bool:
    """The cross block X (15, m) in place from after a general update (prior covariance
    ``P_prior``, posterior ``P_post``, heading reset a) to before it: X ← Aᵀ X with the update's
    closed-loop map A = G (I − K H) = P⁺ G⁻ᵀ (P⁻)⁻¹, i.e. X ← (P⁻)⁻¹ G⁻¹ P⁺ X (the map
    :func:`_general_adjoint` takes lam and Lam through). False when P⁻ cannot be factorised."""
    m = X.shape[1]
    Y = np.empty((15, m))
    for r in range(15):
        for c in range(m):
            s = 0.0
            for k in range(15):
                s += P_post[r, k] * X[k, c]
            Y[r, c] = s
    for c in range(m):
        Y[3, c] -= a0 * Y[8, c]
        Y[4, c] -= a1 * Y[8, c]
    return chol_solve(P_prior, Y, X, np.empty((15, 16)))


@numba.njit(inline="always")
def _smoothed_error_columns(P: np.ndarray, lam: np.ndarray, Lam: np.ndarray, r0: int, d: np.ndarray,
                            T: np.ndarray) -> None:
    """Columns r0 … r0 + 4 of d = −P lam (15,) and T = (Lam P[:, 0:3])ᵀ (3, 15), from P and
    Lam (15, 15) symmetric: row k of P (of Lam) for column k, so each element sums over k in
    the order of the row-times-column product; the 20 sums held in registers."""
    d0 = d1 = d2 = d3 = d4 = 0.0
    a0 = a1 = a2 = a3 = a4 = 0.0
    b0 = b1 = b2 = b3 = b4 = 0.0
    c0 = c1 = c2 = c3 = c4 = 0.0
    for k in range(15):
        lk, p0, p1, p2 = lam[k], P[k, 0], P[k, 1], P[k, 2]
        d0 += P[k, r0] * lk
        d1 += P[k, r0 + 1] * lk
        d2 += P[k, r0 + 2] * lk
        d3 += P[k, r0 + 3] * lk
        d4 += P[k, r0 + 4] * lk
        l0, l1, l2, l3, l4 = Lam[k, r0], Lam[k, r0 + 1], Lam[k, r0 + 2], Lam[k, r0 + 3], Lam[k, r0 + 4]
        a0 += l0 * p0
        a1 += l1 * p0
        a2 += l2 * p0
        a3 += l3 * p0
        a4 += l4 * p0
        b0 += l0 * p1
        b1 += l1 * p1
        b2 += l2 * p1
        b3 += l3 * p1
        b4 += l4 * p1
        c0 += l0 * p2
        c1 += l1 * p2
        c2 += l2 * p2
        c3 += l3 * p2
        c4 += l4 * p2
    d[r0], d[r0 + 1], d[r0 + 2], d[r0 + 3], d[r0 + 4] = -d0, -d1, -d2, -d3, -d4
    T[0, r0], T[0, r0 + 1], T[0, r0 + 2], T[0, r0 + 3], T[0, r0 + 4] = a0, a1, a2, a3, a4
    T[1, r0], T[1, r0 + 1], T[1, r0 + 2], T[1, r0 + 3], T[1, r0 + 4] = b0, b1, b2, b3, b4
    T[2, r0], T[2, r0 + 1], T[2, r0 + 2], T[2, r0 + 3], T[2, r0 + 4] = c0, c1, c2, c3, c4


@numba.njit(cache=True, nogil=True)
def record_pass(start: FilterState, run: FilterRun, general: np.ndarray, i0: int, i1: int,
                store: SweepRecord) -> tuple[np.ndarray, float, int, int, int]:
    """The ekf over i0 < i ≤ i1 of the filter's ``run`` as
    :func:`~bodyfusion.plugins.foot_ins.smoothing_replay.filter_pass` (from the filter's
    state, covariance and mechanisation memory at i0, the ``start``, its corrections outside the
    loop and its gaps replayed), storing compactly into ``store`` what :func:`mbf_sweep` needs,
    j = i − i0:

    * ``Pu`` (L+1, 120), ``f_ns`` (L+1, 3): the posterior covariance packed and the step's
      mean specific force (:func:`~bodyfusion.plugins.foot_ins.kernels.record_posterior`);
    * per stance sample (in order): ``st_v`` (·, 6) the prior velocity (m/s), the heading
      reset's a (``yaw_reset`` of ``filter_pass``) and the ZUPT's σ_v², ``st_P`` (·, 15, 4) the prior covariance's
      columns at ZUPT_COLUMNS (:func:`~bodyfusion.plugins.foot_ins.kernels.record_stance`; what
      the ekf records as it runs, :func:`~bodyfusion.plugins.foot_ins.kernels.run_foot_ins`);
    * per sample with a ``general`` update (in order): ``gen_P`` (·, 15, 15) the prior
      covariance, ``gen_dx`` (·, 15) the correction injected (posterior ⊖ prior nominal; up to
      the state before a kept correction, :func:`~bodyfusion.plugins.foot_ins.smoothing_replay.replay_corrections`),
      ``gen_a`` (·, 2) the heading reset's a, ``gen_kept`` (·,) whether a kept correction was made
      there;
    * per kept correction (in order): ``kept_P`` (·, 15, 15) the covariance before it.

    Returns the covariance at i1, the largest |replayed − recorded| nominal state element and
    the entries written per stance sample, per general update and per kept correction."""
    x0, P0, memory0, _ = start
    samples, params, replay, _ = run
    _, _, gyro, stance = samples
    recorded_x, ov_idx, _, kept_idx, _, gap_idx, gap_dP = replay
    Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = store
    q_diag = process_noise_diag(params)
    work = np.empty((15, 15))
    f_n = np.empty(3)
    C_nb = np.empty((3, 3))
    scratch = np.empty(15)
    x = x0.copy()
    P = P0.copy()
    memory = memory0.copy()
    x_prior = np.empty(16)
    P_prior = np.empty((15, 15))
    no_phi = np.empty((0, 0))
    state = FilterState(x, P, memory, no_phi)
    step = StepScratch(q_diag, f_n, C_nb, work, scratch)
    ptr = np.searchsorted(ov_idx, i0 + 1)
    kptr = np.searchsorted(kept_idx, i0 + 1)
    gptr = np.searchsorted(gap_idx, i0 + 1)
    moved = np.empty(3)
    ns = ng = nk = 0
    error = 0.0
    for k in range(3):
        f_n[k] = 0.0
    record_posterior(P, f_n, 0, Pu, f_ns)
    for i in range(i0 + 1, i1 + 1):
        while gptr < gap_idx.shape[0] and gap_idx[gptr] == i:
            for r in range(15):
                for c in range(15):
                    P[r, c] += gap_dP[gptr, r, c]
            gptr += 1
        # the prior only where it is stored (stance, general update)
        nis = ekf_step(state, samples, i, params, step, x_prior, P_prior if stance[i] or general[i] else no_phi, None)
        j = i - i0
        stanced = nis != NO_STANCE
        if stanced:
            record_stance(x, x_prior, P_prior, stance_velocity_sigma(params, gyro[i], x_prior), ns, st_v, st_P)
            ns += 1
        kept = kptr < kept_idx.shape[0] and kept_idx[kptr] == i
        if kept:
            for r in range(15):
                for c in range(15):
                    kept_P[nk, r, c] = P[r, c]
            nk += 1
        ptr, kptr = replay_corrections(i, x, P, x_prior, replay, ptr, kptr, general[i], scratch, moved)
        for k in range(16):
            error = max(error, abs(x[k] - recorded_x[i, k]))
        record_posterior(P, f_n, j, Pu, f_ns)
        if general[i]:
            for r in range(15):
                for c in range(15):
                    gen_P[ng, r, c] = P_prior[r, c]
            for k in range(15):
                gen_dx[ng, k] = scratch[k]
            gen_a[ng, 0] = st_v[ns - 1, 3] if stanced else 0.0
            gen_a[ng, 1] = st_v[ns - 1, 4] if stanced else 0.0
            gen_kept[ng] = kept
            ng += 1
    return P, error, ns, ng, nk


@numba.njit(cache=True)
def _cross_error(P: np.ndarray, Z: np.ndarray, X: np.ndarray, lam_o: np.ndarray, e: np.ndarray,
                 V: np.ndarray) -> None:
    """The others' part of a jointly smoothed error, e ← e − Z lam_o (Z (15, m) the
    cross-covariance, lam_o (m,) the others' adjoint), and V = Xᵀ P[:, 0:3] (m, 3) for
    :func:`_cross_position_term`."""
    m = Z.shape[1]
    for r in range(15):
        s = 0.0
        for c in range(m):
            s += Z[r, c] * lam_o[c]
        e[r] -= s
    for c in range(m):
        for a in range(3):
            s = 0.0
            for k in range(15):
                s += X[k, c] * P[k, a]
            V[c, a] = s


@numba.njit(cache=True)
def _cross_position_term(Z: np.ndarray, V: np.ndarray, Lam_oo: np.ndarray, a: int, b: int) -> float:
    """Element (a, b) of P X Zᵀ + Z Xᵀ P + Z Lam_oo Zᵀ (V = Xᵀ P[:, 0:3]): what the others add to
    the position block of P Lam P in a joint sweep."""
    m = Z.shape[1]
    s = 0.0
    for c in range(m):
        s += V[c, a] * Z[b, c] + Z[a, c] * V[c, b]
        w = 0.0
        for k in range(m):
            w += Lam_oo[c, k] * Z[b, k]
        s += Z[a, c] * w
    return s


@numba.njit(cache=True, nogil=True)
def mbf_sweep(run: FilterRun, general: np.ndarray, i0: int, L: int, record: SweepRecord, lam: np.ndarray,
              Lam: np.ndarray, out: SmoothedOutput, write_last: bool, cross: CrossTerms) -> int:
    """The fixed-interval (RTS) smoother over samples i0 … i0 + L of the filter's ``run``, from
    what :func:`record_pass` stored (the ``record``), in the modified Bryson–Frazier form (G. J. Bierman,
    Factorization Methods for Discrete Sequential Estimation, 1977): the backward sweep
    carries the adjoint lam (15,) and Lam (15, 15) instead of a smoothed state and covariance,
    so that at each sample

        dxs_i = −P⁺_i lam_i,   Ps_i = P⁺_i − P⁺_i Lam_i P⁺_i,

    and steps back through the updates (:func:`_zupt_adjoint`; :func:`_general_adjoint` where
    ``general[i]``; a kept correction is a known input that holds no information, so the
    adjoint passes through it unchanged: the smoothed error before it is −P lam with the
    covariance ``kept_P`` the filter had before it) and the transitions (lam ← Φᵀ lam, Lam ← Φᵀ Lam Φ, Φ of
    :func:`~bodyfusion.plugins.foot_ins.kernels.transition` from the recorded state ``hist_x``
    before the step and the stored specific force): no inverse of a covariance and no process
    noise (in exact arithmetic the textbook sweep of ``rts_block``, a third of its
    operations). On entry (lam, Lam) is the adjoint at i0 + L (zeros at the end of the run), on
    return at i0. Writes out_x[i] = hist_x[i] ⊞ dxs_i and out_var[i] (variances east, north,
    up, covariance east–north of Ps_i, m²) for i0 ≤ i < i0 + L, and at i0 + L with
    ``write_last``.

    Smoothed jointly with other systems (``cross``, :class:`~bodyfusion.plugins.foot_ins.records.CrossTerms`,
    m > 0; :mod:`~bodyfusion.plugins.foot_ins.smoothing_joint`), the state and covariance are
    the stacked ones': with Z_i the filter's cross-covariance to the others (``Zs[i − i0]``),
    their adjoint lam_o and block Lam_oo, and the cross block X of the adjoint (carried back
    with this foot's steps, X ← Aᵀ X),

        dxs_i = −P⁺_i lam_i − Z_i lam_o,
        Ps_i = P⁺_i − [P⁺ Lam P⁺ + P⁺ X Zᵀ + Z Xᵀ P⁺ + Z Lam_oo Zᵀ]_i,

    and the sweep enters at i0 + L before the kept corrections there (the caller took the
    adjoint back through them, jointly).

    Returns the samples whose update could not be undone (general updates with a
    non-positive-definite prior; the sweep restarts from zero adjoints there, as ``rts_block``
    from the filter)."""
    (t, _, _, stance), params, replay, _ = run
    hist_x = replay.recorded_x
    Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = record
    X, Zs, lam_o, Lam_oo = cross
    m = X.shape[1]
    out_x, out_var = out
    q_diag = process_noise_diag(params)
    P = np.empty((15, 15))
    d = np.empty(15)
    e = np.empty(15)
    T = np.empty((3, 15))
    V = np.empty((m, 3))
    y = np.empty(16)
    zupt = ZuptScratch(np.empty((3, 4)), np.empty((15, 3)), np.empty((15, 4)), np.empty((3, 3)), np.empty((3, 3)))
    C_nb = np.empty((3, 3))
    ns, ng, nk = st_v.shape[0], gen_P.shape[0], kept_P.shape[0]
    failed = 0
    for j in range(L, -1, -1):
        i = i0 + j
        q = 0
        for r in range(15):
            for c in range(r, 15):
                v = Pu[j, q]
                P[r, c] = v
                P[c, r] = v
                q += 1
        if j < L or write_last:
            for r0 in range(0, 15, 5):
                _smoothed_error_columns(P, lam, Lam, r0, d, T)
            # position block of P Lam P: P[0:3, :] T
            q00 = q11 = q22 = q01 = 0.0
            for k in range(15):
                q00 += P[0, k] * T[0, k]
                q11 += P[1, k] * T[1, k]
                q22 += P[2, k] * T[2, k]
                q01 += P[0, k] * T[1, k]
            if m > 0:
                Z = Zs[j]
                for r in range(15):
                    e[r] = d[r]
                _cross_error(P, Z, X, lam_o, e, V)
                q00 += _cross_position_term(Z, V, Lam_oo, 0, 0)
                q11 += _cross_position_term(Z, V, Lam_oo, 1, 1)
                q22 += _cross_position_term(Z, V, Lam_oo, 2, 2)
                q01 += _cross_position_term(Z, V, Lam_oo, 0, 1)
            for k in range(16):
                y[k] = hist_x[i, k]
            inject(y, e if m > 0 else d)
            for k in range(16):
                out_x[i, k] = y[k]
            out_var[i, 0] = P[0, 0] - q00
            out_var[i, 1] = P[1, 1] - q11
            out_var[i, 2] = P[2, 2] - q22
            out_var[i, 3] = P[0, 1] - q01
        else:  # the adjoint's own smoothed error, for the update below
            for r in range(15):
                s = 0.0
                for k in range(15):
                    s += P[k, r] * lam[k]
                d[r] = -s
        if j == 0:
            break
        if general[i]:
            ng -= 1
            if gen_kept[ng]:  # a known input, no information: the adjoint passes through it
                nk -= 1
                for r in range(15):
                    dr = 0.0
                    for k in range(15):
                        P[r, k] = kept_P[nk, r, k]
                        dr -= P[r, k] * lam[k]
                    d[r] = dr
            ok = _general_adjoint(P, gen_P[ng], d, gen_dx[ng], gen_a[ng, 0], gen_a[ng, 1], lam, Lam)
            if ok and m > 0:
                ok = _cross_through_general(P, gen_P[ng], gen_a[ng, 0], gen_a[ng, 1], X)
            if not ok:
                failed += 1
                for r in range(15):
                    lam[r] = 0.0
                    for c in range(15):
                        Lam[r, c] = 0.0
                    for c in range(m):
                        X[r, c] = 0.0
        if stance[i]:
            ns -= 1
            if not general[i]:
                _zupt_adjoint(st_v[ns], st_P[ns], params, lam, Lam, X, zupt)
        quat_to_dcm_into(hist_x[i - 1, 6:10], C_nb)
        _transition_adjoint(C_nb, f_ns[j], t[i] - t[i - 1], q_diag, lam, Lam, X)
    return failed


@numba.njit(cache=True, nogil=True)
def block_sweep(run: FilterRun, general: np.ndarray, starts: np.ndarray, P_start: np.ndarray, memory: np.ndarray,
                store: SweepRecord, P_replayed: np.ndarray, out: SmoothedOutput) -> tuple[int, float]:
    """The whole-run RTS block by block from the last: block k covers samples
    ``starts[k]`` … ``starts[k + 1]`` (the last block to the run's last sample), replayed once
    by :func:`record_pass` from the filter's covariance ``P_start[k]`` (15, 15) and mechanisation
    memory ``memory[k]`` (6,) at its start into the ``store`` (sized for the
    largest block), then swept back by :func:`mbf_sweep`, the adjoint carried into the block
    before it: the sweep of the whole run, whose store holds one block. ``P_replayed[k]``
    (15, 15) receives the replayed covariance at the end of block k (the filter's
    ``P_start[k + 1]`` when the replay reproduces it). Returns the samples whose update could
    not be undone and the largest |replayed − recorded| nominal state element."""
    hist_x = run.replay.recorded_x
    Pu, f_ns, st_v, st_P, gen_P, gen_dx, gen_a, gen_kept, kept_P = store
    no_phi = np.empty((0, 0))
    lam = np.zeros(15)
    Lam = np.zeros((15, 15))
    blocks = starts.shape[0]
    failed = 0
    error = 0.0
    cross = CrossTerms(np.zeros((15, 0)), np.zeros((1, 15, 0)), np.zeros(0), np.zeros((0, 0)))  # alone
    for k in range(blocks - 1, -1, -1):
        a = starts[k]
        b = starts[k + 1] if k + 1 < blocks else hist_x.shape[0] - 1
        P_b, block_error, ns, ng, nk = record_pass(FilterState(hist_x[a], P_start[k], memory[k], no_phi), run, general,
                                                   a, b, store)
        error = max(error, block_error)
        for r in range(15):
            for c in range(15):
                P_replayed[k, r, c] = P_b[r, c]
        failed += mbf_sweep(run, general, a, b - a, SweepRecord(Pu, f_ns, st_v[:ns], st_P[:ns], gen_P[:ng], gen_dx[:ng],
                                                               gen_a[:ng], gen_kept[:ng], kept_P[:nk]), lam, Lam, out,
                            True, cross)
    return failed, error
