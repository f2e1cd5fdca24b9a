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
measurement noise is raised until it equals γ (:func:`gate_noise_variance`). The
correction then shrinks like γ/|y| as the innovation grows (a foot swinging at 2 m/s moves
the state by a few per cent of what a plain ZUPT would), while a filter whose own velocity
is wrong, as after a gap or a bad start, is still pulled back at every stance sample
instead of being locked out by its own error.
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import (P_ZARU_SIGMA, P_ZUPT_GATE, P_ZUPT_SIGMA, inject, innovation_covariance,
                                       keep_yaw_unobservable, quadratic_inverse, update_columns, update_selected)

ZUPT_COLUMNS = np.array([3, 4, 5, 8], dtype=np.int64)
"""The error states a ZUPT's Jacobian touches: δv (3:6) and the heading δψ (8). Kernels take
a writable copy: numba types a global array as read-only, and a kernel given both read-only
and writable index arrays compiles twice."""


@numba.njit(cache=True)
def _nis_with_noise(S0: np.ndarray, y: np.ndarray, r_var: float) -> float:
    S = S0.copy()
    for k in range(3):
        S[k, k] += r_var
    return quadratic_inverse(S, y)


@numba.njit(cache=True)
def gate_noise_variance(S0: np.ndarray, y: np.ndarray, r_var: float, gate: float) -> float:
    """The noise variance (isotropic, unit of y squared) of a 3-D measurement with
    H P Hᵀ = ``S0`` (3, 3): ``r_var`` when its NIS is within ``gate`` (or the gate is off, 0),
    else the r ≥ r_var with yᵀ (S0 + r I)⁻¹ y = gate (the NIS falls monotonically in r;
    bisection on log r to 1e-6 relative)."""
    if gate <= 0.0 or _nis_with_noise(S0, y, r_var) <= gate:
        return r_var
    lo = r_var
    hi = max(r_var, (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]) / gate)  # NIS(hi) ≤ |y|²/hi = gate
    while _nis_with_noise(S0, y, hi) > gate:
        hi *= 2.0
    for _ in range(60):
        if hi <= lo * (1.0 + 1e-6):
            break
        mid = np.sqrt(lo * hi)
        if _nis_with_noise(S0, y, mid) > gate:
            lo = mid
        else:
            hi = mid
    return hi


@numba.njit(cache=True)
def gated_noise_variance(P: np.ndarray, first: int, y: np.ndarray, r_var: float, gate: float) -> float:
    """:func:`gate_noise_variance` of a 3-D measurement selecting states first:first+3."""
    cols, Hc = np.empty(3, np.int64), np.zeros((3, 3))
    for k in range(3):  # the selection H = [0 I 0], as update_selected writes it
        cols[k] = first + k
        Hc[k, k] = 1.0
    return gate_noise_variance(innovation_covariance(P, cols, Hc, 0.0), y, r_var, gate)


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
                         phi: np.ndarray) -> float:
    """Gated ZUPT with noise σ_v (m/s) and chi-square gate ``gate`` (0: off), the heading
    column of its Jacobian from the prior velocity (module docstring); corrects x and P
    (and the transition accumulator phi, see :func:`bodyfusion.nav.error_state.update_columns`)
    in place, then the reset of :func:`bodyfusion.nav.error_state.keep_yaw_unobservable`;
    returns the NIS before gating (the caller counts NIS > gate as gated)."""
    y = np.empty(3)
    for k in range(3):
        y[k] = -x[3 + k]
    Hc = np.zeros((3, 4))
    for k in range(3):
        Hc[k, k] = 1.0
    yaw = np.empty(3)
    unobservable_yaw_column(Hc[:, 0:3], x[3:6], yaw)
    for k in range(3):  # not Hc[:, 3] = yaw: a slice assignment compiles numba's shape-error message (~2 s)
        Hc[k, 3] = yaw[k]
    cols = ZUPT_COLUMNS.copy()  # writable like update_selected's: one signature of each kernel
    S0 = innovation_covariance(P, cols, Hc, 0.0)
    r_var = sigma_v * sigma_v
    nis = _nis_with_noise(S0, y, r_var)
    update_columns(P, cols, Hc, y, gate_noise_variance(S0, y, r_var, gate), dx, phi)
    keep_yaw_unobservable(P, dx[3:6], phi)
    inject(x, dx)
    return nis


@numba.njit(cache=True)
def zero_angular_rate_update(x: np.ndarray, P: np.ndarray, gyro_b: np.ndarray, sigma_w: float,
                             dx: np.ndarray, phi: np.ndarray) -> float:
    """ZARU with noise σ_w (rad/s); corrects x, P and phi in place (with the reset of
    :func:`bodyfusion.nav.error_state.keep_yaw_unobservable`); returns the NIS."""
    y = np.empty(3)
    for k in range(3):
        y[k] = gyro_b[k] - x[13 + k]
    nis = update_selected(P, np.int64(12), y, sigma_w * sigma_w, dx, phi)
    keep_yaw_unobservable(P, dx[3:6], phi)
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
