"""A simulated GNSS receiver: fixes of a truth trajectory in WGS84 with realistic errors.

Fix k at ``t_k = start_s + k / rate_hz`` (up to the end of the IMU data):

* position: truth ENU + white noise (σ ``white_sigma_m`` on east and north,
  ``height_white_sigma_m`` up) + a first-order Gauss–Markov error per axis (stationary
  σ ``gm_sigma_m`` horizontal, ``height_gm_sigma_m`` up, correlation time ``gm_tau_s``;
  stationary from the first fix), converted to latitude, longitude and ellipsoidal
  height about the scenario's ``geodetic_origin`` (:func:`bodyfusion.io.gnss.enu_to_geodetic`);
* ``accuracy_m``: ``accuracy_reported_m``, by default the horizontal 68 % radius of the
  simulated error, 1.515·√(σ_white² + σ_gm²) (for which the hand PDR filter's default
  ``accuracy_to_sigma`` 0.66 gives back the per-axis σ);
* speed and course: the truth's horizontal velocity plus white noise of σ
  ``velocity_sigma_mps`` per axis (speed m/s, course degrees clockwise from North in [0, 360)).

Outages are not cut out of the file: the scenario's windows go into the generated
layout's ``outages`` list, which masks them in ``fusion run``.

Random numbers: ``system_seed(seed, name + "#gnss")``, spawned into white, Gauss–Markov
and velocity streams — independent of the system's IMU streams, so switching the GNSS
on or off leaves the IMU noise alone.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.io.gnss import GnssFixes, enu_to_geodetic
from bodyfusion.base.seeding import system_seed
from bodyfusion.sim.files import SimFile, printed
from bodyfusion.sim.imu import Motion, gauss_markov

__all__ = ["GNSS_COLUMNS", "GNSS_FORMATS", "GnssOutage", "GnssReceiverConfig", "gnss_file", "simulate_fixes",
           "write_gnss_csv"]

GNSS_COLUMNS = ("t", "lat_deg", "lon_deg", "height_m", "accuracy_m", "speed_mps", "course_deg")
GNSS_FORMATS = ("%.10g", "%.11f", "%.11f", "%.4f", "%.4f", "%.4f", "%.3f")
"""Printed precision of each of :data:`GNSS_COLUMNS`."""
RADIUS_68_PER_SIGMA = math.sqrt(-2.0 * math.log(1.0 - 0.6827))
"""Radius of a circular 2-D Gaussian's 68.27 % region in units of the per-axis σ (≈ 1.515)."""


class GnssOutage(StrictModel):
    """A window (s) in which the receiver's fixes are masked in the generated layout."""

    start_s: float = Field(ge=0)
    duration_s: float = Field(gt=0)


class GnssReceiverConfig(StrictModel):
    """A system's ``gnss`` section in a scenario (see the module docstring)."""

    rate_hz: float = Field(default=1.0, gt=0)
    start_s: float = Field(default=0.0, ge=0)
    white_sigma_m: float = Field(default=1.5, ge=0)
    gm_sigma_m: float = Field(default=3.0, ge=0)
    gm_tau_s: float = Field(default=60.0, gt=0)
    height_white_sigma_m: float = Field(default=3.0, ge=0)
    height_gm_sigma_m: float = Field(default=5.0, ge=0)
    velocity_sigma_mps: float = Field(default=0.1, ge=0)
    accuracy_reported_m: float | None = Field(default=None, gt=0)
    outages: list[GnssOutage] = Field(default_factory=list)

    @property
    def horizontal_sigma_m(self) -> float:
        """Per-axis σ of the horizontal error (white and Gauss–Markov together)."""
        return math.hypot(self.white_sigma_m, self.gm_sigma_m)

    @property
    def accuracy_m(self) -> float:
        if self.accuracy_reported_m is not None:
            return self.accuracy_reported_m
        return max(RADIUS_68_PER_SIGMA * self.horizontal_sigma_m, 1e-3)


def simulate_fixes(motion: Motion, t_end: float, origin: tuple[float, float, float], cfg: GnssReceiverConfig,
                   *, seed: int, name: str) -> tuple[GnssFixes, np.ndarray]:
    """Fixes of ``motion`` from ``cfg.start_s`` to ``t_end``; also returns the (N, 3) ENU error added."""
    n = int(math.floor((t_end - cfg.start_s) * cfg.rate_hz + 1e-9)) + 1
    t = cfg.start_s + np.arange(max(n, 0)) / cfg.rate_hz
    truth = motion.evaluate(t)
    ss = system_seed(seed, f"{name}#gnss").spawn(3)
    white_rng, gm_rng, vel_rng = (np.random.Generator(np.random.PCG64(c)) for c in ss)
    white = white_rng.standard_normal((t.size, 3)) * [cfg.white_sigma_m, cfg.white_sigma_m,
                                                      cfg.height_white_sigma_m]
    gm = gauss_markov(t.size, 1.0 / cfg.rate_hz, 1.0, cfg.gm_tau_s, gm_rng) * [
        cfg.gm_sigma_m, cfg.gm_sigma_m, cfg.height_gm_sigma_m]
    error = white + gm
    geo = enu_to_geodetic(truth.pos + error, origin)
    v = truth.vel[:, :2] + cfg.velocity_sigma_mps * vel_rng.standard_normal((t.size, 2))
    speed = np.hypot(v[:, 0], v[:, 1])
    course = np.degrees(np.arctan2(v[:, 0], v[:, 1])) % 360.0
    fixes = GnssFixes(t, geo[:, 0], geo[:, 1], geo[:, 2], np.full(t.size, cfg.accuracy_m), speed, course)
    return fixes, error


def _gnss_table(fixes: GnssFixes) -> np.ndarray:
    return np.column_stack([fixes.t, fixes.lat_deg, fixes.lon_deg, fixes.height_m, fixes.accuracy_m,
                            fixes.speed_mps, fixes.course_deg])


def write_gnss_csv(path: Path, fixes: GnssFixes) -> None:
    """``t,lat_deg,lon_deg,height_m,accuracy_m,speed_mps,course_deg`` (what the hand PDR's CSV reader reads)."""
    np.savetxt(path, _gnss_table(fixes), fmt=list(GNSS_FORMATS), delimiter=",", header=",".join(GNSS_COLUMNS),
               comments="")


def gnss_file(section: str, name: str, fixes: GnssFixes) -> SimFile:
    """The fixes file :func:`write_gnss_csv` writes, as a :class:`~bodyfusion.sim.files.SimFile`
    read by the layout section ``section``: its columns at the printed precision."""
    table = _gnss_table(fixes)
    columns = {col: printed(table[:, j], fmt) for j, (col, fmt) in enumerate(zip(GNSS_COLUMNS, GNSS_FORMATS))}
    return SimFile(section, name, columns, lambda path: write_gnss_csv(path, fixes))
