"""Stance-phase pseudo-measurements of the foot-mounted INS (closed loop).

* Zero-velocity update (ZUPT): during stance the true velocity is zero, so
  z = 0 − v̂_n = δv + noise, H = [0 I 0 0 0] (Foxlin 2005; OpenShoe).
* Zero angular-rate update (ZARU): during stance the true rate is zero, so
  z = ω̃_b − b̂_g = δb_g + noise, H = [0 0 0 0 I].
"""

from __future__ import annotations

import numba
import numpy as np

from fusion.error_state import inject, update_selected


@numba.njit(cache=True)
def zero_velocity_update(x: np.ndarray, P: np.ndarray, sigma_v: float, dx: np.ndarray, phi: np.ndarray) -> float:
    """ZUPT with noise σ_v (m/s); corrects x and P (and the transition accumulator phi,
    see :func:`fusion.error_state.update_selected`) in place; returns the NIS."""
    y = np.empty(3)
    for k in range(3):
        y[k] = -x[3 + k]
    nis = update_selected(P, np.int64(3), y, sigma_v * sigma_v, dx, phi)
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
