"""Pedestrian dead reckoning from a hand-held phone's IMU: steps, step lengths, heading rate.

Frames: phone (body) frame as the IMU reports it; specific force m/s^2, rate rad/s.
Everything is vectorised over the whole stream (the phone log is read at once); the
filter then walks the detected steps in time order.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from bodyfusion.plugins.hand_pdr.config import StepConfig


@dataclass
class PdrInputs:
    """What the PDR filter takes from the phone's IMU samples: ``step_index`` (sample of each step),
    ``step_length_m`` (m, before the step scale), ``up_b`` (N, 3: Up in the phone frame),
    ``azimuth`` (N: cumulative azimuth change, rad, :func:`azimuth_increments`) and ``steady``
    (N: held steadily, :func:`held_steadily`)."""

    step_index: np.ndarray
    step_length_m: np.ndarray
    up_b: np.ndarray
    azimuth: np.ndarray
    steady: np.ndarray


@functools.lru_cache(maxsize=32)
def _butterworth(cutoff: float) -> np.ndarray:
    """Second-order sections of the 2nd-order Butterworth low-pass at ``cutoff`` (a fraction of the
    Nyquist rate): designed once for each (a live run filters every pass)."""
    # imported here: scipy.signal (which imports scipy.stats) is slow to import, and a run
    # without a phone loads this plugin but never filters
    from scipy.signal import butter

    return butter(2, cutoff, output="sos")


def lowpass(x: np.ndarray, rate_hz: float, cutoff_hz: float) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass along axis 0."""
    from scipy.signal import sosfiltfilt

    return sosfiltfilt(_butterworth(min(cutoff_hz / (0.5 * rate_hz), 0.99)), x, axis=0)


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


MISSED_STEPS = 1.6
"""A gap between detected steps longer than this many step periods holds missed steps."""
MISSED_STEP_SHARE = 0.6
"""A missed step's peak is at least this share of the median peak of the steps detected within
:data:`NEIGHBOURS_S` of it: softer than its neighbours, not a phone resting between walks."""
NEIGHBOURS_S = 5.0
"""Span (s) on each side of a gap whose detected steps set the height a missed step must reach."""


def detect_steps(t: np.ndarray, acc_b: np.ndarray, cfg: StepConfig, gravity: float) -> np.ndarray:
    """Sample indices of steps: peaks of the low-passed ‖f‖ − g above the threshold, at least
    ``min_interval_s`` apart (debounced); then the steps the threshold missed while the walk
    goes on (a soft step, a phone held more gently), as the foot INS's watchdog finds its
    missed stances: where the signal repeats with a step period P
    (:func:`bodyfusion.nav.gait.stride_period` of ‖f‖ − g: one cycle per step), a gap between
    detected steps longer than :data:`MISSED_STEPS` P is cut into periods, and the highest peak
    of each is a step if it reaches :data:`MISSED_STEP_SHARE` of its neighbours' median."""
    from scipy.signal import find_peaks

    from bodyfusion.nav.gait import stride_period

    rate = 1.0 / np.median(np.diff(t))
    a = lowpass(np.linalg.norm(acc_b, axis=1) - gravity, rate, cfg.lowpass_hz)
    distance = max(1, int(round(cfg.min_interval_s * rate)))
    peaks, _ = find_peaks(a, height=cfg.threshold_mps2, distance=distance)
    period = stride_period(a, rate) * rate  # samples per step; NaN where nothing repeats
    fills: list[int] = []
    if not np.isfinite(period).any():
        return peaks
    shortest = float(np.nanmin(period))  # no gap shorter than MISSED_STEPS of it can hold a missed step
    for lo, hi in zip(np.concatenate([[0], peaks]), np.concatenate([peaks, [a.size]])):
        if hi - lo <= MISSED_STEPS * shortest:
            continue
        p = float(np.nanmedian(period[lo:hi])) if np.isfinite(period[lo:hi]).any() else np.nan
        if not p > 0 or hi - lo <= MISSED_STEPS * p:
            continue
        near = peaks[(peaks >= lo - NEIGHBOURS_S * rate) & (peaks <= hi + NEIGHBOURS_S * rate)]
        floor = MISSED_STEP_SHARE * float(np.median(a[near])) if near.size else np.inf
        cycles = max(1, int(round((hi - lo) / p)) - 1)  # whole steps strictly between the two
        for c0, c1 in zip(np.linspace(lo + 0.5 * p, hi - 0.5 * p, cycles + 1)[:-1].astype(int),
                          np.linspace(lo + 0.5 * p, hi - 0.5 * p, cycles + 1)[1:].astype(int)):
            if c1 > c0:
                k = c0 + int(np.argmax(a[c0:c1]))
                if a[k] >= floor and k - max([lo, *fills[-1:]]) >= distance:
                    fills.append(k)
    return np.sort(np.concatenate([peaks, np.asarray(fills, dtype=peaks.dtype)]))


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
