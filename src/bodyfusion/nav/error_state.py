"""15-state error-state model of the strapdown INS (closed loop).

Error state δx (15,): δp (m, 0:3), δv (m/s, 3:6), δθ (rad, 6:9; attitude error in the
navigation frame, C_nb,true = (I + [δθ×]) C_nb), δb_a (m/s^2, 9:12), δb_g (rad/s, 12:15).
Errors are true minus estimated. Continuous dynamics (Groves 2013, §14.2, ENU form):

    δṗ = δv,   δv̇ = −[f_n×] δθ − C_nb δb_a − C_nb w_a,   δθ̇ = −C_nb δb_g − C_nb w_g,
    δḃ_a = w_ba,   δḃ_g = w_bg.

Discretised to first order, F = I + A dt, Q_d = diag(σ_a², σ_g², σ_ba², σ_bg²) dt per axis
(noise densities: σ_a m/s^2/√Hz, σ_g rad/s/√Hz, σ_ba m/s^3/√Hz, σ_bg rad/s^2/√Hz).
The propagation exploits the block sparsity of A (no dense 15×15 products).
"""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from bodyfusion.nav.attitude import quat_from_rotvec, quat_multiply, quat_normalise

ERROR_SIZE = 15

# The filter parameter vector ``params`` of the compiled 15-state kernels (the foot INS
# and its smoothers): noise densities, stance-update σs, gravity (m/s^2), Earth rate (ENU),
# and the zero-velocity gate (chi-square threshold, 0: off; see :mod:`bodyfusion.nav.zupt`).
P_ACC_ND, P_GYRO_ND, P_ACC_RW, P_GYRO_RW, P_ZUPT_SIGMA, P_ZARU_SIGMA, P_GRAVITY = range(7)
P_EARTH_RATE = slice(7, 10)
P_ZUPT_GATE = 10
PARAMS_SIZE = 11
DPOS = slice(0, 3)
DVEL = slice(3, 6)
DATT = slice(6, 9)
DACC_BIAS = slice(9, 12)
DGYRO_BIAS = slice(12, 15)


@numba.njit(cache=True)
def process_noise_diag(params: np.ndarray) -> np.ndarray:
    """Diagonal (15,) of the continuous process noise (densities², per Hz) from ``params``."""
    q = np.zeros(15)
    for k in range(3):
        q[3 + k] = params[P_ACC_ND] ** 2
        q[6 + k] = params[P_GYRO_ND] ** 2
        q[9 + k] = params[P_ACC_RW] ** 2
        q[12 + k] = params[P_GYRO_RW] ** 2
    return q


@numba.njit(cache=True)
def _apply_A_left(P: np.ndarray, C: np.ndarray, f_n: np.ndarray, out: np.ndarray) -> None:
    """out = A P for the block-sparse A of the module docstring (P may be non-symmetric)."""
    n = P.shape[1]
    for c in range(n):
        for r in range(3):
            out[r, c] = P[3 + r, c]
        a0, a1, a2 = P[6, c], P[7, c], P[8, c]
        # −[f×] δθ
        out[3, c] = -(-f_n[2] * a1 + f_n[1] * a2)
        out[4, c] = -(f_n[2] * a0 - f_n[0] * a2)
        out[5, c] = -(-f_n[1] * a0 + f_n[0] * a1)
        for r in range(3):
            out[3 + r, c] -= C[r, 0] * P[9, c] + C[r, 1] * P[10, c] + C[r, 2] * P[11, c]
            out[6 + r, c] = -(C[r, 0] * P[12, c] + C[r, 1] * P[13, c] + C[r, 2] * P[14, c])
        for r in range(9, 15):
            out[r, c] = 0.0


@numba.njit(cache=True)
def propagate_covariance(P: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float, q_diag: np.ndarray,
                         work: np.ndarray) -> None:
    """P ← F P Fᵀ + Q_d in place, F = I + A dt. ``q_diag`` (15,) holds densities² (per Hz),
    ``work`` is (2, 15, 15) scratch. Symmetrises the result."""
    AP = work[0]
    _apply_A_left(P, C, f_n, AP)
    FP = work[1]
    for r in range(15):
        for c in range(15):
            FP[r, c] = P[r, c] + dt * AP[r, c]
    # (F P) Fᵀ = FP + dt (A FPᵀ)ᵀ
    FPt = np.empty((15, 15))
    for r in range(15):
        for c in range(15):
            FPt[r, c] = FP[c, r]
    _apply_A_left(FPt, C, f_n, AP)
    for r in range(15):
        for c in range(15):
            P[r, c] = FP[r, c] + dt * AP[c, r]
    for r in range(15):
        P[r, r] += q_diag[r] * dt
        for c in range(r + 1, 15):
            s = 0.5 * (P[r, c] + P[c, r])
            P[r, c] = s
            P[c, r] = s


@numba.njit(cache=True)
def accumulate_propagation(phi: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float, work: np.ndarray) -> None:
    """phi ← F phi in place (F = I + A dt); ``work`` is (15, 15) scratch."""
    _apply_A_left(phi, C, f_n, work)
    for r in range(15):
        for c in range(15):
            phi[r, c] += dt * work[r, c]


@numba.njit(cache=True)
def accumulate_update(phi: np.ndarray, K: np.ndarray, first: int) -> None:
    """phi ← (I − K H) phi in place, H selecting states first:first+3."""
    rows = np.empty((3, 15))
    for k in range(3):
        for c in range(15):
            rows[k, c] = phi[first + k, c]
    for r in range(15):
        for c in range(15):
            phi[r, c] -= K[r, 0] * rows[0, c] + K[r, 1] * rows[1, c] + K[r, 2] * rows[2, c]


