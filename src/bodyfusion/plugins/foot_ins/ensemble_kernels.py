"""Compiled per-sample loop of the ensemble foot INS (``enekf``, ``cenekf``; [Deng2026]).

Members are rows of ``ens`` (M, n_s): the nominal state of :mod:`bodyfusion.nav.strapdown`
(p_n m, v_n m/s, q_nb scalar-first, b_a m/s^2, b_g rad/s; 16 values), and for the
cenekf the coloured stance noise V (m/s, 3 values; eqs. 5–7) appended. Each sample:

* Forecast (eq. 8): every member is mechanised with its own IMU noise draw — specific
  force and rate perturbed by white noise of σ = density/√dt, biases by a random walk of
  σ = density·√dt — so the ensemble samples the process noise Q of the 15-state model
  through the nonlinear quaternion model (eq. 1). cenekf: V ← α V + δ, δ ~ N(0, σ_v² I)
  (eq. 5, w̄ = [w; δ]).
* Analysis at stance samples (eqs. 10–17): predicted observation y_j = v_j (enekf) or
  v_j + V_j (cenekf, H̄ = [H I], eq. 6, no measurement noise); gain
  K = P_sy (P_yy + R̄)⁻¹ from the ensemble cross-covariances; s_j ← s_j + K (z + ε_j − y_j)
  with ε_j ~ N(0, R̄) a perturbed observation per member (R̄ = σ_v² I for the enekf, 0 for
  the cenekf), so the analysed ensemble's covariance is (I − K H) P, as the Kalman update's.
  The optional ZARU (z = ω̃_b, y_j = b_g,j) is analysed the same way. The quaternion rows
  are updated like the others and every member's quaternion is then renormalised.
* Estimate (eq. 18): the ensemble mean (quaternion: normalised mean of the members').

The paper's stance measurement (eq. 4) lists the INS quaternion beside the velocity. Here
every member carries its own quaternion through the mechanisation, so there is no
independent attitude observation to add: stance observes the velocity (and, with the
ZARU, the angular rate); the attitude is corrected through its ensemble correlation with them.

Random numbers come pre-drawn in ``noise`` (L, M, 21) so that the kernel is
deterministic: [0:3] accelerometer, [3:6] gyroscope, [6:9] accelerometer bias walk,
[9:12] gyroscope bias walk, [12:15] δ of V, [15:18] ZUPT perturbation, [18:21] ZARU
perturbation (standard normal). Each sample's draws are made second-order exact before
use (Evensen 2004, Ocean Dynamics 54, §4, "improved sampling"; :func:`improve_sampling`):
centred, uncorrelated with the members' current deviations and with each other, and of
unit sample variance. Plain draws give sample correlations of order 1/√M between the fresh
noise and every state, which the analysis then reads as information: with the many ZUPTs
of a walk that spurious information makes the ensemble collapse at M = 100.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.nav.error_state import FilterParams
from bodyfusion.plugins.foot_ins.records import FilterHistory, ImuSamples
from bodyfusion.nav.kalman import inv3_sym
from bodyfusion.nav.attitude import quat_from_rotvec, quat_multiply, quat_normalised
from bodyfusion.plugins.foot_ins.smoothing_replay import boxminus
from bodyfusion.nav.strapdown import mechanise

NOISE_WIDTH = 21
NOMINAL = 16
# Layout of the ``counters`` vector (as the EKF's: ZUPTs, ZARUs, sum of ZUPT NIS).
C_ZUPTS, C_ZARUS, C_NIS_SUM = range(3)


@numba.njit(cache=True)
def _renormalise(ens: np.ndarray) -> None:
    for j in range(ens.shape[0]):
        ens[j, 6], ens[j, 7], ens[j, 8], ens[j, 9] = quat_normalised((ens[j, 6], ens[j, 7], ens[j, 8], ens[j, 9]))


@numba.njit(cache=True)
def ensemble_mean(ens: np.ndarray, out: np.ndarray) -> None:
    """out (n_s,) = member mean; the quaternion part is the normalised mean quaternion."""
    M, ns = ens.shape
    for k in range(ns):
        out[k] = 0.0
    for j in range(M):
        for k in range(ns):
            out[k] += ens[j, k]
    for k in range(ns):
        out[k] /= M
    out[6], out[7], out[8], out[9] = quat_normalised((out[6], out[7], out[8], out[9]))


MOTION_PAIRS = ((3, 3), (4, 4), (5, 5), (6, 6), (7, 7), (8, 8), (6, 7), (6, 8), (7, 8))
"""Error-state index pairs of the recorded velocity and attitude entries, in the order of
:data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE` columns 4–12."""


@numba.njit(cache=True)
def _record_motion_covariance(ens: np.ndarray, mean: np.ndarray, D: np.ndarray, row: np.ndarray) -> None:
    """``row[4:13]`` ← the members' sample covariance of the velocity and attitude deviations
    (:data:`MOTION_PAIRS`)."""
    M = ens.shape[0]
    ensemble_deviations(ens, mean, D, np.bool_(True))  # not a literal: one signature
    for c in range(9):
        a, b = MOTION_PAIRS[c]
        s = 0.0
        for j in range(M):
            s += D[j, a] * D[j, b]
        row[4 + c] = s / (M - 1)


@numba.njit(cache=True)
def ensemble_deviations(ens: np.ndarray, mean: np.ndarray, D: np.ndarray, centre: bool) -> None:
    """D (M, n) = error-state deviations of the members from ``mean``: rows
    [δp, δv, δθ (rotation vector of q_j ⊗ q̄⁻¹, navigation frame), δb_a, δb_g] (n = 15), and
    for the cenekf δV (n = 18); with ``centre`` each column's mean is subtracted (the
    attitude's is of second order: q̄ is the normalised mean quaternion)."""
    M = ens.shape[0]
    n = D.shape[1]
    d = np.empty(15)
    for j in range(M):
        boxminus(ens[j], mean, d)
        for k in range(15):
            D[j, k] = d[k]
        for k in range(15, n):
            D[j, k] = ens[j, k + 1] - mean[k + 1]
    if not centre:
        return
    for k in range(n):
        s = 0.0
        for j in range(M):
            s += D[j, k]
        s /= M
        for j in range(M):
            D[j, k] -= s


@numba.njit(cache=True)
def ensemble_covariance(ens: np.ndarray, mean: np.ndarray, P: np.ndarray) -> None:
    """P (n, n) = sample covariance (1/(M−1)) Dᵀ D of :func:`ensemble_deviations`."""
    M = ens.shape[0]
    n = P.shape[0]
    D = np.empty((M, n))
    ensemble_deviations(ens, mean, D, np.bool_(True))  # not a literal: the signature Python calls
    for r in range(n):
        for c in range(r, n):
            s = 0.0
            for j in range(M):
                s += D[j, r] * D[j, c]
            s /= M - 1
            P[r, c] = s
            P[c, r] = s


@numba.njit(cache=True)
def place_members(mean: np.ndarray, D: np.ndarray, ens: np.ndarray) -> None:
    """Members from a mean state (n_s,) and error-state deviations D (M, n):
    member_j = mean ⊕ D_j (attitude by the rotation vector, left-multiplied, as
    :func:`bodyfusion.nav.error_state.inject`)."""
    M, ns = ens.shape
    for j in range(M):
        for k in range(3):
            ens[j, k] = mean[k] + D[j, k]
            ens[j, 3 + k] = mean[3 + k] + D[j, 3 + k]
            ens[j, 10 + k] = mean[10 + k] + D[j, 9 + k]
            ens[j, 13 + k] = mean[13 + k] + D[j, 12 + k]
        for k in range(16, ns):
            ens[j, k] = mean[k] + D[j, k - 1]
        q = quat_multiply(quat_from_rotvec((D[j, 6], D[j, 7], D[j, 8])), (mean[6], mean[7], mean[8], mean[9]))
        ens[j, 6], ens[j, 7], ens[j, 8], ens[j, 9] = quat_normalised(q)


@numba.njit(cache=True)
def improve_sampling(ens: np.ndarray, nz: np.ndarray, used: np.ndarray, basis: np.ndarray) -> None:
    """Make the draws nz (M, 21) second-order exact in place: each ``used`` column centred,
    orthogonal (over the members) to the centred member states ``ens`` (M, n_s; the
    quaternion by its vector part) and to the used columns before it, and scaled to unit
    sample variance (modified Gram–Schmidt; ``basis`` (M, n_s + 21) scratch). Needs
    M − 1 ≥ n_s + (used columns); a column left without room keeps its draw."""
    M, ns = ens.shape
    w = nz.shape[1]
    v = np.empty(M)
    k = 0
    for c in range(ns + w):
        if c == 6 or (c >= ns and not used[c - ns]):
            continue  # q_w: first-order dependent on q_x, q_y, q_z, and its deviations cancel badly
        m = 0.0
        for j in range(M):
            v[j] = ens[j, c] if c < ns else nz[j, c - ns]
            m += v[j]
        m /= M
        norm0 = 0.0
        for j in range(M):
            v[j] -= m
            norm0 += v[j] * v[j]
        for l in range(k):
            d = 0.0
            for j in range(M):
                d += basis[j, l] * v[j]
            for j in range(M):
                v[j] -= d * basis[j, l]
        norm = 0.0
        for j in range(M):
            norm += v[j] * v[j]
        if norm <= 1e-20 * norm0 or norm == 0.0:
            continue
        norm = math.sqrt(norm)
        for j in range(M):
            basis[j, k] = v[j] / norm
        k += 1
        if c >= ns:
            scale = math.sqrt(M - 1.0)
            for j in range(M):
                nz[j, c - ns] = basis[j, k - 1] * scale


@numba.njit(cache=True)
def ensemble_analysis(ens: np.ndarray, first: int, second: int, z: np.ndarray, r_var: float,
                      pert: np.ndarray, offset: int) -> float:
    """Ensemble Kalman analysis (eqs. 10–17) of a 3-D observation y_j = s_j[first:first+3]
    (+ s_j[second:second+3] when ``second`` ≥ 0) with value z (3,) and noise variance
    r_var per axis; member j's observation is perturbed by √r_var · pert[j, offset:offset+3].
    Quaternions are renormalised afterwards. Returns the NIS of the mean innovation."""
    M, ns = ens.shape
    y = np.empty((M, 3))
    for j in range(M):
        for k in range(3):
            y[j, k] = ens[j, first + k]
            if second >= 0:
                y[j, k] += ens[j, second + k]
    ybar = np.zeros(3)
    sbar = np.zeros(ns)
    for j in range(M):
        for k in range(3):
            ybar[k] += y[j, k]
        for k in range(ns):
            sbar[k] += ens[j, k]
    for k in range(3):
        ybar[k] /= M
    for k in range(ns):
        sbar[k] /= M
    Psy = np.zeros((ns, 3))
    Pyy = np.zeros((3, 3))
    for j in range(M):
        for c in range(3):
            dy = y[j, c] - ybar[c]
            for r in range(ns):
                Psy[r, c] += (ens[j, r] - sbar[r]) * dy
            for r in range(3):
                Pyy[r, c] += (y[j, r] - ybar[r]) * dy
    for c in range(3):
        for r in range(ns):
            Psy[r, c] /= M - 1
        for r in range(3):
            Pyy[r, c] /= M - 1
        Pyy[c, c] += r_var
    Si = inv3_sym(Pyy)
    K = np.empty((ns, 3))
    for r in range(ns):
        for c in range(3):
            K[r, c] = Psy[r, 0] * Si[0, c] + Psy[r, 1] * Si[1, c] + Psy[r, 2] * Si[2, c]
    sd = math.sqrt(r_var)
    innov = np.empty(3)
    for j in range(M):
        for k in range(3):
            innov[k] = z[k] + sd * pert[j, offset + k] - y[j, k]
        for r in range(ns):
            ens[j, r] += K[r, 0] * innov[0] + K[r, 1] * innov[1] + K[r, 2] * innov[2]
    _renormalise(ens)
    nis = 0.0
    for r in range(3):
        for c in range(3):
            nis += (z[r] - ybar[r]) * Si[r, c] * (z[c] - ybar[c])
    return nis


@numba.njit(cache=True)
def run_ensemble(ens: np.ndarray, memory: np.ndarray, samples: ImuSamples, i0: int, i1: int, params: FilterParams,
                 alpha: float, noise: np.ndarray, mean: np.ndarray, history: FilterHistory) -> None:
    """Process samples i0 ≤ i < i1 (i0 ≥ 1) as the module docstring says; ``alpha`` < 0:
    enekf, ``alpha`` ≥ 0: cenekf with colour factor α (``ens`` then has 19 columns).

    ``ens`` (M, n_s) and ``memory`` (M, 6) (each member's two-sample mechanisation memory)
    are updated in place; ``noise`` (i1 − i0, M, 21) holds the draws; ``mean`` (n_s,)
    receives the ensemble mean after the last sample; of the ``history``, row i of ``hist_x``
    (N, 16) and ``hist_cov`` (N, 13) the mean nominal state and the members' covariance
    entries (:data:`~bodyfusion.plugins.foot_ins.records.RECORDED_COVARIANCE`; velocity and
    attitude from the members' error-state deviations) (the ensemble keeps no NIS: ``hist_nis``
    is not written), ``counters`` accumulates [ZUPTs, ZARUs, sum of
    ZUPT NIS].
    """
    t, acc_b, gyro_b, stance = samples
    hist_x, hist_cov, _, counters = history
    M = ens.shape[0]
    g = params.gravity
    w_ie = params.earth_rate.copy()
    zupt_sigma = params.zupt_sigma
    zaru_sigma = params.zaru_sigma
    coloured = alpha >= 0.0
    f_n = np.empty(3)
    C_nb = np.empty((3, 3))  # C_nb of a member's step (not used here)
    a = np.empty(3)
    w = np.empty(3)
    zero = np.zeros(3)
    z = np.empty(3)
    D = np.empty((M, 15))  # the members' error-state deviations from the mean
    basis = np.empty((M, ens.shape[1] + NOISE_WIDTH))
    used = np.zeros(NOISE_WIDTH, dtype=np.bool_)  # the draws this filter uses
    for k in range(12):
        used[k] = True
    for k in range(3):
        used[12 + k] = coloured
        used[15 + k] = not coloured
        used[18 + k] = zaru_sigma > 0
    exact = M - 1 >= ens.shape[1] + np.sum(used)
    for i in range(i0, i1):
        dt = t[i] - t[i - 1]
        nz = noise[i - i0]
        if exact:
            improve_sampling(ens, nz, used, basis)
        sa = params.acc_noise_density / math.sqrt(dt)
        sg = params.gyro_noise_density / math.sqrt(dt)
        sba = params.acc_bias_walk * math.sqrt(dt)
        sbg = params.gyro_bias_walk * math.sqrt(dt)
        for j in range(M):
            for k in range(3):
                a[k] = acc_b[i, k] + sa * nz[j, k]
                w[k] = gyro_b[i, k] + sg * nz[j, 3 + k]
            mechanise(ens[j], a, w, dt, g, w_ie, f_n, memory[j], C_nb)
            for k in range(3):
                ens[j, 10 + k] += sba * nz[j, 6 + k]
                ens[j, 13 + k] += sbg * nz[j, 9 + k]
            if coloured:
                for k in range(3):
                    ens[j, 16 + k] = alpha * ens[j, 16 + k] + zupt_sigma * nz[j, 12 + k]
        if stance[i]:
            # np.int64, not bare integers: numba types a constant argument as a literal, one
            # compilation per value (three of this kernel, 1.8 s more of a cold start)
            if coloured:
                nis = ensemble_analysis(ens, np.int64(3), np.int64(16), zero, 0.0, nz, np.int64(15))
            else:
                nis = ensemble_analysis(ens, np.int64(3), np.int64(-1), zero, zupt_sigma * zupt_sigma, nz,
                                        np.int64(15))
            counters[C_NIS_SUM] += nis
            counters[C_ZUPTS] += 1
            if zaru_sigma > 0:
                for k in range(3):
                    z[k] = gyro_b[i, k]
                ensemble_analysis(ens, np.int64(13), np.int64(-1), z, zaru_sigma * zaru_sigma, nz, np.int64(18))
                counters[C_ZARUS] += 1
        ensemble_mean(ens, mean)
        for k in range(16):
            hist_x[i, k] = mean[k]
        for k in range(3):
            s = 0.0
            for j in range(M):
                d = ens[j, k] - mean[k]
                s += d * d
            hist_cov[i, k] = s / (M - 1)
        s = 0.0
        for j in range(M):
            s += (ens[j, 0] - mean[0]) * (ens[j, 1] - mean[1])
        hist_cov[i, 3] = s / (M - 1)
        _record_motion_covariance(ens, mean, D, hist_cov[i])
