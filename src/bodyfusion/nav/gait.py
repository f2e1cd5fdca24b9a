"""Gait timing from a foot-worn IMU: the stride period, wherever the recording is.

A foot repeats its motion once per stride (one gait cycle: from a stance of that foot to its
next). Walking strides take 1.0–1.4 s, running ones 0.6–0.8 s, a slow shuffle or a stair
climb up to ~2 s. Detectors and watchdogs that must follow the gait measure it in strides,
not seconds: :func:`stride_period` finds the period locally, from the autocorrelation of a
signal that repeats with the stride (the log SHOE statistic, or the angular rate's norm).

Method: the signal is cut in windows of :data:`PERIOD_WINDOW_S` every :data:`PERIOD_HOP_S`;
in each, the normalised autocorrelation (FFT, mean removed) is searched for local maxima at
lags in [:data:`MIN_STRIDE_S`, :data:`MAX_STRIDE_S`], and the shortest one within
:data:`HARMONIC_RATIO` of the highest is the period (two strides repeat too). A window whose best
peak is below :data:`MIN_PERIODICITY` holds no gait (standing, fidgeting, an irregular
motion): its period is NaN. Between window centres the period is interpolated.
"""

from __future__ import annotations

import functools

import numpy as np

MIN_STRIDE_S = 0.45
"""Shortest stride period looked for, s (a sprint's ~0.55 s, with room)."""
MAX_STRIDE_S = 2.5
"""Longest stride period looked for, s (a slow shuffle or a stair climb)."""
PERIOD_WINDOW_S = 8.0
"""Length of the windows whose autocorrelation gives the period, s (several strides)."""
PERIOD_HOP_S = 1.0
"""Spacing of the windows, s."""
HARMONIC_RATIO = 0.85
"""A shorter lag whose autocorrelation peak reaches this share of the highest is the period."""
WINDOWS_KEPT = 1024
"""Windows whose stride lag :func:`_best_lag` keeps (about 4 MB at 100 Hz)."""
MIN_PERIODICITY = 0.3
"""Normalised autocorrelation at the period below which a window holds no gait."""


def _best_lag(x: np.ndarray, lo: int, hi: int) -> tuple[int, float]:
    """The stride lag of ``x``: among the local maxima of its normalised autocorrelation (mean
    removed) at lags in [lo, hi], the shortest within :data:`HARMONIC_RATIO` of the highest
    (the fundamental, not a multiple of it); and its value. (0, 0) when there is none. A window
    met before (its samples bit for bit: a live run derives the same windows on each pass,
    :mod:`bodyfusion.plugins.foot_ins.streaming`) is answered from :func:`_best_lag_of`'s cache."""
    return _best_lag_of(np.ascontiguousarray(x, dtype=np.float64).tobytes(), lo, hi)


@functools.lru_cache(maxsize=WINDOWS_KEPT)
def _best_lag_of(samples: bytes, lo: int, hi: int) -> tuple[int, float]:
    """:func:`_best_lag` of the window whose float64 samples are ``samples``."""
    x = np.frombuffer(samples, dtype=np.float64)
    x = x - x.mean()
    n = x.size
    spectrum = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    if acf[0] <= 0.0:
        return 0, 0.0
    acf = acf / acf[0]
    hi = min(hi, n - 2)
    if hi <= lo:
        return 0, 0.0
    seg = acf[lo - 1:hi + 2]
    peaks = np.flatnonzero((seg[1:-1] > seg[:-2]) & (seg[1:-1] >= seg[2:])) + lo
    if peaks.size == 0:
        return 0, 0.0
    top = acf[peaks].max()
    if top <= 0.0:
        return 0, 0.0
    best = int(peaks[np.flatnonzero(acf[peaks] >= HARMONIC_RATIO * top)[0]])
    return best, float(acf[best])


def stride_period(signal: np.ndarray, rate_hz: float) -> np.ndarray:
    """The local stride period (s) at every sample of ``signal`` (N,), sampled at ``rate_hz``
    (module docstring); NaN where no gait repeats. A recording shorter than a window is one
    window."""
    x = np.asarray(signal, dtype=float)
    n = x.size
    out = np.full(n, np.nan)
    if n == 0:
        return out
    width = min(n, int(round(PERIOD_WINDOW_S * rate_hz)))
    hop = max(1, int(round(PERIOD_HOP_S * rate_hz)))
    lo, hi = int(np.ceil(MIN_STRIDE_S * rate_hz)), int(MAX_STRIDE_S * rate_hz)
    starts = list(range(0, max(1, n - width + 1), hop))
    if starts[-1] != n - width:
        starts.append(max(0, n - width))
    centres, periods = [], []
    for a in starts:
        lag, r = _best_lag(x[a:a + width], lo, hi)
        centres.append(a + width / 2)
        periods.append(lag / rate_hz if r >= MIN_PERIODICITY else np.nan)
    centres_a, periods_a = np.asarray(centres), np.asarray(periods)
    ok = np.isfinite(periods_a)
    if not ok.any():
        return out
    i = np.arange(n)
    out = np.interp(i, centres_a[ok], periods_a[ok])
    nearest = np.searchsorted(0.5 * (centres_a[:-1] + centres_a[1:]), i)  # the window a sample is closest to
    out[~ok[nearest]] = np.nan  # no gait there
    return out
