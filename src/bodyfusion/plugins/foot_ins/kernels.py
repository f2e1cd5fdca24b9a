"""Compiled per-sample loop of the foot-mounted INS: strapdown, covariance propagation, ZUPT/ZARU.

The ``ekf`` (:func:`run_foot_ins`) and the ``ckf`` (:func:`run_foot_ins_coloured`) share the
per-sample steps; the ckf replaces the ZUPT at every stance sample whose previous sample was
also updated by the coloured-noise update of :mod:`bodyfusion.plugins.foot_ins.coloured`. The
first stance sample of a stance phase has no previous measurement to difference with and
takes the ordinary ZUPT, with the stationary variance of the AR(1) noise
v_k = α v_{k−1} + ξ_k, R = σ_ξ² / (1 − α²) (:func:`stationary_zupt_params`).

Every stance update is chi-square gated with bounded influence (``params[P_ZUPT_GATE]``,
0: off; :mod:`bodyfusion.nav.zupt`): a stance sample whose NIS exceeds the gate is counted and
de-weighted, and gets no ZARU (the foot is not at rest there).
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import (P_GRAVITY, P_ZARU_SIGMA, P_ZUPT_GATE, P_ZUPT_SIGMA, accumulate_propagation,
                                       decay_bias_rows, decay_biases, process_noise_diag, propagate_covariance)
from bodyfusion.nav.strapdown import mechanise
from bodyfusion.nav.zupt import stance_update, zero_angular_rate_update
from bodyfusion.plugins.foot_ins.coloured import coloured_zero_velocity_update

# Layout of the ``counters`` vector: updates, NIS sum (before gating), the
# gated (de-weighted) stance samples, the coloured updates, and the ckf's stance updates
# recorded by this call.
C_ZUPTS, C_ZARUS, C_NIS_SUM, C_COLOURED, C_GATED, C_CALL_RECORDS = range(6)
COUNTERS_SIZE = 6


@numba.njit(cache=True)
def stationary_zupt_params(params: np.ndarray, alpha: float) -> np.ndarray:
    """``params`` with the ZUPT σ of the ordinary update under AR(1) noise of colour factor α:
    the stationary σ_ξ / √(1 − α²) of v_k = α v_{k−1} + ξ_k (σ_ξ = ``params[P_ZUPT_SIGMA]``)."""
    out = params.copy()
    out[P_ZUPT_SIGMA] = params[P_ZUPT_SIGMA] / np.sqrt(1.0 - alpha * alpha)
    return out


@numba.njit(inline="always")
def _propagate_sample(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                      i: int, params: np.ndarray, q_diag: np.ndarray, f_n: np.ndarray, mech_memory: np.ndarray,
                      phi: np.ndarray, work: np.ndarray) -> np.ndarray:
    """Mechanise sample i (from t[i-1] to t[i]), decay the bias estimates and propagate P
    (and Φ when tracked); returns C_nb (3, 3) of the step, f_n (3,) is left in ``f_n``."""
    dt = t[i] - t[i - 1]
    C = mechanise(x, acc_b[i], gyro_b[i], dt, params[P_GRAVITY], params[7:10], f_n, mech_memory)
    decay_biases(x, q_diag, dt)
    if phi.shape[0] > 0:
        accumulate_propagation(phi, C, f_n, dt, work[0])
        decay_bias_rows(phi, q_diag, dt)
    propagate_covariance(P, C, f_n, dt, q_diag, work)
    return C


@numba.njit(inline="always")
def _count(params: np.ndarray, nis: float, counters: np.ndarray) -> None:
    """Count a stance sample's updates: ZUPT, its NIS, gated or ZARU."""
    counters[C_ZUPTS] += 1
    counters[C_NIS_SUM] += nis
    if params[P_ZUPT_GATE] > 0.0 and nis > params[P_ZUPT_GATE]:
        counters[C_GATED] += 1
    elif params[P_ZARU_SIGMA] > 0:
        counters[C_ZARUS] += 1


@numba.njit(inline="always")
def _record_sample(x: np.ndarray, P: np.ndarray, i: int, hist_x: np.ndarray, hist_pos_cov: np.ndarray) -> None:
    for k in range(16):
        hist_x[i, k] = x[k]
    for k in range(3):
        hist_pos_cov[i, k] = P[k, k]
    hist_pos_cov[i, 3] = P[0, 1]


