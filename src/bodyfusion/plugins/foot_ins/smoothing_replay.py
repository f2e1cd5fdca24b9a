"""The filter replayed over a block, for the smoothers (:mod:`bodyfusion.plugins.foot_ins.smoothing`),
[Shen2025] §3.

Every pass steps the filter's own per-sample recursion,
:func:`bodyfusion.plugins.foot_ins.kernels.ekf_step` (mechanisation, covariance propagation,
gated ZUPT/ZARU), and repeats what the filter did outside its compiled loop: the covariance
rebuild of the forward filter and the backward navigation cannot drift from the filter.

Block buffers (:class:`~bodyfusion.plugins.foot_ins.records.PassBuffers`, float64), j = 0 … L
over the samples of one block in the pass's own time order (forward j = i − a; backward
j = b − i): ``xs`` (L+1, 16) posterior and ``xp`` (L+1, 16) prior nominal states, ``Ppost`` /
``Pprior`` (L+1, 15, 15) posterior / prior covariances, ``Phi`` (L+1, 15, 15) the transition
from j−1 to j, ``dx`` (L+1, 15) the correction injected at j (posterior ⊖ prior nominal),
``jump`` (L+1, 3) the position moved by a correction made outside the filter's loop. Only one
block is held at a time: O(longest block) memory, never N×15×15 (the whole-run RTS stores
less: :mod:`bodyfusion.plugins.foot_ins.smoothing_mbf`). Scalar loops only (array expressions
cost numba compile time).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.nav.attitude import quat_multiply
from bodyfusion.nav.error_state import FilterParams, process_noise_diag
from bodyfusion.plugins.foot_ins.kernels import NO_STANCE, ekf_step
from bodyfusion.plugins.foot_ins.records import FilterReplay, FilterState, ImuSamples, PassBuffers, StepScratch


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


@numba.njit(cache=True, nogil=True)
def filter_pass(start: FilterState, samples: ImuSamples, params: FilterParams, i0: int, i1: int, replay: FilterReplay,
                store: bool, buffers: PassBuffers) -> np.ndarray:
    """The ekf over i0 < i ≤ i1 (:func:`~bodyfusion.plugins.foot_ins.kernels.ekf_step`) from
    the nominal state x0 (16,), covariance P0 (15, 15) and mechanisation memory ``memory0``
    (6,) at i0 (the ``start``, left as it is), replaying what the filter did outside its compiled
    loop (the ``replay``):

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
    x0, P0, memory0, _ = start
    recorded_x, ov_idx, ov_P, kept_idx, kept_x, gap_idx, gap_dP = replay
    xs, xp, Ppost, Pprior, Phi, dx, jump, yaw_reset = buffers
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
    state = FilterState(x, P, memory, no_phi)
    step = StepScratch(q_diag, f_n, C_nb, work, scratch)
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
        nis = ekf_step(state, samples, i, params, step, x_prior_j, P_prior_j, Phi_j)
        if store:
            stanced = nis != NO_STANCE
            yaw_reset[j, 0] = -(x[4] - x_prior_j[4]) if stanced else 0.0
            yaw_reset[j, 1] = (x[3] - x_prior_j[3]) if stanced else 0.0
        ptr, kptr = replay_corrections(i, x, P, x_prior_j, replay, ptr, kptr, store, scratch, moved)
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
def replay_corrections(i: int, x: np.ndarray, P: np.ndarray, x_prior: np.ndarray, replay: FilterReplay, ptr: int,
                       kptr: int, want_dx: bool, dx: np.ndarray, moved: np.ndarray) -> tuple[int, int]:
    """After the filter's step to sample i (x, P its posterior in place, x_prior its prior): the
    corrections the filter made outside its loop at i (the ``replay``), from the pointers ``ptr``
    into the sorted ``ov_idx`` and ``kptr`` into the sorted ``kept_idx``. With an override at i the
    state becomes the recorded one and the covariance the last one left at i; ``moved`` (3,)
    gets the position it moved (m; zero without one). With ``want_dx``, ``dx`` (15,) gets the
    update the smoothers step through at i: posterior ⊖ prior; where a kept correction was made
    at i — one derived from other systems' estimates (a distance constraint), which a
    per-system smoother cannot re-derive from their smoothed estimates and so keeps as the
    filter made it — the state before it (``kept_x``) ⊖ prior: the jump is then a known input
    of the smoothed model, not information. Returns the advanced pointers."""
    recorded_x, ov_idx, ov_P, kept_idx, kept_x, _, _ = replay
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
