"""The walking heading from the shape of the GNSS track, not from its jitter.

A phone's GNSS course (Doppler) is reported only above a walking speed many phones never
report, and a course computed from consecutive fixes of a slow walker is the fixes' jitter.
The shape of the track is not: over a stretch of :data:`WINDOW_M` of walking, the fixes
trace the path the PDR dead-reckons, turned by the PDR's heading error (its step lengths may
be scaled, which does not turn it). The rotation that lays the dead-reckoned track onto the
fixes (2-D Procrustes about their centroids) measures that error, as a clockwise azimuth
(true minus estimated, the filter's δψ):

    z = ∠(DR → GNSS) = δψ,   σ_z = max(s / r, σ_k √(1 − ρ) / (r √(N / 4))),

with r the dead-reckoned track's RMS distance from its centroid, s the RMS across-track
residual of the fit, σ_k the fixes' σ and ρ their correlated share (a fix's error is mostly a
bias common to the stretch, which a rotation about the centroid does not see; the √(N/4)
credits the rest with a quarter of the fixes as independent).

A stretch holds only fixes taken while the phone walks, held steadily, with its heading
resolved (one filter): the dead-reckoned track is the walking path there. Handling the phone
breaks the stretch (the walking direction relative to the phone is lost); standing adds no
points but keeps it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

WINDOW_M = 20.0
"""Walking (m, dead-reckoned) over which a stretch measures the heading."""
MIN_FIXES = 8
"""Fixes a stretch needs."""


@dataclass
class TrackHeading:
    """One stretch of the track (module docstring): dead-reckoned positions ``dr`` and fixes
    ``gnss`` (E, N, m) with their σ, and the dead reckoning itself (:meth:`step`)."""

    correlated_fraction: float
    dr_position: np.ndarray = field(default_factory=lambda: np.zeros(2))
    walked_m: float = 0.0
    points: list[tuple[float, float, float, float, float]] = field(default_factory=list)

    def step(self, length_m: float, azimuth_rad: float) -> None:
        """One step of ``length_m`` towards ``azimuth_rad`` (clockwise from North)."""
        self.dr_position = self.dr_position + length_m * np.array([np.sin(azimuth_rad), np.cos(azimuth_rad)])
        if self.points:
            self.walked_m += length_m

    def add(self, fix_en: np.ndarray, sd_m: float) -> None:
        """A fix (E, N, m; σ m) taken where the dead reckoning is now."""
        self.points.append((*self.dr_position, float(fix_en[0]), float(fix_en[1]), float(sd_m)))

    def clear(self) -> None:
        """Start a new stretch."""
        self.points = []
        self.walked_m = 0.0

    def measure(self) -> tuple[float, float] | None:
        """(z rad, σ_z² rad²) of a complete stretch (then cleared), else None."""
        if self.walked_m < WINDOW_M or len(self.points) < MIN_FIXES:
            return None
        a = np.array(self.points)
        dr, gnss, sd = a[:, 0:2] - a[:, 0:2].mean(axis=0), a[:, 2:4] - a[:, 2:4].mean(axis=0), a[:, 4]
        self.clear()
        r2 = float(np.mean(np.sum(dr**2, axis=1)))
        if r2 <= 0.0:
            return None
        # the clockwise rotation from dr to gnss: azimuths grow clockwise, cross products anticlockwise
        z = float(np.arctan2(np.sum(dr[:, 1] * gnss[:, 0] - dr[:, 0] * gnss[:, 1]), np.sum(dr * gnss)))
        c, s = np.cos(z), np.sin(z)
        turned = np.column_stack([c * dr[:, 0] + s * dr[:, 1], -s * dr[:, 0] + c * dr[:, 1]])
        arm = np.maximum(np.hypot(*turned.T), 1e-9)
        across = np.column_stack([turned[:, 1], -turned[:, 0]]) / arm[:, None]
        scatter = float(np.sqrt(np.mean(np.sum((gnss - turned) * across, axis=1) ** 2)))
        point = max(scatter, float(np.sqrt(np.mean(sd**2) * (1.0 - self.correlated_fraction))))
        return z, point**2 / (max(len(a) / 4.0, 1.0) * r2)
