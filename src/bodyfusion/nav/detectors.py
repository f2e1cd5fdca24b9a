"""The statistics and tests of the zero-velocity (stance) detectors, and stance post-processing.

The detectors themselves, with their parameters' defaults, are the model classes of
:mod:`bodyfusion.nav.stance_detectors`; these functions take every parameter explicitly.
Inputs: body-frame specific force ``acc_b`` (N, 3) in m/s^2 (about +g along the up-pointing
axis at rest) and angular rate ``gyro_b`` (N, 3) in rad/s; a stance array is (N,) bool, True =
the foot at rest. Per-sample work is done in numba kernels or vectorised numpy.

Sources
-------
- SHOE / GLRT: I. Skog, P. Händel, J.-O. Nilsson, J. Rantakokko,
  "Zero-velocity detection - An algorithm evaluation", IEEE Trans. Biomed.
  Eng. 57(11), 2010, doi:10.1109/TBME.2010.2060723; statistic and stance
  marking as in the OpenShoe Matlab implementation (``zero_velocity_detector.m``).
- Acceleration magnitude: Y. Xu, J. Yu, X. Wang, T. Li, M. Sun, "Dual
  foot-mounted localisation scheme employing a minimum-distance-constraint
  Kalman filter under coloured measurement noise", Micromachines 15(11):1346,
  2024, Sec. 2 (threshold ``t_d`` on ``VAcc = sqrt(ax^2 + ay^2 + az^2)``).
- Axes-sum band: L. Deng, J. Yu, M. Li, Q. Zhao, Y. Xu, "Distance constraint
  ensemble Kalman filter for pedestrian localization", Micromachines 17:436,
  2026, Sec. 2.2 (``Z_th_down < f_x + f_y + f_z < Z_th_up``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = [
    "acceleration_magnitude",
    "adaptive_shoe_threshold",
    "axes_sum_band",
    "debounce",
    "shoe_statistic",
    "spread_windows",
    "stance_events",
]


def _as_n3(x: np.ndarray, name: str) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {a.shape}")
    return a


def _check_window(window: int) -> int:
    w = int(window)
    if w < 1 or w != window:
        raise ValueError(f"window must be a positive integer number of samples, got {window!r}")
    return w


def _centred_mean(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average over ``window`` samples; shrinks at the ends.

    For even ``window`` the extra sample is taken before the centre.
    """
    n = x.shape[0]
    if window == 1 or n == 0:
        return x.astype(np.float64, copy=True)
    c = np.concatenate(([0.0], np.cumsum(x, dtype=np.float64)))
    i = np.arange(n)
    lo = np.maximum(i - window // 2, 0)
    hi = np.minimum(i - window // 2 + window, n)
    return (c[hi] - c[lo]) / (hi - lo)


# --------------------------------------------------------------------------- SHOE


@numba.njit(cache=True)
def _shoe_kernel(acc, gyro, window, inv_var_a, inv_var_g, g):  # pragma: no cover - compiled
    n = acc.shape[0]
    m = n - window + 1
    out = np.empty(m)
    for k in range(m):
        mx = 0.0
        my = 0.0
        mz = 0.0
        for l in range(k, k + window):
            mx += acc[l, 0]
            my += acc[l, 1]
            mz += acc[l, 2]
        norm = math.sqrt(mx * mx + my * my + mz * mz)
        if norm > 0.0:
            ux = g * mx / norm
            uy = g * my / norm
            uz = g * mz / norm
        else:
            ux = 0.0
            uy = 0.0
            uz = 0.0
        s = 0.0
        for l in range(k, k + window):
            dx = acc[l, 0] - ux
            dy = acc[l, 1] - uy
            dz = acc[l, 2] - uz
            wx = gyro[l, 0]
            wy = gyro[l, 1]
            wz = gyro[l, 2]
            s += (dx * dx + dy * dy + dz * dz) * inv_var_a + (wx * wx + wy * wy + wz * wz) * inv_var_g
        out[k] = s / window
    return out


@numba.njit(cache=True)
def spread_windows(passed, window, n):  # pragma: no cover - compiled
    """Stance flags (N,) from per-window verdicts ``passed`` (N − W + 1,): as OpenShoe marks them,
    stance[i] = any(passed[k] for the windows k = i − W + 1 .. i that exist)."""
    out = np.zeros(n, dtype=np.bool_)
    last = -1  # last window start that passed, seen so far
    m = passed.shape[0]
    for i in range(n):
        if i < m and passed[i]:
            last = i
        if last >= 0 and i - last < window:
            out[i] = True
    return out


def shoe_statistic(acc_b: np.ndarray, gyro_b: np.ndarray, *, window: int, sigma_acc: float, sigma_gyro: float,
                   gravity: float) -> np.ndarray:
    """SHOE (GLRT) test statistic of Skog et al. (2010), one value per window.

    For the window of ``W`` samples starting at sample ``k`` (k = 0 .. N-W)::

        T_k = (1/W) * sum_{l=k}^{k+W-1} [ ||a_l - g * abar / ||abar|| ||^2 / sigma_acc^2
                                          + ||w_l||^2 / sigma_gyro^2 ]

    with ``abar`` the window mean of ``acc_b``.  Units: ``sigma_acc`` m/s^2,
    ``sigma_gyro`` rad/s, ``gravity`` m/s^2; ``T`` is dimensionless.  Returns
    an (N - W + 1,) array (empty when N < W).
    """
    acc = _as_n3(acc_b, "acc_b")
    gyro = _as_n3(gyro_b, "gyro_b")
    if acc.shape != gyro.shape:
        raise ValueError(f"acc_b {acc.shape} and gyro_b {gyro.shape} differ in length")
    w = _check_window(window)
    if not (sigma_acc > 0 and sigma_gyro > 0):
        raise ValueError("sigma_acc and sigma_gyro must be positive")
    if acc.shape[0] < w:
        return np.empty(0)
    return _shoe_kernel(acc, gyro, w, 1.0 / sigma_acc**2, 1.0 / sigma_gyro**2, float(gravity))


# --------------------------------------------------------------------------- adaptive SHOE


def adaptive_shoe_threshold(statistic: np.ndarray, period_s: np.ndarray, rate_hz: float, *, gamma_still: float,
                            gamma_motion: float, margin_decades: float, prominence_decades: float) -> np.ndarray:
    """Per-window threshold γ_k for the SHOE statistic T_k, from the gait cycle around each window.

    The statistic of a foot at rest sits at the sensor's noise level; in a walking stance the
    foot rolls and T dips to 10²–10⁴ (OpenShoe scaling, σ_a = 0.01 m/s^2, σ_ω = 0.1 °/s); in a
    running stance, 0.1–0.2 s long with the foot never quite still, only to 10⁴–3·10⁵, above
    any fixed threshold fit for walking. Each gait cycle has one stance, at its lowest T. So,
    with P_k the stride period at window k (``period_s``, s, per window; NaN: no gait there,
    :func:`bodyfusion.nav.gait.stride_period`), the *cycle floor* f_k and *cycle peak* h_k are
    the least and largest log₁₀ T over the P_k centred on k, and

        log₁₀ γ_k = clip(f_k + margin_decades, log₁₀ gamma_still, log₁₀ gamma_motion)

    where the cycle's stance stands out of its swing (h_k − f_k ≥ ``prominence_decades``), else
    log₁₀ gamma_still: what is still at OpenShoe's threshold is always stance; a gait's stance
    is ``margin_decades`` above its own cycle's floor, whatever the gait; nothing whose RMS
    angular rate exceeds ~5 rad/s (``gamma_motion``) is. ``rate_hz`` (Hz) converts periods to
    windows. Returns an array shaped like ``statistic``.
    """
    # imported here: only adaptive thresholds need it, and scipy.ndimage is slow to import
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    z = np.log10(np.maximum(np.asarray(statistic, dtype=float), 1e-300))
    log_gamma = np.full(z.size, np.log10(gamma_still))
    period = np.asarray(period_s, dtype=float)[: z.size]
    gait = np.isfinite(period)
    if not gait.any():
        return 10.0**log_gamma
    # cycle floors and peaks on a few quantised window lengths (one filter pass each)
    lengths = np.maximum(3, np.round(period[gait] * rate_hz / PERIOD_STEP_SAMPLES) * PERIOD_STEP_SAMPLES).astype(int)
    floor = np.empty(lengths.size)
    peak = np.empty(lengths.size)
    for length in np.unique(lengths):
        use = lengths == length
        floor[use] = minimum_filter1d(z, int(length), mode="nearest")[gait][use]
        peak[use] = maximum_filter1d(z, int(length), mode="nearest")[gait][use]
    lifted = np.clip(floor + margin_decades, np.log10(gamma_still), np.log10(gamma_motion))
    log_gamma[gait] = np.where(peak - floor >= prominence_decades, lifted, log_gamma[gait])
    return 10.0**log_gamma


PERIOD_STEP_SAMPLES = 8
"""Cycle windows (:func:`adaptive_shoe_threshold`) are whole multiples of this many samples."""


# --------------------------------------------------------------------------- magnitude


def acceleration_magnitude(acc_b: np.ndarray, *, threshold: float, gravity: float, window: int) -> np.ndarray:
    """Acceleration-magnitude stance detector of [Xu2024].

    The paper (Sec. 2, Eq. for ``VAcc``) computes ``VAcc_t = sqrt(ax^2 + ay^2 +
    az^2)`` and declares stance by comparing it with a threshold ``t_d``; the
    comparison operator is lost in the published text and no value is given.
    A one-sided test on ``VAcc`` cannot isolate rest (``VAcc`` ~ g at rest, and
    both above and below g in swing), so we use the deviation from gravity::

        stance_t = | mean_window(VAcc)_t - gravity | <= threshold

    ``threshold`` and ``gravity`` in m/s^2; ``window`` (samples) is an optional
    centred moving average of ``VAcc`` (1 = the paper's per-sample test).
    """
    acc = _as_n3(acc_b, "acc_b")
    w = _check_window(window)
    mag = np.sqrt(np.einsum("ij,ij->i", acc, acc))
    mag = _centred_mean(mag, w)
    return np.abs(mag - gravity) <= threshold


# --------------------------------------------------------------------------- axes sum


def axes_sum_band(acc_b: np.ndarray, *, low: float, high: float, window: int) -> np.ndarray:
    """Axes-sum band stance detector of [Deng2026].

    Sec. 2.2: "the sum of the values along the three axes in the b-frame is
    used as the initial reference for ZUPT", stance when::

        Z_th_down < f_x + f_y + f_z < Z_th_up

    (plain signed sum, strict inequalities, as printed).  ``low`` = Z_th_down
    and ``high`` = Z_th_up are in the units of ``acc_b``, m/s^2; the paper
    gives no values.  At rest the sum equals ``g * (ux + uy + uz)`` for the
    unit up-vector ``u`` in the body frame, so the band depends on how the
    sensor is mounted (about [g - d, g + d] when one axis points up).
    ``window`` (samples) optionally smooths the sum with a centred moving
    average first.
    """
    acc = _as_n3(acc_b, "acc_b")
    w = _check_window(window)
    if not low < high:
        raise ValueError(f"need low < high, got low={low}, high={high}")
    s = _centred_mean(acc.sum(axis=1), w)
    return (s > low) & (s < high)


# --------------------------------------------------------------------------- post-processing


def _runs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run-length encoding: (starts, ends exclusive, values)."""
    n = x.shape[0]
    if n == 0:
        e = np.empty(0, dtype=np.int64)
        return e, e, np.empty(0, dtype=bool)
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    starts = np.concatenate(([0], change)).astype(np.int64)
    ends = np.concatenate((change, [n])).astype(np.int64)
    return starts, ends, x[starts]


def _as_bool1(stance: np.ndarray) -> np.ndarray:
    s = np.asarray(stance)
    if s.ndim != 1:
        raise ValueError(f"stance must be 1-D, got shape {s.shape}")
    return s.astype(bool)


def debounce(stance: np.ndarray, *, min_stance: int, min_swing: int) -> np.ndarray:
    """Clean a stance sequence: fill short swing gaps, then drop short stance runs.

    1. Every swing gap *between two stance runs* shorter than ``min_swing``
       samples becomes stance (a swing run touching either end of the record
       is not a gap and is never filled: there is no evidence of rest there).
    2. Every stance run (after step 1) shorter than ``min_stance`` samples
       becomes swing, including runs touching the ends of the record.

    Filling first lets a stance phase broken by a one-sample flicker survive
    step 2 as one run.  ``min_stance`` / ``min_swing`` <= 1 disable a step.
    Returns a new bool array.
    """
    s = _as_bool1(stance).copy()
    n = s.shape[0]
    if n == 0:
        return s
    starts, ends, vals = _runs(s)
    if min_swing > 1:
        lengths = ends - starts
        interior = (starts > 0) & (ends < n)
        fill = (~vals) & interior & (lengths < min_swing)
        if fill.any():
            s[_mask_from_runs(starts[fill], ends[fill], n)] = True
            starts, ends, vals = _runs(s)
    if min_stance > 1:
        lengths = ends - starts
        kill = vals & (lengths < min_stance)
        if kill.any():
            s[_mask_from_runs(starts[kill], ends[kill], n)] = False
    return s


def _mask_from_runs(starts: np.ndarray, ends: np.ndarray, n: int) -> np.ndarray:
    d = np.zeros(n + 1, dtype=np.int64)
    np.add.at(d, starts, 1)
    np.add.at(d, ends, -1)
    return np.cumsum(d[:-1]) > 0


def stance_events(stance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start indices and exclusive end indices of the stance runs.

    ``stance[starts[i]:ends[i]]`` is all True and maximal.  Both are int64.
    """
    s = _as_bool1(stance)
    starts, ends, vals = _runs(s)
    return starts[vals], ends[vals]
