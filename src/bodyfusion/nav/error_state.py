"""15-state error-state model of the strapdown INS (closed loop).

Error state δx (15,): δp (m, 0:3), δv (m/s, 3:6), δθ (rad, 6:9; attitude error in the
navigation frame, C_nb,true = (I + [δθ×]) C_nb), δb_a (m/s^2, 9:12), δb_g (rad/s, 12:15).
Errors are true minus estimated. Continuous dynamics (Groves 2013, §14.2, ENU form):

    δṗ = δv,   δv̇ = −[f_n×] δθ − C_nb δb_a − C_nb w_a,   δθ̇ = −C_nb δb_g − C_nb w_g,
    δḃ_a = −β_a δb_a + w_ba,   δḃ_g = −β_g δb_g + w_bg.

The biases are random walks (β = 0) or first-order Gauss–Markov processes of correlation
time τ = 1/β (their estimates then decay too, b̂̇ = −β b̂: :func:`decay_biases`).
Discretised to first order, F = I + A dt, Q_d = diag(σ_a², σ_g², σ_ba², σ_bg²) dt per axis
(noise densities: σ_a m/s^2/√Hz, σ_g rad/s/√Hz, σ_ba m/s^3/√Hz, σ_bg rad/s^2/√Hz).
The propagation exploits the block sparsity of A (no dense 15×15 products).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from bodyfusion.nav.attitude import quat_from_rotvec, quat_multiply, quat_normalised

ERROR_SIZE = 15



class FilterParams(NamedTuple):
    """The model parameters of the compiled 15-state kernels (the foot INS and its smoothers),
    by name: noise densities (accelerometer m/s^2/√Hz, gyroscope rad/s/√Hz), bias random walks
    (m/s^3/√Hz, rad/s^2/√Hz), the stance updates' σ (ZUPT m/s, ZARU rad/s; 0: no ZARU), gravity
    (m/s^2), the Earth rate in ENU (rad/s, (3,)), the zero-velocity gate (chi-square threshold,
    0: off; :mod:`bodyfusion.nav.zupt`), the bias decay rates β = 1/τ (1/s; 0: random walk) and
    the rolling foot's pivot (m; :func:`bodyfusion.nav.zupt.stance_velocity_sigma`)."""

    acc_noise_density: float
    gyro_noise_density: float
    acc_bias_walk: float
    gyro_bias_walk: float
    zupt_sigma: float
    zaru_sigma: float
    gravity: float
    earth_rate: np.ndarray
    zupt_gate: float
    acc_bias_decay: float
    gyro_bias_decay: float
    zupt_pivot: float

    def backward(self) -> FilterParams:
        """The parameters of the run navigated back in time: the Earth rate changes sign."""
        return self._replace(earth_rate=-self.earth_rate)


def filter_params(**values: float | np.ndarray) -> FilterParams:
    """:class:`FilterParams` with every field not given zero (the Earth rate (0, 0, 0))."""
    fields = {name: 0.0 for name in FilterParams._fields}
    fields["earth_rate"] = np.zeros(3)
    fields.update(values)
    fields["earth_rate"] = np.ascontiguousarray(fields["earth_rate"], dtype=np.float64)
    return FilterParams(**{name: (fields[name] if name == "earth_rate" else float(fields[name]))
                           for name in FilterParams._fields})
Q_DECAY = 15
"""Index in the :func:`process_noise_diag` vector of the decay rates β_a, β_g (after the 15 densities²)."""
DPOS = slice(0, 3)
DVEL = slice(3, 6)
DATT = slice(6, 9)
DACC_BIAS = slice(9, 12)
DGYRO_BIAS = slice(12, 15)


