"""Stance-phase pseudo-measurements of the foot-mounted INS (closed loop).

* Zero-velocity update (ZUPT): during stance the true velocity is zero, so
  z = 0 − v̂_n = δv + noise (Foxlin 2005; OpenShoe).
* Zero angular-rate update (ZARU): during stance the true rate is zero, so
  z = ω̃_b − b̂_g = δb_g + noise, H = [0 0 0 0 I].

Heading stays unobservable (observability-constrained EKF, [Hesch2014]). Turning the
whole state about Up by δψ moves the error state along N(x̂) = [e_z × p̂; e_z × v̂; e_z; 0; 0],
and a foot at rest stays at rest: no stance measurement holds heading. The EKF linearised at
the estimate does not know it: with H = [0 I 0 0 0], H N = e_z × v̂⁻ ≠ 0 whenever the prior
velocity is not exactly zero (sensor noise, level error times g), and every stance sample
then "measures" heading. Over an hour the reported heading σ stayed near 2° while the real
error reached 20°. So the ZUPT's Jacobian takes the yaw column that makes H N(x̂⁻) = 0,

    H = [0  I  (v̂_N, −v̂_E, 0)ᵀ on δψ  0  0]   (δv − δψ e_z × v̂: the velocity error a
                                               rotation about Up does not explain),

and every stance correction ends with the reset of
:func:`bodyfusion.nav.error_state.keep_yaw_unobservable`, which carries N(x̂⁻) to N(x̂⁺).

A stance detector is sometimes wrong (a foot rolling or shuffling, a running stance whose
edges still move): a ZUPT at a moving foot corrupts velocity, attitude and biases at once.
So every ZUPT is chi-square gated, with bounded influence rather than rejection: when the
normalised innovation squared yᵀ S⁻¹ y (3 degrees of freedom) exceeds the gate γ, the
measurement noise is raised until it equals γ (:func:`gated_variance`). The
correction then shrinks like γ/|y| as the innovation grows (a foot swinging at 2 m/s moves
the state by a few per cent of what a plain ZUPT would), while a filter whose own velocity
is wrong, as after a gap or a bad start, is still pulled back at every stance sample
instead of being locked out by its own error.
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import FilterParams, inject, keep_yaw_unobservable
from bodyfusion.nav.kalman import nis3, selection_moments, selection_update

ZUPT_COLUMNS = np.array([3, 4, 5, 8], dtype=np.int64)
"""The error states a ZUPT's Jacobian touches: δv (3:6) and the heading δψ (8)."""


@numba.njit(cache=True)
def gated_variance(S0: tuple[float, float, float, float, float, float], y: tuple[float, float, float], r_var: float,
                   gate: float) -> float:
    """The noise variance (isotropic, unit of y squared) of a 3-D measurement with
    H P Hᵀ = ``S0`` (its upper triangle, :func:`bodyfusion.nav.kalman.nis3`) and
    innovation y: ``r_var`` when its NIS is within ``gate`` (or the gate is off, 0), else the
    r ≥ r_var with yᵀ (S0 + r I)⁻¹ y = gate (the NIS falls monotonically in r; bisection on
    log r to 1e-6 relative)."""
    if gate <= 0.0 or nis3(S0, r_var, y) <= gate:
        return r_var
    lo = r_var
    hi = max(r_var, (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) / gate)  # NIS(hi) ≤ |y|²/hi = gate
    while nis3(S0, hi, y) > gate:
        hi *= 2.0
    for _ in range(60):
        if hi <= lo * (1.0 + 1e-6):
            break
        mid = np.sqrt(lo * hi)
        if nis3(S0, mid, y) > gate:
            lo = mid
        else:
            hi = mid
    return hi


@numba.njit(cache=True)
def gated_noise_variance(P: np.ndarray, first: int, y: np.ndarray, r_var: float, gate: float) -> float:
    """:func:`gated_variance` of a 3-D measurement selecting states first:first+3."""
    S0 = selection_moments(P, first, (0.0, 0.0, 0.0), np.empty((15, 15)))
    return gated_variance(S0, (y[0], y[1], y[2]), r_var, gate)


@numba.njit(cache=True)
def unobservable_yaw_column(H_v: np.ndarray, v: np.ndarray, out: np.ndarray) -> None:
    """out (3,) = −H_v (e_z × v): the heading column of a stance measurement whose velocity
    columns are H_v (3, 3) (and position columns zero), so that H N(x̂) = 0 at the velocity
    v (m/s) of the linearisation point (module docstring)."""
    u0, u1 = -v[1], v[0]
    for r in range(3):
        out[r] = -(H_v[r, 0] * u0 + H_v[r, 1] * u1)


