"""Initial (coarse) alignment of a strapdown IMU: find where it is at rest, level it there.

A recording rarely starts with the sensor still for a known time: people start walking as
soon as the logger runs. So the still interval is looked for in the data:

* :func:`window_spreads` — the spread of the specific force and of the angular rate over
  every window of ``L`` samples: s_f = √(Σ_axes var f) (m/s^2), s_ω = √(Σ_axes var ω)
  (rad/s); computed with running sums, O(N).
* :func:`find_still_interval` — the first window whose two spreads are within
  ``STILL_NOISE_FACTOR`` times the recording's own noise floor (the smallest window
  spread: a sensor at rest shows only its noise, ~0.01–0.1 m/s^2 and ~0.002–0.02 rad/s
  for MEMS IMUs) and within absolute limits (a foot in a walking stance of that length
  rolls, and heel strike and toe-off fall inside), grown to the whole run of still
  windows. The factor keeps out the shuffling before a walk, whose mean rate would pass
  for gyro bias. When there is none, the first of the *quietest* windows of the recording
  (a score s_f/f_lim + s_ω/ω_lim within the same factor of its smallest: the earliest, so that
  little is navigated backward), grown the same way and flagged as not still so that the
  caller widens its priors.
* :func:`attitude_from_specific_force` — TRIAD levelling: the mean specific force over the
  interval is "up" in the body frame; the heading is the azimuth of the horizontal
  projection of a named body axis (x by default), which is defined for any mounting except
  with that axis vertical (:func:`heading_axis` picks another then).

Frames: body b (the IMU's axes after the layout's axis map), navigation n = ENU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

AXIS_VECTORS = {"x": np.array([1.0, 0.0, 0.0]), "y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}

STILL_NOISE_FACTOR = 1.5
"""A still window's spreads are at most this multiple of the recording's smallest."""

MAX_HEADING_AXIS_TILT_DEG = 60.0
"""A heading axis tilted more than this from the horizontal gives a poorly defined heading."""


@dataclass(frozen=True)
class StillInterval:
    """Samples [start, stop) used to level the IMU and estimate the gyro bias.

    ``still``: the spreads were within the limits (False: the quietest window of a recording
    with no still interval). ``acc_spread_mps2`` / ``gyro_spread_radps``: the largest window
    spreads inside the interval."""

    start: int
    stop: int
    still: bool
    acc_spread_mps2: float
    gyro_spread_radps: float


def window_spreads(acc_b: np.ndarray, gyro_b: np.ndarray, length: int) -> tuple[np.ndarray, np.ndarray]:
    """Spreads (N − L + 1,) of the specific force (m/s^2) and angular rate (rad/s) over every
    window of ``length`` samples starting at index k: √(Σ_axes var), population variance."""
    def spread(x: np.ndarray) -> np.ndarray:
        x = x - x.mean(axis=0)  # running sums of centred data lose no digits
        c1 = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
        c2 = np.vstack([np.zeros((1, 3)), np.cumsum(x * x, axis=0)])
        m1 = (c1[length:] - c1[:-length]) / length
        m2 = (c2[length:] - c2[:-length]) / length
        return np.sqrt(np.maximum(m2 - m1 * m1, 0.0).sum(axis=1))

    return spread(np.asarray(acc_b, dtype=float)), spread(np.asarray(gyro_b, dtype=float))


DRIFT_BATCHES = 5
"""Consecutive batches of a window whose means show a slow rotation (:func:`window_drifts`)."""
DRIFT_FACTOR = 2.0
"""A still window's angular-rate drift is at most this multiple of the recording's smallest."""


def window_drifts(gyro_b: np.ndarray, length: int) -> np.ndarray:
    """Drift (N − L + 1,) of the angular rate over every window of ``length`` samples starting at
    index k, rad/s: √(Σ_axes var) of the means of its :data:`DRIFT_BATCHES` consecutive batches.
    Noise averages out of a batch mean; a slow rotation (a foot shifting its weight, which
    the spread of single samples hides in the noise) does not, and its mean would pass for
    gyro bias."""
    x = np.asarray(gyro_b, dtype=float)
    x = x - x.mean(axis=0)
    c = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
    size = max(1, length // DRIFT_BATCHES)
    m = len(x) - length + 1
    means = np.stack([(c[j * size + size:j * size + size + m] - c[j * size:j * size + m]) / size
                      for j in range(DRIFT_BATCHES)])
    return np.sqrt(means.var(axis=0).sum(axis=1))


def find_still_interval(acc_b: np.ndarray, gyro_b: np.ndarray, length: int, acc_limit_mps2: float,
                        gyro_limit_radps: float) -> StillInterval:
    """The first still interval of at least ``length`` samples (both window spreads within
    the limits and within :data:`STILL_NOISE_FACTOR` times their smallest over the
    recording), extended over the following still windows; else the first run of the quietest
    windows.
    Raises ValueError when the recording is shorter than one window."""
    n = len(acc_b)
    if n < length or length < 2:
        raise ValueError(f"{n} samples cannot hold a window of {length}")
    s_f, s_w = window_spreads(acc_b, gyro_b, length)
    d_w = window_drifts(gyro_b, length)
    still = ((s_f <= min(acc_limit_mps2, STILL_NOISE_FACTOR * s_f.min()))
             & (s_w <= min(gyro_limit_radps, STILL_NOISE_FACTOR * s_w.min()))
             & (d_w <= DRIFT_FACTOR * np.percentile(d_w[s_w <= STILL_NOISE_FACTOR * s_w.min()], 10)))
    is_still = bool(still.any())
    if not is_still:  # the quietest windows instead
        score = s_f / acc_limit_mps2 + s_w / gyro_limit_radps
        still = score <= STILL_NOISE_FACTOR * score.min()
    first = int(np.argmax(still))
    moving = np.flatnonzero(~still[first:])
    last = first + (int(moving[0]) - 1 if moving.size else len(still) - 1 - first)
    run = slice(first, last + 1)
    return StillInterval(first, last + length, is_still, float(s_f[run].max()), float(s_w[run].max()))


BATCHES = 10
"""Non-overlapping batches whose means estimate the standard error of a window mean."""


def mean_standard_error(x: np.ndarray) -> float:
    """Standard error of the window mean of ``x`` (N, 3), combined over the axes, by batch
    means: √(Σ_axes var(batch means) / B) over B = 10 consecutive batches (fewer for a short
    window). It holds for correlated noise (a sensor's low-pass filter) as for white: jitter
    averages out over the window, a smooth motion does not."""
    x = np.asarray(x, dtype=float)
    batches = max(2, min(BATCHES, len(x) // 5))
    size = len(x) // batches
    means = x[: batches * size].reshape(batches, size, -1).mean(axis=1)
    return float(np.sqrt(np.sum(means.var(axis=0, ddof=1)) / batches))


def heading_axis(up_b: np.ndarray, preferred: str = "x") -> str:
    """The body axis whose horizontal projection defines the heading: ``preferred`` unless
    it is tilted more than :data:`MAX_HEADING_AXIS_TILT_DEG` from the horizontal (the sensor
    mounted with it up or down), then the most horizontal of x, y, z."""
    up = np.asarray(up_b, dtype=float) / np.linalg.norm(up_b)
    tilt = np.degrees(np.arcsin(np.clip(np.abs(up), 0.0, 1.0)))  # elevation of each axis
    if tilt["xyz".index(preferred)] <= MAX_HEADING_AXIS_TILT_DEG:
        return preferred
    return "xyz"[int(np.argmin(tilt))]


def attitude_from_specific_force(f_b: np.ndarray, azimuth_rad: float, axis: str = "x") -> np.ndarray:
    """q_nb (scalar-first) of a sensor at rest measuring the specific force ``f_b`` (m/s^2,
    pointing up), whose body ``axis`` projects horizontally onto azimuth ``azimuth_rad``
    (clockwise from North). TRIAD: up_n = C_nb f̂_b, and the horizontal part of the axis maps
    to (sin ψ, cos ψ, 0). With x the axis and the sensor level, ψ is the usual yaw; for a
    tilted sensor it equals the ZYX Euler azimuth of the body x axis."""
    up_b = np.asarray(f_b, dtype=float) / np.linalg.norm(f_b)
    a_b = AXIS_VECTORS[axis]
    h_b = a_b - (a_b @ up_b) * up_b
    h_b /= np.linalg.norm(h_b)
    body = np.column_stack([h_b, np.cross(up_b, h_b), up_b])  # forward, left, up in body axes
    fwd_n = np.array([np.sin(azimuth_rad), np.cos(azimuth_rad), 0.0])
    nav = np.column_stack([fwd_n, np.cross([0.0, 0.0, 1.0], fwd_n), [0.0, 0.0, 1.0]])
    return Rotation.from_matrix(nav @ body.T).as_quat(scalar_first=True)