@numba.njit(cache=True)
def process_noise_diag(params: FilterParams) -> np.ndarray:
    """The process model (17,) from ``params``: the diagonal of the continuous process noise
    of the 15 error states (densities², per Hz), then the bias decay rates β_a, β_g (1/s)."""
    q = np.zeros(Q_DECAY + 2)
    q[Q_DECAY] = params.acc_bias_decay
    q[Q_DECAY + 1] = params.gyro_bias_decay
    for k in range(3):
        q[3 + k] = params.acc_noise_density ** 2
        q[6 + k] = params.gyro_noise_density ** 2
        q[9 + k] = params.acc_bias_walk ** 2
        q[12 + k] = params.gyro_bias_walk ** 2
    return q


@numba.njit(cache=True)
def bias_decay(q_diag: np.ndarray, dt: float) -> tuple[float, float]:
    """(da, dg) = (−β_a dt, −β_g dt): the bias decay entries of E = Φ − I over dt (s), β (1/s)
    from the process model ``q_diag`` (:func:`process_noise_diag`; (0, 0) when it holds the 15
    densities² only)."""
    if q_diag.shape[0] > Q_DECAY:
        return -dt * q_diag[Q_DECAY], -dt * q_diag[Q_DECAY + 1]
    return 0.0, 0.0


@numba.njit(cache=True)
def transition_left(M: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float, da: float, dg: float,
                    lower: bool) -> None:
    """M ← Φ M in place (M (15, m)) for the first-order transition Φ = I + E of one step,
    written from the non-zero entries of E = A dt (module docstring; C_nb (3, 3), the step's
    mean specific force f_n (3,) m/s² in the navigation frame, dt s): E[r, 3+r] = dt
    (δp ← δv), E[3:6, 6:9] = −[f_n×] dt (δv ← δθ), E[3:6, 9:12] = −C_nb dt (δv ← δb_a),
    E[6:9, 12:15] = −C_nb dt (δθ ← δb_g), E[9+k, 9+k] = da, E[12+k, 12+k] = dg (the bias
    decay, :func:`bias_decay`; the bias rows are scaled by 1 + da, 1 + dg). Rows are done
    from the first, each reading rows below it, not yet changed. With ``lower`` only
    M[r, :r + 1] of each row changes (the lower triangle of Φ M).

    The same entries, transposed, are what :func:`transition_transpose_left` applies."""
    m = M.shape[1]
    for r in range(3):  # position rows: from δv
        for q in range(r + 1 if lower else m):
            M[r, q] = M[r, q] + dt * M[3 + r, q]
    f0, f1, f2 = dt * f_n[0], dt * f_n[1], dt * f_n[2]
    for r in range(3):  # velocity rows: −[f×] dt from δθ, −C_nb dt from δb_a
        c0, c1, c2 = dt * C[r, 0], dt * C[r, 1], dt * C[r, 2]
        if r == 0:
            for q in range(4 if lower else m):
                M[3, q] = M[3, q] + f2 * M[7, q] - f1 * M[8, q] - c0 * M[9, q] - c1 * M[10, q] - c2 * M[11, q]
        elif r == 1:
            for q in range(5 if lower else m):
                M[4, q] = M[4, q] - f2 * M[6, q] + f0 * M[8, q] - c0 * M[9, q] - c1 * M[10, q] - c2 * M[11, q]
        else:
            for q in range(6 if lower else m):
                M[5, q] = M[5, q] + f1 * M[6, q] - f0 * M[7, q] - c0 * M[9, q] - c1 * M[10, q] - c2 * M[11, q]
    for r in range(3):  # attitude rows: −C_nb dt from δb_g
        c0, c1, c2 = dt * C[r, 0], dt * C[r, 1], dt * C[r, 2]
        for q in range(7 + r if lower else m):
            M[6 + r, q] = M[6 + r, q] - c0 * M[12, q] - c1 * M[13, q] - c2 * M[14, q]
    if da != 0.0 or dg != 0.0:
        for r in range(9, 15):
            d = 1.0 + (da if r < 12 else dg)
            for q in range(r + 1 if lower else m):
                M[r, q] *= d


