"""Pedestrian dead reckoning from a hand-held phone's IMU: steps, step lengths, heading rate.

Frames: phone (body) frame as the IMU reports it; specific force m/s^2, rate rad/s.
Everything is vectorised over the whole stream (the phone log is read at once); the
filter then walks the detected steps in time order.

The low-pass filter and the peak picking compute what scipy.signal's ``sosfiltfilt`` of a
``butter(2, …, output="sos")`` and ``find_peaks`` compute, bit for bit (the same operations
in the same order; the per-sample recursion compiled), without importing scipy.signal (over
a second, with the scipy.stats it imports).
"""

from __future__ import annotations

import numpy as np

from bodyfusion.plugins.hand_pdr.config import StepConfig
from bodyfusion.plugins.hand_pdr.kernels import biquad

PAD = 9
"""Samples of odd extension at each end of a zero-phase pass: 3 × (2 × 1 section + 1), scipy's default."""


def butterworth_sos(wn: float) -> np.ndarray:
    """Second-order section (b0, b1, b2, 1, a1, a2) of the digital 2nd-order Butterworth low-pass
    of cutoff ``wn`` (fraction of the Nyquist frequency, 0 < wn < 1), by the bilinear transform
    (fs = 2) of the analog prototype prewarped to ω = 4 tan(π wn / 2): analog poles
    p = −ω e^{±iπ/4}, digital pole z = (4 + p) / (4 − p), double zero at −1, gain
    k = ω² Re(1 / ((4 − p₁)(4 − p₂))); a1 = −2 Re z, a2 = |z|²."""
    w = 4.0 * np.tan(np.pi * wn / 2.0)
    p = w * -np.exp(1j * np.pi * np.array([-1.0, 1.0]) / 4)
    k = w**2 * np.real(1.0 / np.prod(4.0 - p))
    z = (4.0 + p[1]) / (4.0 - p[1])
    return np.array([k, 2.0 * k, k, 1.0, -2.0 * z.real, z.real * z.real + z.imag * z.imag])


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass along axis 0 of x (N,) or (N, m), N > :data:`PAD`:
    the section of :func:`butterworth_sos` (cutoff at most 0.99 of Nyquist) run forward over x
    extended at each end by :data:`PAD` samples of odd reflection (2 x₀ − x_k), then backward;
    each pass starts in the section's steady state for its first sample (zi = x₀ z_ss, z_ss
    solving z = A z + B of the transposed direct form II)."""
    if x.shape[0] <= PAD:
        raise ValueError(f"The length of the input vector x must be greater than padlen, which is {PAD}.")
    sos = butterworth_sos(min(cutoff_hz / (0.5 * rate_hz), 0.99))
    b, a = sos[:3], sos[3:]
    steady = np.linalg.solve(np.array([[1.0 + a[1], -1.0], [a[2], 1.0]]), b[1:] - a[1:] * b[0])
    columns = x.reshape(x.shape[0], -1)
    ext = np.concatenate((2 * columns[0:1] - columns[PAD:0:-1], columns,
                          2 * columns[-1:] - columns[-2:-(PAD + 2):-1])).T.copy()
    biquad(sos, ext, np.multiply.outer(ext[:, 0], steady))
    ext = ext[:, ::-1].copy()
    biquad(sos, ext, np.multiply.outer(ext[:, 0], steady))
    return ext[:, -1 - PAD:PAD - 1:-1].T.reshape(x.shape)


def find_peaks(a: np.ndarray, height: float, distance: int) -> np.ndarray:
    """Indices of the peaks of ``a`` (N,) at least ``height`` high, at least ``distance`` (≥ 1)
    samples apart. A peak is a sample, or the middle (rounded down) of a run of equal samples,
    whose neighbours on both sides are lower (not the first or last sample). Of peaks closer
    than ``distance``, the highest is kept and its neighbours within the distance dropped,
    highest first (ties in the order of a quicksort of the heights)."""
    change = np.flatnonzero(a[1:] != a[:-1]) + 1  # the runs of equal samples: [first, last]
    first, last = np.concatenate([[0], change]), np.concatenate([change - 1, [len(a) - 1]])
    inner = (first >= 1) & (last <= len(a) - 2)
    first, last = first[inner], last[inner]
    top = a[first]
    peaks = ((first + last) // 2)[(a[first - 1] < top) & (a[last + 1] < top) & (top >= height)]
    keep = np.ones(len(peaks), dtype=bool)
    for j in np.argsort(a[peaks])[::-1]:
        if keep[j]:
            k = j - 1
            while k >= 0 and peaks[j] - peaks[k] < distance:
                keep[k] = False
                k -= 1
            k = j + 1
            while k < len(peaks) and peaks[k] - peaks[j] < distance:
                keep[k] = False
                k += 1
    return peaks[keep]


def up_in_body(t: np.ndarray, acc_b: np.ndarray, cutoff_hz: float = 0.3) -> np.ndarray:
    """(N, 3) unit vector of Up in the phone frame: the low-passed specific force direction."""
    rate = 1.0 / np.median(np.diff(t))
    g_b = lowpass(acc_b, rate, cutoff_hz)
    return g_b / np.linalg.norm(g_b, axis=1, keepdims=True)


def pose_change(t: np.ndarray, up_b: np.ndarray, window_s: float) -> np.ndarray:
    """(N,) angle (rad) by which the Up direction in the phone frame ``up_b`` (N, 3, unit)
    turned over the last ``window_s`` (0 within the first window): how much the way the phone
    is held changed (into a pocket, swinging, raised to read)."""
    j = np.maximum(np.searchsorted(t, t - window_s), 0)
    return np.arccos(np.clip(np.einsum("ij,ij->i", up_b, up_b[j]), -1.0, 1.0))


def held_steadily(t: np.ndarray, up_b: np.ndarray, window_s: float, max_change_rad: float) -> np.ndarray:
    """(N,) True where the phone has been held steadily for ``window_s``: no :func:`pose_change`
    above ``max_change_rad`` within the last ``window_s`` (one tip up and back, whose
    2-s change dips at its top, is one handling, not two)."""
    moved = np.concatenate([[0], np.cumsum(pose_change(t, up_b, window_s) > max_change_rad)])
    j = np.maximum(np.searchsorted(t, t - window_s), 0)
    return moved[1:] - moved[j] == 0


def azimuth_increments(t: np.ndarray, gyro_b: np.ndarray, up_b: np.ndarray) -> np.ndarray:
    """(N,) cumulative change of azimuth (rad, clockwise from North) from the rate about Up:
    levelled gyro integration, ψ̇ = −ω_b · u_b (trapezoidal; 0 at the first sample)."""
    yaw_rate = np.einsum("ij,ij->i", gyro_b, up_b)
    dt = np.diff(t)
    return np.concatenate([[0.0], np.cumsum(-0.5 * (yaw_rate[1:] + yaw_rate[:-1]) * dt)])


def detect_steps(t: np.ndarray, acc_b: np.ndarray, cfg: StepConfig, gravity: float) -> np.ndarray:
    """Sample indices of steps: peaks of the low-passed ‖f‖ − g above the threshold, at least
    ``min_interval_s`` apart (debounced)."""
    rate = 1.0 / np.median(np.diff(t))
    a = lowpass(np.linalg.norm(acc_b, axis=1) - gravity, rate, cfg.lowpass_hz)
    return find_peaks(a, cfg.threshold_mps2, max(1, int(round(cfg.min_interval_s * rate))))


def weinberg_features(t: np.ndarray, acc_b: np.ndarray, steps: np.ndarray, cfg: StepConfig) -> np.ndarray:
    """(a_max − a_min)^(1/4) of the low-passed ‖f‖ (m/s^2) over the samples since the previous
    step (the first step: the same span before it), one per step."""
    rate = 1.0 / np.median(np.diff(t))
    a = lowpass(np.linalg.norm(acc_b, axis=1), rate, cfg.lowpass_hz)
    bounds = np.concatenate([[max(0, steps[0] - (steps[1] - steps[0] if len(steps) > 1 else int(rate)))], steps])
    span = a[:bounds[-1] + 1]  # step k spans bounds[k]..bounds[k + 1], both ends included
    high = np.maximum(np.maximum.reduceat(span, bounds[:-1]), a[bounds[1:]])
    low = np.minimum(np.minimum.reduceat(span, bounds[:-1]), a[bounds[1:]])
    return np.maximum(high - low, 0.0) ** 0.25


def step_lengths(t: np.ndarray, acc_b: np.ndarray, steps: np.ndarray, cfg: StepConfig) -> np.ndarray:
    """Length (m) of each step: Weinberg's K·(a_max − a_min)^(1/4), or constant."""
    if cfg.length == "constant" or len(steps) == 0:
        return np.full(len(steps), cfg.constant_m)
    return cfg.weinberg_k * weinberg_features(t, acc_b, steps, cfg)


def calibrate_weinberg_k(t: np.ndarray, acc_b: np.ndarray, distance_m: float, cfg: StepConfig,
                         gravity: float) -> float:
    """K such that the steps of a walk of known length ``distance_m`` (m) add up to it."""
    steps = detect_steps(t, acc_b, cfg, gravity)
    features = weinberg_features(t, acc_b, steps, cfg)
    if features.sum() <= 0:
        raise ValueError("no steps to calibrate on")
    return float(distance_m / features.sum())
