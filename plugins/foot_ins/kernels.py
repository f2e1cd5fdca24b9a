"""Compiled per-sample loop of the foot-mounted INS: strapdown, covariance propagation, ZUPT/ZARU."""

from __future__ import annotations

import numba
import numpy as np

from fusion.error_state import (P_GRAVITY, P_ZARU_SIGMA, P_ZUPT_SIGMA, accumulate_propagation,
                                process_noise_diag, propagate_covariance)
from fusion.strapdown import mechanise
from fusion.zupt import zero_angular_rate_update, zero_velocity_update

# Layout of the ``counters`` vector.
C_ZUPTS, C_ZARUS, C_NIS_SUM = range(3)


@numba.njit(cache=True)
def run_foot_ins(x: np.ndarray, P: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray,
                 stance: np.ndarray, i0: int, i1: int, params: np.ndarray, mech_memory: np.ndarray,
                 phi: np.ndarray, hist_x: np.ndarray, hist_pos_var: np.ndarray, counters: np.ndarray) -> None:
    """Process samples i0 ≤ i < i1 (i0 ≥ 1): mechanise from t[i-1] to t[i], propagate P,
    and at stance samples apply the ZUPT (and the ZARU when its σ > 0).

    x (16,) nominal state, P (15, 15) and ``mech_memory`` (6,) (the previous step's
    increments, see :func:`fusion.strapdown.mechanise`) are updated in place; row i of ``hist_x`` and
    ``hist_pos_var`` receives the state and the position variances (m^2) after sample i.
    ``counters`` accumulates [ZUPTs, ZARUs, sum of ZUPT NIS]. ``phi`` (15, 15) accumulates
    the error-state transition for the fuser's cross-covariances (empty (0, 0): off).
    """
    q_diag = process_noise_diag(params)
    g = params[P_GRAVITY]
    w_ie = params[7:10].copy()
    zupt_sigma = params[P_ZUPT_SIGMA]
    zaru_sigma = params[P_ZARU_SIGMA]
    work = np.empty((2, 15, 15))
    f_n = np.empty(3)
    dx = np.empty(15)
    for i in range(i0, i1):
        dt = t[i] - t[i - 1]
        C = mechanise(x, acc_b[i], gyro_b[i], dt, g, w_ie, f_n, mech_memory)
        if phi.shape[0] > 0:
            accumulate_propagation(phi, C, f_n, dt, work[0])
        propagate_covariance(P, C, f_n, dt, q_diag, work)
        if stance[i]:
            counters[C_NIS_SUM] += zero_velocity_update(x, P, zupt_sigma, dx, phi)
            counters[C_ZUPTS] += 1
            if zaru_sigma > 0:
                zero_angular_rate_update(x, P, gyro_b[i], zaru_sigma, dx, phi)
                counters[C_ZARUS] += 1
        for k in range(16):
            hist_x[i, k] = x[k]
        for k in range(3):
            hist_pos_var[i, k] = P[k, k]