@numba.njit(cache=True)
def transition_transpose_left(M: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float, da: float, dg: float,
                              lower: bool) -> None:
    """M ← Φᵀ M in place (M (15, m)) for the transition Φ = I + E of :func:`transition_left`,
    from the same non-zero entries of E (C_nb (3, 3), the step's specific force f_n (3,) m/s²
    in the navigation frame, dt s, the bias decay da, dg): the adjoint of the smoothers'
    backward sweep. Row c of Φᵀ M is M[c] + Σ_k E[k, c] M[k] over k < c (then k = c) in
    increasing k, the order of a dense product; rows are done from the last, so each reads
    rows not yet changed. With ``lower`` only M[c, :c + 1] of each row changes. A kernel of its
    own, ``lower`` passed as np.bool_ (one signature): inlined at its three call sites it made
    their kernel take 3.6 s to compile."""
    m = M.shape[1]
    for k in range(2, -1, -1):  # gyro bias rows 12 + k: from δθ (rows 6:9)
        c = 12 + k
        e0, e1, e2 = dt * -C[0, k], dt * -C[1, k], dt * -C[2, k]
        for q in range(c + 1 if lower else m):
            M[c, q] = M[c, q] + e0 * M[6, q] + e1 * M[7, q] + e2 * M[8, q] + dg * M[c, q]
    for k in range(2, -1, -1):  # accelerometer bias rows 9 + k: from δv (rows 3:6)
        c = 9 + k
        e0, e1, e2 = dt * -C[0, k], dt * -C[1, k], dt * -C[2, k]
        for q in range(c + 1 if lower else m):
            M[c, q] = M[c, q] + e0 * M[3, q] + e1 * M[4, q] + e2 * M[5, q] + da * M[c, q]
    f0, f1, f2 = dt * f_n[0], dt * f_n[1], dt * f_n[2]  # attitude rows: −[f×] dt from δv
    for q in range(9 if lower else m):
        M[8, q] = M[8, q] - f1 * M[3, q] + f0 * M[4, q]
    for q in range(8 if lower else m):
        M[7, q] = M[7, q] + f2 * M[3, q] - f0 * M[5, q]
    for q in range(7 if lower else m):
        M[6, q] = M[6, q] - f2 * M[4, q] + f1 * M[5, q]
    for r in range(2, -1, -1):  # velocity rows: from δp
        for q in range(4 + r if lower else m):
            M[3 + r, q] = M[3 + r, q] + dt * M[r, q]


@numba.njit(cache=True)
def propagate_covariance(P: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float, q_diag: np.ndarray) -> None:
    """P ← Φ P Φᵀ + Q_d in place (P (15, 15) symmetric), Φ = I + A dt with the bias decay of
    ``q_diag`` (densities² per Hz of the 15 states, optionally followed by the decay rates:
    :func:`process_noise_diag`), Q_d = diag(q) dt. From the non-zero entries of Φ
    (:func:`transition_left`), no dense products: V = Φ P, then Φ Vᵀ = (V Φᵀ)ᵀ, whose lower
    triangle is that of Φ P Φᵀ; the result's lower triangle is mirrored (P exactly symmetric)."""
    da, dg = bias_decay(q_diag, dt)
    # np.bool_, not a bare True/False: numba types a constant argument as a literal, one
    # compilation per value
    transition_left(P, C, f_n, dt, da, dg, np.bool_(False))
    for r in range(15):
        for c in range(r + 1, 15):
            v = P[r, c]
            P[r, c] = P[c, r]
            P[c, r] = v
    transition_left(P, C, f_n, dt, da, dg, np.bool_(True))
    for r in range(15):
        P[r, r] += q_diag[r] * dt
        for c in range(r + 1, 15):
            P[r, c] = P[c, r]


@numba.njit(cache=True)
def decay_biases(x: np.ndarray, q_diag: np.ndarray, dt: float) -> None:
    """The nominal biases of x (16,) over dt (s): b̂ ← (1 − β dt) b̂ (β from ``q_diag``)."""
    for k in range(3):
        x[10 + k] *= 1.0 - dt * q_diag[Q_DECAY]
        x[13 + k] *= 1.0 - dt * q_diag[Q_DECAY + 1]


