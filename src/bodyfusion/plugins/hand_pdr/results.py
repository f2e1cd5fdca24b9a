"""The hand PDR's results in the names every plugin shares (:meth:`bodyfusion.core.system.SensorSystem.states`)."""

from __future__ import annotations

import numpy as np

ERROR_STATES = ("east_m", "north_m", "up_m", "heading_rad", "step_length_m", "gyro_bias_radps", "gnss_bias_east",
                "gnss_bias_north", "step_scale", "holding_offset_rad")
"""Names of the error states δE, δN, δU (m), δψ (rad), δS (m), δb (rad/s), δβE, δβN (units of a
fix's correlated σ), δc and δo (rad), in :meth:`~bodyfusion.plugins.hand_pdr.system.HandPdr.covariance_history`."""
STORED = ("the whole error-state covariance at each step, GNSS and magnetometer update and correction (a "
          "mixture's moments while the heading bank is open)")
"""What the hand PDR's covariance history holds."""


def hand_states(h: np.ndarray) -> dict[str, np.ndarray]:
    """Columns of the records h (K, 1 + n): time (s), position (ENU, m), ``heading_deg`` (walking
    azimuth, clockwise from North), ``gyro_bias_radps``, ``gnss_bias_east`` and ``gnss_bias_north``
    (units of a fix's correlated σ), ``step_scale`` and, with the magnetometer (n = 9),
    ``holding_offset_deg`` (in [−180, 180))."""
    out = {"t": h[:, 0], "east_m": h[:, 1], "north_m": h[:, 2], "up_m": h[:, 3],
           "heading_deg": np.mod(np.degrees(h[:, 4]), 360.0), "gyro_bias_radps": h[:, 5],
           "gnss_bias_east": h[:, 6], "gnss_bias_north": h[:, 7], "step_scale": h[:, 8]}
    if h.shape[1] > 9:
        out["holding_offset_deg"] = np.degrees(np.mod(h[:, 9] + np.pi, 2.0 * np.pi) - np.pi)
    return out
