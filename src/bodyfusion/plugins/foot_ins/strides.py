"""The foot's gait, stride by stride: what gaitmap calls the spatial parameters, and the motion.

A stride runs from the middle of one stance to the middle of the next (the foot at rest at both
ends; stances apart by less than :data:`MIN_SWING_S`, a detector's flicker, are one). From the navigated track (the smoothed one where smoothed), per stride: its start and end
(s), ``length_m`` (horizontal distance between its two stances), ``duration_s``, ``speed_mps``,
``climb_m`` (the rise from the first stance to the second), ``clearance_m`` (the highest the foot
rises above the straight line between its two stances) and ``motion``:

* ``stairs_up`` / ``stairs_down``: a climb of at least :data:`STAIR_CLIMB_M` (one tread of a
  stair, the foot passing two, rises 0.3 m and more);
* ``run``: faster than :data:`RUN_SPEED_MPS`, or a stride shorter than :data:`RUN_STRIDE_S` and
  faster than :data:`JOG_SPEED_MPS` (a run's flight);
* ``shuffle``: shorter than :data:`SHUFFLE_M` (turning on the spot, a shift of weight);
* ``walk``: the rest.
"""

from __future__ import annotations

import numpy as np

from bodyfusion.nav import detectors

STAIR_CLIMB_M = 0.12
"""The least rise (m) between a stride's two stances that makes it a stair stride."""
RUN_SPEED_MPS = 2.5
"""Any stride faster than this (m/s) is running."""
RUN_STRIDE_S = 0.85
"""A stride shorter than this (s) and faster than :data:`JOG_SPEED_MPS` is running."""
JOG_SPEED_MPS = 1.8
"""The least speed (m/s) of a short stride that makes it a run."""
SHUFFLE_M = 0.25
"""A stride shorter than this (m) is a shuffle, not a step."""
MIN_SWING_S = 0.2
"""The shortest swing (s): stance phases closer than this are one (a foot swings longer)."""
MOTIONS = ("walk", "run", "stairs_up", "stairs_down", "shuffle")


def classify(length_m: np.ndarray, duration_s: np.ndarray, climb_m: np.ndarray) -> np.ndarray:
    """The ``motion`` of each stride (module docstring)."""
    speed = length_m / np.maximum(duration_s, 1e-9)
    motion = np.full(length_m.size, "walk", dtype=object)
    motion[(speed > RUN_SPEED_MPS) | ((duration_s < RUN_STRIDE_S) & (speed > JOG_SPEED_MPS))] = "run"
    motion[length_m < SHUFFLE_M] = "shuffle"
    motion[climb_m >= STAIR_CLIMB_M] = "stairs_up"
    motion[climb_m <= -STAIR_CLIMB_M] = "stairs_down"
    return motion


def stride_table(t: np.ndarray, pos_n: np.ndarray, stance: np.ndarray) -> dict[str, np.ndarray]:
    """The strides (module docstring) of a foot whose track is ``pos_n`` (N, 3) ENU m at ``t``
    (N,) s, at rest where ``stance`` (N,): equal-length columns ``stride`` (0, 1, ...),
    ``t_start``, ``t_end``, ``length_m``, ``duration_s``, ``speed_mps``, ``climb_m``,
    ``clearance_m``, ``motion``."""
    rate = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    whole = detectors.debounce(np.asarray(stance, dtype=bool)[:len(t)], min_stance=1,
                               min_swing=max(1, int(round(MIN_SWING_S * rate))))
    starts, ends = detectors.stance_events(whole)
    mids = ((starts + ends - 1) // 2).astype(np.int64)
    if mids.size < 2:
        empty = np.empty(0)
        return {"stride": np.empty(0, dtype=np.int64), "t_start": empty, "t_end": empty, "length_m": empty,
                "duration_s": empty, "speed_mps": empty, "climb_m": empty, "clearance_m": empty,
                "motion": np.empty(0, dtype=object)}
    a, b = mids[:-1], mids[1:]
    d = pos_n[b] - pos_n[a]
    length = np.hypot(d[:, 0], d[:, 1])
    duration = t[b] - t[a]
    clearance = np.empty(a.size)
    for k, (i, j) in enumerate(zip(a, b)):
        line = pos_n[i, 2] + (pos_n[j, 2] - pos_n[i, 2]) * (t[i:j + 1] - t[i]) / max(t[j] - t[i], 1e-12)
        clearance[k] = max(float(np.max(pos_n[i:j + 1, 2] - line)), 0.0)
    return {"stride": np.arange(a.size), "t_start": t[a], "t_end": t[b], "length_m": length,
            "duration_s": duration, "speed_mps": length / np.maximum(duration, 1e-9), "climb_m": d[:, 2],
            "clearance_m": clearance, "motion": classify(length, duration, d[:, 2])}


def mounting(t: np.ndarray, x: np.ndarray, stance: np.ndarray, acc_b: np.ndarray) -> dict | None:
    """How the IMU sits on the foot, from the walk itself (None without two walking strides):
    ``up_b`` the body-frame direction of Up at rest (the mean specific force over the stances),
    ``forward_from_x_deg`` the angle about Up from the body x axis to the direction of walking
    (positive counter-clockwise seen from above; each walking stride's displacement against the
    x axis's azimuth at its first stance, the median over the strides: turns do not bias it), and
    ``forward_b`` that direction in the body frame. ``x`` (N, 16) the nominal states (q_nb at 6:10)."""
    from scipy.spatial.transform import Rotation

    table = stride_table(t, x[:, 0:3], stance)
    walks = np.flatnonzero(table["motion"] == "walk")
    if walks.size < 2:
        return None
    up_b = np.asarray(acc_b)[np.asarray(stance, dtype=bool)[:len(acc_b)]].mean(axis=0)
    up_b = up_b / np.linalg.norm(up_b)
    starts = np.searchsorted(t, table["t_start"][walks])
    ends = np.searchsorted(t, table["t_end"][walks])
    d_n = x[ends, 0:3] - x[starts, 0:3]
    x_n = Rotation.from_quat(x[starts, 6:10], scalar_first=True).apply([1.0, 0.0, 0.0])
    turn = np.arctan2(d_n[:, 0], d_n[:, 1]) - np.arctan2(x_n[:, 0], x_n[:, 1])  # azimuths: clockwise
    centre = np.angle(np.mean(np.exp(-1j * turn)))  # counter-clockwise from here on
    angle = centre + float(np.median(np.angle(np.exp(1j * (-turn - centre)))))
    x_b = np.array([1.0, 0.0, 0.0]) - up_b[0] * up_b
    x_b /= max(np.linalg.norm(x_b), 1e-12)
    forward = np.cos(angle) * x_b + np.sin(angle) * np.cross(up_b, x_b)
    return {"up_b": [float(v) for v in up_b], "forward_b": [float(v) for v in forward],
            "forward_from_x_deg": float(np.degrees(np.angle(np.exp(1j * angle))))}
