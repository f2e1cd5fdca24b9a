"""Attitude conventions, said once for the whole project.

Quaternions are **scalar-first** ``[w, x, y, z]`` with the Hamilton product. ``q_nb``
rotates body-frame vectors into the navigation frame (ENU): ``v_n = C_nb v_b`` with
``C_nb = quat_to_dcm(q_nb)``. Heading (azimuth) is measured clockwise from North;
the ENU yaw angle (counter-clockwise about Up from East) is ``pi/2 - azimuth``.

The numba kernels here serve the per-sample loops; the conversions that run once
use :class:`scipy.spatial.transform.Rotation` with ``scalar_first=True``.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.spatial.transform import Rotation


@numba.njit(cache=True)
def quat_multiply(a: tuple[float, float, float, float],
                  b: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """Hamilton product a ⊗ b of scalar-first quaternions. Quaternions in the compiled
    kernels are 4-tuples of floats: no array is allocated per sample."""
    return (a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0])


@numba.njit(cache=True)
def quat_from_rotvec(r: tuple[float, float, float]) -> tuple[float, float, float, float]:
    """Quaternion of the rotation vector r (rad); exact, with a series near zero."""
    angle = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if angle < 1e-8:
        w = 1.0 - angle * angle / 8.0
        s = 0.5 - angle * angle / 48.0
    else:
        w = math.cos(0.5 * angle)
        s = math.sin(0.5 * angle) / angle
    return w, s * r[0], s * r[1], s * r[2]


@numba.njit(cache=True)
def quat_normalised(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """q scaled to unit norm."""
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return q[0] / n, q[1] / n, q[2] / n, q[3] / n


@numba.njit(cache=True)
def quat_to_dcm_into(q: np.ndarray, C_nb: np.ndarray) -> None:
    """``C_nb`` (3, 3) ← the direction-cosine matrix of the unit quaternion q_nb (4,)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    C_nb[0, 0] = 1 - 2 * (y * y + z * z)
    C_nb[0, 1] = 2 * (x * y - w * z)
    C_nb[0, 2] = 2 * (x * z + w * y)
    C_nb[1, 0] = 2 * (x * y + w * z)
    C_nb[1, 1] = 1 - 2 * (x * x + z * z)
    C_nb[1, 2] = 2 * (y * z - w * x)
    C_nb[2, 0] = 2 * (x * z - w * y)
    C_nb[2, 1] = 2 * (y * z + w * x)
    C_nb[2, 2] = 1 - 2 * (x * x + y * y)


@numba.njit(cache=True)
def quat_to_dcm(q: np.ndarray) -> np.ndarray:
    """Direction-cosine matrix C_nb (3, 3) of the unit quaternion q_nb (4,), in a new array
    (:func:`quat_to_dcm_into` fills one)."""
    C_nb = np.empty((3, 3))
    quat_to_dcm_into(q, C_nb)
    return C_nb


def quat_from_azimuth_pitch_roll(azimuth: float, pitch: float, roll: float) -> np.ndarray:
    """q_nb from azimuth (clockwise from North), pitch and roll (rad), ZYX order in ENU."""
    rot = Rotation.from_euler("ZYX", [np.pi / 2 - azimuth, pitch, roll])
    return rot.as_quat(scalar_first=True)


def azimuth_pitch_roll(q_nb: np.ndarray) -> np.ndarray:
    """(azimuth, pitch, roll) in rad of scalar-first q_nb; accepts (4,) or (N, 4)."""
    yaw, pitch, roll = Rotation.from_quat(q_nb, scalar_first=True).as_euler("ZYX").T
    azimuth = np.mod(np.pi / 2 - yaw, 2 * np.pi)
    return np.array([azimuth, pitch, roll])


def levelling(mean_acc_b: np.ndarray) -> tuple[float, float]:
    """Pitch and roll (rad) from the mean specific force over a stationary window."""
    ax, ay, az = mean_acc_b
    return float(np.arctan2(-ax, np.hypot(ay, az))), float(np.arctan2(ay, az))