@numba.njit(cache=True)
def accumulate_propagation(phi: np.ndarray, C: np.ndarray, f_n: np.ndarray, dt: float) -> None:
    """phi ← F₀ phi in place (F₀ = I + A dt without the bias decay: :func:`transition_left`
    with da = dg = 0)."""
    transition_left(phi, C, f_n, dt, 0.0, 0.0, np.bool_(False))  # np.bool_: see propagate_covariance


@numba.njit(cache=True)
def inject(x: np.ndarray, dx: np.ndarray) -> None:
    """Closed-loop reset: add the error-state estimate dx (15,) to the nominal state x (16,)."""
    for k in range(3):
        x[k] += dx[k]
        x[3 + k] += dx[3 + k]
        x[10 + k] += dx[9 + k]
        x[13 + k] += dx[12 + k]
    q = quat_multiply(quat_from_rotvec((dx[6], dx[7], dx[8])), (x[6], x[7], x[8], x[9]))
    x[6], x[7], x[8], x[9] = quat_normalised(q)


@numba.njit(inline="always")
def closed_loop_reset(x: np.ndarray, P: np.ndarray, dx: np.ndarray, P_new: np.ndarray) -> None:
    """Closed-loop reset after a correction from outside the filter: :func:`inject` dx (≥ 15,)
    into x (16,), and P (n, n) ← ½ (P_new + P_newᵀ) in place (P_new may be P). Inlined into the
    kernel that records the state with it (:func:`bodyfusion.plugins.foot_ins.kernels.set_state`):
    no compilation of its own."""
    inject(x, dx)
    n = P.shape[0]
    for a in range(n):
        for b in range(a, n):
            v = 0.5 * (P_new[a, b] + P_new[b, a])
            P[a, b] = v
            P[b, a] = v


@numba.njit(cache=True)
def congruence_by_yaw_reset(M: np.ndarray, a0: float, a1: float) -> None:
    """M ← G M Gᵀ in place for the heading reset G = I + a e_ψᵀ of
    :func:`keep_yaw_unobservable` whose east and north velocity rows are a = (a0, a1); its
    inverse G⁻¹ = I − a e_ψᵀ (e_ψᵀ a = 0) is the call with (−a0, −a1). M symmetric (15, 15)."""
    for c in range(15):
        M[3, c] += a0 * M[8, c]
        M[4, c] += a1 * M[8, c]
    for r in range(15):
        M[r, 3] += a0 * M[r, 8]
        M[r, 4] += a1 * M[r, 8]
    M[3, 4] = M[4, 3]  # equal but for rounding: keep M exactly symmetric


@numba.njit(cache=True)
def keep_yaw_unobservable(P: np.ndarray, dv: np.ndarray, phi: np.ndarray) -> None:
    """Closed-loop reset of a stance update that moved the velocity by ``dv`` (3,) (m/s).

    A rotation of the whole state about Up by δψ changes the error state along
    N(x̂) = [e_z × p̂; e_z × v̂; e_z; 0; 0], which no zero-velocity or zero-rate measurement
    sees, and F N(x̂_k) = N(x̂_{k+1}) (F of :func:`propagate_covariance`; f_n dt is the
    mechanisation's velocity increment). A correction moves v̂, so the direction the update
    left unobserved, N(x̂⁻), is not the one the next propagation carries, N(x̂⁺): left as is,
    every stance sample gains heading information no measurement holds, and the heading
    variance stops growing. The reset G = I + a e_ψᵀ, a = [0; e_z × dv; 0; 0; 0], maps
    N(x̂⁻) to N(x̂⁺) (observability-constrained EKF, [Hesch2014]; the position part
    e_z × dp is a translation, unobservable anyway): P ← G P Gᵀ and, unless empty,
    phi ← G phi."""
    a0, a1 = -dv[1], dv[0]
    congruence_by_yaw_reset(P, a0, a1)
    if phi.shape[0] > 0:
        for c in range(15):
            phi[3, c] += a0 * phi[8, c]
            phi[4, c] += a1 * phi[8, c]


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
