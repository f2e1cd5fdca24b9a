"""Compiled per-sample loop of the foot-mounted INS: strapdown, covariance propagation, ZUPT/ZARU.

The ``ekf`` (:func:`run_foot_ins`) and the ``ckf`` (:func:`run_foot_ins_coloured`) share the
per-sample steps; the ckf replaces the ZUPT at every stance sample whose previous sample was
also a stance update by the coloured-noise update of :mod:`fusion_plugins.foot_ins.coloured`.
The first stance sample of a stance phase has no previous measurement to difference with and
takes the ordinary ZUPT.
"""

from __future__ import annotations

import numba
import numpy as np

from fusion.error_state import (P_GRAVITY, P_ZARU_SIGMA, P_ZUPT_SIGMA, accumulate_propagation,
                                process_noise_diag, propagate_covariance)
from fusion.strapdown import mechanise
from fusion.zupt import zero_angular_rate_update, zero_velocity_update
from fusion_plugins.foot_ins.coloured import coloured_zero_velocity_update

# Layout of the ``counters`` vector.
C_ZUPTS, C_ZARUS, C_NIS_SUM, C_COLOURED = range(4)
COUNTERS_SIZE = 4


def differenced_samples(stance: np.ndarray, i0: int, i1: int) -> np.ndarray:
    """Indices i0 ≤ i < i1 (i0 ≥ 1) where the ckf applies the differenced (coloured) update:
    stance at i and at i − 1, and i − 1 ≥ 1 (sample 0 is the initial state, not an update)."""
    i = np.arange(max(i0, 2), i1)
    return i[stance[i] & stance[i - 1]]


@numba.njit(inline="always")
def _propagate_sample(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                      i: int, params: np.ndarray, q_diag: np.ndarray, f_n: np.ndarray, mech_memory: np.ndarray,
                      phi: np.ndarray, work: np.ndarray) -> np.ndarray:
    """Mechanise sample i (from t[i-1] to t[i]) and propagate P (and Φ when tracked);
    returns C_nb (3, 3) of the step, f_n (3,) is left in ``f_n``."""
    dt = t[i] - t[i - 1]
    C = mechanise(x, acc_b[i], gyro_b[i], dt, params[P_GRAVITY], params[7:10], f_n, mech_memory)
    if phi.shape[0] > 0:
        accumulate_propagation(phi, C, f_n, dt, work[0])
    propagate_covariance(P, C, f_n, dt, q_diag, work)
    return C


@numba.njit(inline="always")
def _angular_rate_update_and_count(x: np.ndarray, P: np.ndarray, gyro_b_i: np.ndarray, params: np.ndarray,
                                   dx: np.ndarray, phi: np.ndarray, counters: np.ndarray) -> None:
    """After a stance sample's ZUPT: the ZARU when its σ > 0, and the counters."""
    counters[C_ZUPTS] += 1
    if params[P_ZARU_SIGMA] > 0:
        zero_angular_rate_update(x, P, gyro_b_i, params[P_ZARU_SIGMA], dx, phi)
        counters[C_ZARUS] += 1


@numba.njit(inline="always")
def _record_sample(x: np.ndarray, P: np.ndarray, i: int, hist_x: np.ndarray, hist_pos_var: np.ndarray) -> None:
    for k in range(16):
        hist_x[i, k] = x[k]
    for k in range(3):
        hist_pos_var[i, k] = P[k, k]


@numba.njit(cache=True)
def run_foot_ins(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                 stance: np.ndarray, i0: int, i1: int, params: np.ndarray, mech_memory: np.ndarray,
                 phi: np.ndarray, hist_x: np.ndarray, hist_pos_var: np.ndarray, counters: np.ndarray) -> None:
    """The ``ekf``: process samples i0 ≤ i < i1 (i0 ≥ 1): mechanise from t[i-1] to t[i],
    propagate P, and at stance samples apply the ZUPT (and the ZARU when its σ > 0).

    x (16,) nominal state, P (15, 15) and ``mech_memory`` (6,) (the previous step's
    increments, see :func:`fusion.strapdown.mechanise`) are updated in place; row i of ``hist_x`` and
    ``hist_pos_var`` receives the state and the position variances (m^2) after sample i.
    ``counters`` accumulates [ZUPTs, ZARUs, sum of ZUPT NIS, coloured updates]. ``phi`` (15, 15)
    accumulates the error-state transition for the fuser's cross-covariances (empty (0, 0): off).
    """
    q_diag = process_noise_diag(params)
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    dx = np.empty(15)
    for i in range(i0, i1):
        _propagate_sample(x, P, t, acc_b, gyro_b, i, params, q_diag, f_n, mech_memory, phi, work)
        if stance[i]:
            counters[C_NIS_SUM] += zero_velocity_update(x, P, params[P_ZUPT_SIGMA], dx, phi)
            _angular_rate_update_and_count(x, P, gyro_b[i], params, dx, phi, counters)
        _record_sample(x, P, i, hist_x, hist_pos_var)


@numba.njit(cache=True)
def run_foot_ins_coloured(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                          stance: np.ndarray, i0: int, i1: int, params: np.ndarray, alpha: float,
                          mech_memory: np.ndarray, phi: np.ndarray, hist_x: np.ndarray, hist_pos_var: np.ndarray,
                          counters: np.ndarray, post_P: np.ndarray) -> None:
    """The ``ckf`` with colour factor α: as :func:`run_foot_ins`, with the coloured-noise
    update at the :func:`differenced_samples` (a separate entry point, so that the ekf does
    not compile it). The posterior covariance after each coloured update is written, in
    order, to ``post_P`` (K, 15, 15), K the number of differenced samples in the chunk
    (the smoother's record)."""
    q_diag = process_noise_diag(params)
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    dx = np.empty(15)
    v_prev = np.empty(3)
    n_post = 0
    for i in range(i0, i1):
        for k in range(3):
            v_prev[k] = x[3 + k]
        C = _propagate_sample(x, P, t, acc_b, gyro_b, i, params, q_diag, f_n, mech_memory, phi, work)
        if stance[i]:
            coloured = stance[i - 1] and i >= 2
            if coloured:
                counters[C_NIS_SUM] += coloured_zero_velocity_update(x, P, v_prev, C, f_n, t[i] - t[i - 1], q_diag,
                                                                     alpha, params[P_ZUPT_SIGMA], dx, phi)
                counters[C_COLOURED] += 1
            else:
                counters[C_NIS_SUM] += zero_velocity_update(x, P, params[P_ZUPT_SIGMA], dx, phi)
            _angular_rate_update_and_count(x, P, gyro_b[i], params, dx, phi, counters)
            if coloured:
                for r in range(15):
                    for c in range(15):
                        post_P[n_post, r, c] = P[r, c]
                n_post += 1
        _record_sample(x, P, i, hist_x, hist_pos_var)
