"""Earth model: normal gravity and Earth rotation in the local ENU frame."""

from __future__ import annotations

import numpy as np

STANDARD_GRAVITY = 9.80665
"""Conventional gravity (m/s^2), the value behind the unit "g"."""

EARTH_RATE = 7.2921151467e-5
"""Earth rotation rate, rad/s (WGS84)."""

_GE = 9.7803253359  # normal gravity at the equator, m/s^2 (WGS84)
_K = 0.00193185265241  # Somigliana constant
_E2 = 0.00669437999013  # first eccentricity squared


def normal_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """Magnitude of normal gravity (m/s^2): Somigliana's formula with a free-air correction."""
    s2 = np.sin(np.deg2rad(latitude_deg)) ** 2
    g0 = _GE * (1 + _K * s2) / np.sqrt(1 - _E2 * s2)
    return float(g0 - 3.086e-6 * height_m)


def earth_rate_enu(latitude_deg: float) -> np.ndarray:
    """Earth rotation vector in the local ENU frame, rad/s, shape (3,)."""
    lat = np.deg2rad(latitude_deg)
    return np.array([0.0, EARTH_RATE * np.cos(lat), EARTH_RATE * np.sin(lat)])
