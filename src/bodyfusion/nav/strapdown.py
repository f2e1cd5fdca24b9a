"""Strapdown mechanisation in the local ENU frame with a quaternion attitude.

Nominal state vector ``x`` (16,): position p_n (m, 0:3), velocity v_n (m/s, 3:6),
attitude q_nb (scalar-first, 6:10), accelerometer bias b_a (m/s^2, 10:13), gyroscope
bias b_g (rad/s, 13:16).

An IMU sample at t_k is taken as the mean rate over (t_{k-1}, t_k] (increment
convention). One step, from t_{k-1} to t_k, with the bias-corrected increments
α_k = (ω_k − b_g) dt and υ_k = (f_k − b_a) dt and those of the previous step
(a two-sample algorithm, Savage 1998, "Strapdown inertial navigation integration
algorithm design", JGCD 21(1–2)):

    φ     = α_k + (1/12) α_{k-1} × α_k                                   (coning)
    Δv_b  = υ_k + ½ α_k × υ_k + (1/6) α_k × (α_k × υ_k)                  (rotation)
            + (1/12) (α_{k-1} × υ_k + υ_{k-1} × α_k)                       (sculling)
    Δv_n  = (I − ½ [ω_ie dt ×]) C_nb(t_{k-1}) Δv_b
    v_n  ← v_n + Δv_n + (g_n − 2 ω_ie × v_n) dt
    p_n  ← p_n + ½ (v_n(t_{k-1}) + v_n(t_k)) dt
    q_nb ← exp(−ω_ie dt) ⊗ q_nb ⊗ exp(φ)

``prev`` (6,) carries [α_{k-1}, υ_{k-1}] from step to step (zeros at the start).
The Earth rate ω_ie (ENU) is optional (a zero vector switches it off).
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.nav.attitude import quat_from_rotvec, quat_multiply, quat_normalised, quat_to_dcm_into

POS = slice(0, 3)
VEL = slice(3, 6)
QUAT = slice(6, 10)
ACC_BIAS = slice(10, 13)
GYRO_BIAS = slice(13, 16)
NOMINAL_SIZE = 16


@numba.njit(cache=True)
def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple[float, float, float]:
    """a × b of 3-vectors given by their components."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@numba.njit(cache=True)
def mechanise(x: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray, dt: float, g: float,
              w_ie_n: np.ndarray, f_n_out: np.ndarray, prev: np.ndarray, C_nb: np.ndarray) -> None:
    """Advance the nominal state ``x`` in place by one sample (see module docstring).

    acc_b: specific force (m/s^2), gyro_b: angular rate (rad/s), dt (s), g: gravity
    magnitude (m/s^2). Writes the mean navigation-frame specific force of the step
    into ``f_n_out`` (3,) and C_nb at the start of the step into ``C_nb`` (3, 3) (both feed
    the error-state transition matrix). The 3-vectors are scalars and the quaternions
    4-tuples: the step allocates no array.
    """
    quat_to_dcm_into(x[6:10], C_nb)
    t0, t1, t2 = (gyro_b[0] - x[13]) * dt, (gyro_b[1] - x[14]) * dt, (gyro_b[2] - x[15]) * dt  # α_k
    u0, u1, u2 = (acc_b[0] - x[10]) * dt, (acc_b[1] - x[11]) * dt, (acc_b[2] - x[12]) * dt  # υ_k
    pt0, pt1, pt2, pu0, pu1, pu2 = prev[0], prev[1], prev[2], prev[3], prev[4], prev[5]  # α_{k-1}, υ_{k-1}
    a0, a1, a2 = _cross(t0, t1, t2, u0, u1, u2)  # α × υ
    r0, r1, r2 = _cross(t0, t1, t2, a0, a1, a2)  # α × (α × υ)
    s0, s1, s2 = _cross(pt0, pt1, pt2, u0, u1, u2)  # α_{k-1} × υ_k
    w0, w1, w2 = _cross(pu0, pu1, pu2, t0, t1, t2)  # υ_{k-1} × α_k
    c0, c1, c2 = _cross(pt0, pt1, pt2, t0, t1, t2)  # α_{k-1} × α_k
    sixth, twelfth = 1.0 / 6.0, 1.0 / 12.0
    dv0 = u0 + 0.5 * a0 + sixth * r0 + twelfth * s0 + twelfth * w0  # Δv_b
    dv1 = u1 + 0.5 * a1 + sixth * r1 + twelfth * s1 + twelfth * w1
    dv2 = u2 + 0.5 * a2 + sixth * r2 + twelfth * s2 + twelfth * w2
    phi = (t0 + twelfth * c0, t1 + twelfth * c1, t2 + twelfth * c2)  # the rotation vector of the step
    prev[0], prev[1], prev[2], prev[3], prev[4], prev[5] = t0, t1, t2, u0, u1, u2
    v0, v1, v2 = x[3], x[4], x[5]
    n0 = C_nb[0, 0] * dv0 + C_nb[0, 1] * dv1 + C_nb[0, 2] * dv2  # C_nb Δv_b
    n1 = C_nb[1, 0] * dv0 + C_nb[1, 1] * dv1 + C_nb[1, 2] * dv2
    n2 = C_nb[2, 0] * dv0 + C_nb[2, 1] * dv1 + C_nb[2, 2] * dv2
    # rotation of the navigation frame over the step, −½ (ω_ie dt) × Δv_n, and Coriolis −2 ω_ie × v dt
    e0, e1, e2 = w_ie_n[0], w_ie_n[1], w_ie_n[2]
    k0, k1, k2 = _cross(e0, e1, e2, n0, n1, n2)
    n0 += -0.5 * dt * k0
    n1 += -0.5 * dt * k1
    n2 += -0.5 * dt * k2
    k0, k1, k2 = _cross(e0, e1, e2, v0, v1, v2)
    f_n_out[0], f_n_out[1], f_n_out[2] = n0 / dt, n1 / dt, n2 / dt
    x[3] = v0 + n0 + -2.0 * dt * k0
    x[4] = v1 + n1 + -2.0 * dt * k1
    x[5] = v2 + n2 + -2.0 * dt * k2
    x[5] -= g * dt
    x[0] += 0.5 * (v0 + x[3]) * dt
    x[1] += 0.5 * (v1 + x[4]) * dt
    x[2] += 0.5 * (v2 + x[5]) * dt
    q = quat_multiply((x[6], x[7], x[8], x[9]), quat_from_rotvec(phi))
    if e0 != 0.0 or e1 != 0.0 or e2 != 0.0:
        q = quat_multiply(quat_from_rotvec((-w_ie_n[0] * dt, -w_ie_n[1] * dt, -w_ie_n[2] * dt)), q)
    x[6], x[7], x[8], x[9] = quat_normalised(q)


@numba.njit(cache=True)
def integrate(x0: np.ndarray, t: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray, g: float,
              w_ie_n: np.ndarray) -> np.ndarray:
    """Free inertial navigation (no aiding) from x0 at t[0]; returns (N, 16) nominal states."""
    n = t.shape[0]
    out = np.empty((n, 16))
    x = x0.copy()
    out[0] = x
    f_n = np.empty(3)
    prev = np.zeros(6)
    C_nb = np.empty((3, 3))
    for i in range(1, n):
        mechanise(x, acc_b[i], gyro_b[i], t[i] - t[i - 1], g, w_ie_n, f_n, prev, C_nb)
        out[i] = x
    return out
