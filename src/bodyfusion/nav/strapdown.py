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

from bodyfusion.nav.attitude import quat_from_rotvec, quat_multiply, quat_normalise, quat_to_dcm

POS = slice(0, 3)
VEL = slice(3, 6)
QUAT = slice(6, 10)
ACC_BIAS = slice(10, 13)
GYRO_BIAS = slice(13, 16)
NOMINAL_SIZE = 16


@numba.njit(cache=True)
def _cross_into(a: np.ndarray, b: np.ndarray, out: np.ndarray, scale: float) -> None:
    """out += scale · (a × b)."""
    out[0] += scale * (a[1] * b[2] - a[2] * b[1])
    out[1] += scale * (a[2] * b[0] - a[0] * b[2])
    out[2] += scale * (a[0] * b[1] - a[1] * b[0])


@numba.njit(cache=True)
def mechanise(x: np.ndarray, acc_b: np.ndarray, gyro_b: np.ndarray, dt: float, g: float,
              w_ie_n: np.ndarray, f_n_out: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """Advance the nominal state ``x`` in place by one sample (see module docstring).

    acc_b: specific force (m/s^2), gyro_b: angular rate (rad/s), dt (s), g: gravity
    magnitude (m/s^2). Writes the mean navigation-frame specific force of the step
    into ``f_n_out`` and returns C_nb at the start of the step (both feed the error-state
    transition matrix). Scalar loops only: array expressions cost numba compile time.
    """
    C = quat_to_dcm(x[6:10])
    dth = np.empty(3)
    dv = np.empty(3)
    for k in range(3):
        dth[k] = (gyro_b[k] - x[13 + k]) * dt
        dv[k] = (acc_b[k] - x[10 + k]) * dt
    pth = prev[0:3].copy()
    pv = prev[3:6].copy()
    a = np.zeros(3)
    _cross_into(dth, dv, a, 1.0)
    comp = dv.copy()
    phi = dth.copy()
    for k in range(3):
        comp[k] += 0.5 * a[k]
    _cross_into(dth, a, comp, 1.0 / 6.0)
    _cross_into(pth, dv, comp, 1.0 / 12.0)
    _cross_into(pv, dth, comp, 1.0 / 12.0)
    _cross_into(pth, dth, phi, 1.0 / 12.0)
    for k in range(3):
        prev[k] = dth[k]
        prev[3 + k] = dv[k]
    v0 = x[3:6].copy()
    dvn = np.zeros(3)
    for r in range(3):
        dvn[r] = C[r, 0] * comp[0] + C[r, 1] * comp[1] + C[r, 2] * comp[2]
    # rotation of the navigation frame over the step, −½ (ω_ie dt) × Δv_n, and Coriolis −2 ω_ie × v dt
    _cross_into(w_ie_n, dvn.copy(), dvn, -0.5 * dt)
    cor = np.zeros(3)
    _cross_into(w_ie_n, v0, cor, -2.0 * dt)
    for r in range(3):
        f_n_out[r] = dvn[r] / dt
        x[3 + r] = v0[r] + dvn[r] + cor[r]
    x[5] -= g * dt
    for r in range(3):
        x[r] += 0.5 * (v0[r] + x[3 + r]) * dt
    q = quat_multiply(x[6:10], quat_from_rotvec(phi))
    if w_ie_n[0] != 0.0 or w_ie_n[1] != 0.0 or w_ie_n[2] != 0.0:
        earth = np.empty(3)
        for k in range(3):
            earth[k] = -w_ie_n[k] * dt
        q = quat_multiply(quat_from_rotvec(earth), q)
    quat_normalise(q)
    for k in range(4):
        x[6 + k] = q[k]
    return C


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
    for i in range(1, n):
        mechanise(x, acc_b[i], gyro_b[i], t[i] - t[i - 1], g, w_ie_n, f_n, prev)
        out[i] = x
    return out
