"""Stance-phase pseudo-measurements of the foot-mounted INS (closed loop).

* Zero-velocity update (ZUPT): during stance the true velocity is zero, so
  z = 0 − v̂_n = δv + noise, H = [0 I 0 0 0] (Foxlin 2005; OpenShoe).
* Zero angular-rate update (ZARU): during stance the true rate is zero, so
  z = ω̃_b − b̂_g = δb_g + noise, H = [0 0 0 0 I].

A stance detector is sometimes wrong (a foot rolling or shuffling, a running stance whose
edges still move): a ZUPT at a moving foot corrupts velocity, attitude and biases at once.
So every ZUPT is chi-square gated, with bounded influence rather than rejection: when the
normalised innovation squared yᵀ S⁻¹ y (3 degrees of freedom) exceeds the gate γ, the
measurement noise is raised until it equals γ (:func:`gated_noise_variance`). The
correction then shrinks like γ/|y| as the innovation grows (a foot swinging at 2 m/s moves
the state by a few per cent of what a plain ZUPT would), while a filter whose own velocity
is wrong, as after a gap or a bad start, is still pulled back at every stance sample
instead of being locked out by its own error.
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import P_ZARU_SIGMA, P_ZUPT_GATE, P_ZUPT_SIGMA, inject, nis_selected, update_selected


@numba.njit(cache=True)
def gated_noise_variance(P: np.ndarray, first: int, y: np.ndarray, r_var: float, gate: float) -> float:
    """The noise variance (isotropic, unit of y squared) of a 3-D measurement selecting
    states first:first+3: ``r_var`` when its NIS is within ``gate`` (or the gate is off, 0),
    else the r ≥ r_var with yᵀ (P_sel + r I)⁻¹ y = gate (the NIS falls monotonically in r;
    bisection on log r to 1e-6 relative)."""
    if gate <= 0.0 or nis_selected(P, first, y, r_var) <= gate:
        return r_var
    lo = r_var
    hi = max(r_var, (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) / gate)  # NIS(hi) ≤ |y|²/hi = gate
    while nis_selected(P, first, y, hi) > gate:
        hi *= 2.0
    for _ in range(60):
        if hi <= lo * (1.0 + 1e-6):
            break
        mid = np.sqrt(lo * hi)
        if nis_selected(P, first, y, mid) > gate:
            lo = mid
        else:
            hi = mid
    return hi


@numba.njit(cache=True)
def zero_velocity_update(x: np.ndarray, P: np.ndarray, sigma_v: float, gate: float, dx: np.ndarray,
                         phi: np.ndarray) -> float:
    """Gated ZUPT with noise σ_v (m/s) and chi-square gate ``gate`` (0: off); corrects x and
    P (and the transition accumulator phi, see :func:`bodyfusion.nav.error_state.update_selected`) in
    place; returns the NIS before gating (the caller counts NIS > gate as gated)."""
    y = np.empty(3)
    for k in range(3):
        y[k] = -x[3 + k]
    nis = nis_selected(P, np.int64(3), y, sigma_v * sigma_v)
    r_var = gated_noise_variance(P, np.int64(3), y, sigma_v * sigma_v, gate)
    update_selected(P, np.int64(3), y, r_var, dx, phi)
    inject(x, dx)
    return nis

@numba.njit(cache=True)
def zero_angular_rate_update(x: np.ndarray, P: np.ndarray, gyro_b: np.ndarray, sigma_w: float,
                             dx: np.ndarray, phi: np.ndarray) -> float:
    """ZARU with noise σ_w (rad/s); corrects x, P and phi in place; returns the NIS."""
    y = np.empty(3)
    for k in range(3):
        y[k] = gyro_b[k] - x[13 + k]
    nis = update_selected(P, np.int64(12), y, sigma_w * sigma_w, dx, phi)
    inject(x, dx)
    return nis


@numba.njit(cache=True)
def stance_update(x: np.ndarray, P: np.ndarray, gyro_b: np.ndarray, params: np.ndarray, dx: np.ndarray,
                  phi: np.ndarray) -> float:
    """The update of a stance sample with the filter parameters ``params`` (layout in
    :mod:`bodyfusion.nav.error_state`): the gated ZUPT, then, when its NIS is within the gate and
    the ZARU σ > 0, the ZARU with the sample's angular rate ``gyro_b`` (rad/s). Returns the
    ZUPT's NIS before gating."""
    nis = zero_velocity_update(x, P, params[P_ZUPT_SIGMA], params[P_ZUPT_GATE], dx, phi)
    if params[P_ZARU_SIGMA] > 0 and (params[P_ZUPT_GATE] <= 0.0 or nis <= params[P_ZUPT_GATE]):
        zero_angular_rate_update(x, P, gyro_b, params[P_ZARU_SIGMA], dx, phi)
    return nis