@numba.njit(cache=True)
def run_foot_ins(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                 stance: np.ndarray, i0: int, i1: int, params: np.ndarray, mech_memory: np.ndarray,
                 phi: np.ndarray, hist_x: np.ndarray, hist_pos_cov: np.ndarray, counters: np.ndarray) -> None:
    """The ``ekf``: process samples i0 ≤ i < i1 (i0 ≥ 1): mechanise from t[i-1] to t[i],
    propagate P, and at stance samples apply the gated ZUPT (and the ZARU when its σ > 0).

    x (16,) nominal state, P (15, 15) and ``mech_memory`` (6,) (the previous step's
    increments, see :func:`bodyfusion.nav.strapdown.mechanise`) are updated in place; row i of ``hist_x`` and
    ``hist_pos_cov`` (N, 4) receives the state and the position covariance after sample i
    (variances east, north, up and the east–north covariance, m^2).
    ``counters`` accumulates (layout ``C_*``). ``phi`` (15, 15) accumulates the error-state
    transition for the fuser's cross-covariances (empty (0, 0): off).
    """
    q_diag = process_noise_diag(params)
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    dx = np.empty(15)
    for i in range(i0, i1):
        _propagate_sample(x, P, t, acc_b, gyro_b, i, params, q_diag, f_n, mech_memory, phi, work)
        if stance[i]:
            _count(params, stance_update(x, P, gyro_b[i], params, dx, phi), counters)
        _record_sample(x, P, i, hist_x, hist_pos_cov)


@numba.njit(cache=True)
def run_foot_ins_coloured(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                          stance: np.ndarray, i0: int, i1: int, params: np.ndarray, alpha: float,
                          mech_memory: np.ndarray, phi: np.ndarray, hist_x: np.ndarray, hist_pos_cov: np.ndarray,
                          counters: np.ndarray, post_idx: np.ndarray, post_P: np.ndarray) -> None:
    """The ``ckf`` with colour factor α: as :func:`run_foot_ins`, with the coloured-noise
    update at every stance sample i ≥ 2 whose previous sample was stance too (a separate
    entry point, so that the ekf does not compile it). The other stance samples, and a
    differenced sample whose coloured NIS exceeds the gate, take the gated ordinary ZUPT with
    the stationary σ (:func:`stationary_zupt_params`). Neither is what the smoothers rebuild
    (the ZUPT with σ_ξ), so the index and posterior covariance of every stance update are
    written, in order, to ``post_idx`` (K,) and ``post_P`` (K, 15, 15), K the stance samples
    of the chunk; ``counters[C_CALL_RECORDS]`` says how many were written."""
    q_diag = process_noise_diag(params)
    ordinary = stationary_zupt_params(params, alpha)
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    dx = np.empty(15)
    v_prev = np.empty(3)
    gate = params[P_ZUPT_GATE]
    counters[C_CALL_RECORDS] = 0
    for i in range(i0, i1):
        for k in range(3):
            v_prev[k] = x[3 + k]
        C = _propagate_sample(x, P, t, acc_b, gyro_b, i, params, q_diag, f_n, mech_memory, phi, work)
        if stance[i]:
            coloured = False
            nis = 0.0
            if stance[i - 1] and i >= 2:
                nis = coloured_zero_velocity_update(x, P, v_prev, C, f_n, t[i] - t[i - 1], q_diag, alpha,
                                                    params[P_ZUPT_SIGMA], gate, dx, phi)
                coloured = gate <= 0.0 or nis <= gate
                if coloured and params[P_ZARU_SIGMA] > 0:
                    zero_angular_rate_update(x, P, gyro_b[i], params[P_ZARU_SIGMA], dx, phi)
            if not coloured:
                nis = stance_update(x, P, gyro_b[i], ordinary, dx, phi)
            _count(params, nis, counters)
            if coloured:
                counters[C_COLOURED] += 1
            n_post = int(counters[C_CALL_RECORDS])
            post_idx[n_post] = i
            for r in range(15):
                for c in range(15):
                    post_P[n_post, r, c] = P[r, c]
            counters[C_CALL_RECORDS] += 1
        _record_sample(x, P, i, hist_x, hist_pos_cov)
