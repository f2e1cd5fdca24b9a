"""Zero-velocity update under coloured measurement noise (the cKF of [Xu2024]).

During stance the foot is not perfectly still: the zero-velocity pseudo-measurement
m_k = 0 = H x_k + v_k (H selects the velocity) carries a coloured error
v_k = α v_{k−1} + ξ_k, ξ_k ~ N(0, R) ([Xu2024] eq. 4; docs/architecture.md "Coloured measurement
noise"). Differencing consecutive measurements (eq. 5) and substituting the state
backwards with x_{k−1} = F⁻¹ (x_k − w_k) (the backward-Euler step of eqs. 6–9) gives

    m̄_k = m_k − α m_{k−1} = H̄ x_k + v̄̄_k,   H̄ = H − T̄,   T̄ = α H F⁻¹,
    v̄̄_k = T̄ w_k + ξ_k,   R̄ = T̄ Q T̄ᵀ + R (eq. 10),   θ = E[w_k v̄̄_kᵀ] = Q T̄ᵀ,

a white measurement whose noise is correlated with the process noise of the same step.
The filter then uses the gain that accounts for that correlation (eqs. 11–14, the same
posterior as the de-correlated form with Λ of eqs. 15–18):

    S = H̄ P⁻ H̄ᵀ + R̄ + H̄ θ + θᵀ H̄ᵀ,   K = (P⁻ H̄ᵀ + θ) S⁻¹,
    P⁺ = (I − K H̄) P⁻ (I − K H̄)ᵀ + K R̄ Kᵀ − (I − K H̄) θ Kᵀ − K θᵀ (I − K H̄)ᵀ.

With the error-state model of :mod:`bodyfusion.nav.error_state` and random-walk biases
(A nilpotent, A⁴ = 0) the velocity rows of F⁻¹ = I − A dt + (A dt)² are exact:
H F⁻¹ = [0, I, dt [f_n×], dt C_nb, dt² [f_n×] C_nb] (with decaying Gauss–Markov biases
the bias columns are first order in β dt). In closed loop the innovation is
m̄_k − H̄ x̂_k⁻ = α v̂⁺_{k−1} − v̂⁻_k (v̂⁺_{k−1}: the velocity after every update and
correction at the previous sample). With α = 0 every term reduces to the ordinary ZUPT.

Heading stays unobservable as in :mod:`bodyfusion.nav.zupt`: the heading column of H̄ is
replaced by the one with H̄ N(x̂⁻) = 0, −(1 − α) e_z × v̂⁻
(:func:`bodyfusion.nav.zupt.unobservable_yaw_column`), and the update ends with the reset of
:func:`bodyfusion.nav.error_state.keep_yaw_unobservable`.
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.error_state import inject, keep_yaw_unobservable
from bodyfusion.nav.kalman import correlated_update
from bodyfusion.nav.zupt import unobservable_yaw_column
from bodyfusion.plugins.foot_ins.records import FilterState, StepScratch


@numba.njit(cache=True)
def velocity_rows_of_inverse_transition(C: np.ndarray, f_n: np.ndarray, dt: float, out: np.ndarray) -> None:
    """out (3, 15) = H F⁻¹ = [0, I, dt [f_n×], dt C_nb, dt² [f_n×] C_nb] for the first-order
    transition F = I + A dt of :mod:`bodyfusion.nav.error_state` (exact for random-walk biases: A⁴ = 0)."""
    for r in range(3):
        for c in range(15):
            out[r, c] = 0.0
        out[r, 3 + r] = 1.0
    # [f×] rows
    fx = np.zeros((3, 3))
    fx[0, 1] = -f_n[2]
    fx[0, 2] = f_n[1]
    fx[1, 0] = f_n[2]
    fx[1, 2] = -f_n[0]
    fx[2, 0] = -f_n[1]
    fx[2, 1] = f_n[0]
    for r in range(3):
        for c in range(3):
            out[r, 6 + c] = dt * fx[r, c]
            out[r, 9 + c] = dt * C[r, c]
            s = 0.0
            for k in range(3):
                s += fx[r, k] * C[k, c]
            out[r, 12 + c] = dt * dt * s


@numba.njit(cache=True)
def coloured_zero_velocity_update(state: FilterState, v_prev: np.ndarray, step: StepScratch, dt: float, alpha: float,
                                  sigma_v: float, gate: float) -> float:
    """The cKF stance update (module docstring) at a stance sample whose previous sample was
    also updated. The ``state``'s x (16,) prior nominal state and P (15, 15) prior covariance
    are corrected in place; ``v_prev`` (3,) the posterior velocity at the previous sample (m/s);
    of the ``step``, ``C`` and ``f_n`` its C_nb and mean navigation-frame specific force (m/s^2)
    and ``q_diag`` (15,) the process noise densities² (Q = diag(q_diag) dt), ``dt`` its interval
    (s); α the colour factor; σ_v (m/s) the standard deviation of the white driving noise ξ. The
    state's ``phi`` (15, 15), when not empty, is left-multiplied by (I − K H̄). Writes
    ``step.dx`` (15,); returns the NIS yᵀ S⁻¹ y. With ``gate`` > 0 and NIS > gate nothing is
    changed (chi-square gate, 3 degrees of freedom)."""
    x, P, _, phi = state
    q_diag, f_n, C, _, dx = step
    T = np.empty((3, 15))
    velocity_rows_of_inverse_transition(C, f_n, dt, T)
    Hb = np.zeros((3, 15))
    for r in range(3):
        for c in range(15):
            T[r, c] *= alpha
            Hb[r, c] = -T[r, c]
        Hb[r, 3 + r] += 1.0
    yaw = np.empty(3)
    unobservable_yaw_column(Hb[:, 3:6], x[3:6], yaw)
    for r in range(3):  # not Hb[:, 8] = yaw: a slice assignment compiles numba's shape-error message (~2 s)
        Hb[r, 8] = yaw[r]
    # θ = Q T̄ᵀ (15, 3); R̄ = T̄ θ + R (eq. 10)
    theta = np.empty((15, 3))
    for r in range(15):
        for c in range(3):
            theta[r, c] = q_diag[r] * dt * T[c, r]
    Rb = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            s = 0.0
            for k in range(15):
                s += T[r, k] * theta[k, c]
            Rb[r, c] = s
        Rb[r, r] += sigma_v * sigma_v
    y = np.empty(3)
    for k in range(3):
        y[k] = alpha * v_prev[k] - x[3 + k]
    nis = correlated_update(P, Hb, Rb, theta, y, gate, dx, phi)
    if gate > 0.0 and nis > gate:
        return nis
    keep_yaw_unobservable(P, dx[3:6], phi)
    inject(x, dx)
    return nis