@numba.njit(cache=True)
def inject(x: np.ndarray, dx: np.ndarray) -> None:
    """Closed-loop reset: add the error-state estimate dx (15,) to the nominal state x (16,)."""
    for k in range(3):
        x[k] += dx[k]
        x[3 + k] += dx[3 + k]
        x[10 + k] += dx[9 + k]
        x[13 + k] += dx[12 + k]
    q = quat_multiply(quat_from_rotvec(dx[6:9]), x[6:10])
    quat_normalise(q)
    for k in range(4):
        x[6 + k] = q[k]


@numba.njit(cache=True)
def inv3_sym(S: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric positive-definite 3×3 matrix (cofactors)."""
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e = S[1, 1], S[1, 2]
    f = S[2, 2]
    A = d * f - e * e
    B = c * e - b * f
    C = b * e - c * d
    det = a * A + b * B + c * C
    out = np.empty((3, 3))
    out[0, 0] = A / det
    out[0, 1] = B / det
    out[0, 2] = C / det
    out[1, 0] = B / det
    out[1, 1] = (a * f - c * c) / det
    out[1, 2] = (b * c - a * e) / det
    out[2, 0] = C / det
    out[2, 1] = out[1, 2]
    out[2, 2] = (a * d - b * b) / det
    return out


@numba.njit(cache=True)
def nis_selected(P: np.ndarray, first: int, y: np.ndarray, r_var: float) -> float:
    """Normalised innovation squared yᵀ S⁻¹ y of a 3-D measurement selecting states
    first:first+3, S = P_sel + r_var I (the chi-square test statistic, 3 degrees of freedom)."""
    S = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            S[r, c] = P[first + r, first + c]
        S[r, r] += r_var
    Si = inv3_sym(S)
    nis = 0.0
    for r in range(3):
        for c in range(3):
            nis += y[r] * Si[r, c] * y[c]
    return nis


@numba.njit(cache=True)
def update_selected(P: np.ndarray, first: int, y: np.ndarray, r_var: float, dx: np.ndarray,
                    phi: np.ndarray) -> float:
    """Kalman update for a 3-D measurement that selects states first:first+3 (H = [0 I 0]),
    innovation y (3,), isotropic noise variance r_var. Joseph form, P in place; writes
    dx (15,) and returns the normalised innovation squared yᵀ S⁻¹ y.

    ``phi`` (15, 15), the error-state transition accumulated since the fuser's last sync,
    is left-multiplied by (I − K H) in place; pass an empty (0, 0) array when the fuser
    does not track cross-covariances."""
    S = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            S[r, c] = P[first + r, first + c]
        S[r, r] += r_var
    Si = inv3_sym(S)
    K = np.empty((15, 3))
    for r in range(15):
        for c in range(3):
            K[r, c] = P[r, first] * Si[0, c] + P[r, first + 1] * Si[1, c] + P[r, first + 2] * Si[2, c]
    for r in range(15):
        dx[r] = K[r, 0] * y[0] + K[r, 1] * y[1] + K[r, 2] * y[2]
    if phi.shape[0] > 0:
        accumulate_update(phi, K, first)
    # Joseph: (I − K H) P (I − K H)ᵀ + K R Kᵀ
    M = P.copy()
    for r in range(15):
        for c in range(15):
            M[r, c] -= K[r, 0] * P[first, c] + K[r, 1] * P[first + 1, c] + K[r, 2] * P[first + 2, c]
    for r in range(15):
        for c in range(r, 15):
            v = M[r, c] - (M[r, first] * K[c, 0] + M[r, first + 1] * K[c, 1] + M[r, first + 2] * K[c, 2])
            v += r_var * (K[r, 0] * K[c, 0] + K[r, 1] * K[c, 1] + K[r, 2] * K[c, 2])
            P[r, c] = v
            P[c, r] = v
    nis = 0.0
    for r in range(3):
        for c in range(3):
            nis += y[r] * Si[r, c] * y[c]
    return nis


def error_between(x_true: np.ndarray, x_est: np.ndarray) -> np.ndarray:
    """The error state (15,) of nominal ``x_est`` against ``x_true`` (both (16,)): true minus
    estimated, δθ = rotvec(q_true ⊗ q_est⁻¹) in the navigation frame (the inverse of :func:`inject`)."""
    dx = np.empty(ERROR_SIZE)
    dx[0:6] = x_true[0:6] - x_est[0:6]
    r = Rotation.from_quat(x_true[6:10], scalar_first=True) * Rotation.from_quat(x_est[6:10], scalar_first=True).inv()
    dx[6:9] = r.as_rotvec()
    dx[9:15] = x_true[10:16] - x_est[10:16]
    return dx


def rotate_about_up(x: np.ndarray, P: np.ndarray, delta_azimuth: float) -> tuple[np.ndarray, np.ndarray]:
    """The nominal state (16,) and covariance (15, 15) turned about Up by ``delta_azimuth``
    (rad, clockwise from North positive, as azimuth): position, velocity and attitude (and
    their error blocks, navigation frame) rotate; the body-frame biases do not."""
    rot = Rotation.from_euler("z", -delta_azimuth)
    R = rot.as_matrix()
    out = np.asarray(x, dtype=float).copy()
    out[0:3] = R @ out[0:3]
    out[3:6] = R @ out[3:6]
    out[6:10] = (rot * Rotation.from_quat(out[6:10], scalar_first=True)).as_quat(scalar_first=True)
    T = np.eye(ERROR_SIZE)
    for block in (DPOS, DVEL, DATT):
        T[block, block] = R
    return out, T @ P @ T.T