@numba.njit(cache=True)
def zero_velocity_update(x: np.ndarray, P: np.ndarray, sigma_v: float, gate: float, dx: np.ndarray,
                         phi: np.ndarray, work: np.ndarray) -> float:
    """Gated ZUPT with noise σ_v (m/s) and chi-square gate ``gate`` (0: off): y = −v̂ (m/s),
    H = [0 I h 0 0] with the heading column h = −(e_z × v̂) = (v̂_N, −v̂_E, 0) of the prior
    velocity (:func:`unobservable_yaw_column` of H_v = I; module docstring). Corrects x and P
    (and the transition accumulator phi) in place by
    :func:`bodyfusion.nav.kalman.selection_update` (``work`` (15, 15) scratch), then the
    reset of :func:`bodyfusion.nav.error_state.keep_yaw_unobservable`; returns the NIS before
    gating (the caller counts NIS > gate as gated)."""
    y = (-x[3], -x[4], -x[5])
    h = (x[4], -x[3], 0.0)
    first = np.int64(3)  # not a bare 3: numba types a constant argument as a literal, one compilation per value
    S0 = selection_moments(P, first, h, work)
    r_var = sigma_v * sigma_v
    nis = nis3(S0, r_var, y)
    selection_update(P, first, h, S0, gated_variance(S0, y, r_var, gate), y, dx, phi, work)
    keep_yaw_unobservable(P, dx[3:6], phi)
    inject(x, dx)
    return nis


@numba.njit(cache=True)
def zero_angular_rate_update(x: np.ndarray, P: np.ndarray, gyro_b: np.ndarray, sigma_w: float,
                             dx: np.ndarray, phi: np.ndarray, work: np.ndarray) -> float:
    """ZARU with noise σ_w (rad/s): y = ω̃_b − b̂_g, H = [0 0 0 0 I]; corrects x, P and phi in
    place (``work`` (15, 15) scratch; with the reset of
    :func:`bodyfusion.nav.error_state.keep_yaw_unobservable`); returns the NIS."""
    y = (gyro_b[0] - x[13], gyro_b[1] - x[14], gyro_b[2] - x[15])
    h = (0.0, 0.0, 0.0)
    first = np.int64(12)  # not a literal (zero_velocity_update)
    S = selection_moments(P, first, h, work)
    nis = selection_update(P, first, h, S, sigma_w * sigma_w, y, dx, phi, work)
    keep_yaw_unobservable(P, dx[3:6], phi)
    inject(x, dx)
    return nis


@numba.njit(cache=True)
def stance_velocity_sigma(params: FilterParams, gyro_b: np.ndarray, x: np.ndarray) -> float:
    """σ (m/s) of a stance sample's zero velocity: √(σ_v² + (r |ω̃_b − b̂_g|)²), a foot rolling
    at ω about a pivot r = ``params.zupt_pivot`` m from the IMU moves it at up to r |ω|."""
    r = params.zupt_pivot
    w0 = gyro_b[0] - x[13]
    w1 = gyro_b[1] - x[14]
    w2 = gyro_b[2] - x[15]
    return np.sqrt(params.zupt_sigma ** 2 + r * r * (w0 * w0 + w1 * w1 + w2 * w2))


@numba.njit(cache=True)
def stance_update(x: np.ndarray, P: np.ndarray, gyro_b: np.ndarray, params: FilterParams, dx: np.ndarray,
                  phi: np.ndarray, work: np.ndarray) -> float:
    """The update of a stance sample with the filter parameters ``params`` (layout in
    :mod:`bodyfusion.nav.error_state`): the gated ZUPT, then, when its NIS is within the gate and
    the ZARU σ > 0, the ZARU with the sample's angular rate ``gyro_b`` (rad/s); ``work``
    (15, 15) scratch. Returns the ZUPT's NIS before gating."""
    nis = zero_velocity_update(x, P, stance_velocity_sigma(params, gyro_b, x), params.zupt_gate, dx, phi, work)
    if params.zaru_sigma > 0 and (params.zupt_gate <= 0.0 or nis <= params.zupt_gate):
        zero_angular_rate_update(x, P, gyro_b, params.zaru_sigma, dx, phi, work)
    return nis
