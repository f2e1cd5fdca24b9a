"""A simulated magnetometer (the hand-held phone's): Earth field, disturbances, sensor errors.

Reading of a body with attitude C_nb at ENU position p (µT, body frame)::

    m_b = C_nbᵀ (B_n + Σ_z w_z(p) D_z) + b_hard + n_k

``B_n``: the Earth field in ENU, ``field_enu_uT`` or, from the intensity F, inclination I
(dip below the horizontal) and declination D (East of true North),
``B_n = F (cos I sin D, cos I cos D, −sin I)``. Disturbance zones (steel, machinery):
zone z adds its field ``D_z`` (ENU, µT) with weight ``w_z = (1 − (d/r)²)²`` inside its
radius r (d: horizontal distance to its centre), full at the centre and fading smoothly
to 0 at the edge. ``b_hard``: the hard-iron bias left after the phone's own calibration
(given vector plus a draw of σ ``hard_iron_sd_uT`` per axis); ``n_k``: white noise of σ
``noise_uT`` per sample and axis. Instantaneous samples (no averaging over the interval).

Random numbers: the stream ``system_seed(seed, name + "#magnetometer")``, spawned into
one child per term (hard iron, white), so the IMU's and the GNSS's draws stay as they are.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.base.seeding import system_seed
from bodyfusion.sim.imu import MotionState, dcm_from_quat

__all__ = ["DisturbanceZone", "MagnetometerSimConfig", "simulate_magnetometer"]

Vec3 = tuple[float, float, float]


class DisturbanceZone(StrictModel):
    """A local magnetic disturbance; see the module docstring for the weighting."""

    position_m: tuple[float, float]
    """Centre, East and North, m."""
    radius_m: float = Field(gt=0)
    """Horizontal radius of the zone, m."""
    field_uT: Vec3
    """Perturbing field at the centre, East, North, Up, µT."""


class MagnetometerSimConfig(StrictModel):
    """The phone's magnetometer (module docstring). Defaults: about the WMM field at the
    default geodetic origin (Nuremberg, 2023) and a calibrated phone magnetometer."""

    intensity_uT: float = Field(default=48.8, gt=0)
    """Earth field intensity F, µT."""
    inclination_deg: float = Field(default=65.5, ge=-90, le=90)
    """Dip I below the horizontal, degrees."""
    declination_deg: float = Field(default=4.0, ge=-180, le=180)
    """Declination D, degrees East of true North."""
    field_enu_uT: Vec3 | None = None
    """Earth field East, North, Up, µT (replaces intensity, inclination and declination)."""
    noise_uT: float = Field(default=0.4, ge=0)
    """White noise σ per sample and axis, µT."""
    hard_iron_uT: Vec3 = (0.0, 0.0, 0.0)
    """Fixed hard-iron bias, phone frame, µT."""
    hard_iron_sd_uT: float = Field(default=1.0, ge=0)
    """σ of the drawn hard-iron bias per axis, µT."""
    disturbances: list[DisturbanceZone] = Field(default_factory=list)
    """Disturbance zones along the walk."""

    def field_n(self) -> np.ndarray:
        """The Earth field in ENU, µT."""
        if self.field_enu_uT is not None:
            return np.asarray(self.field_enu_uT, dtype=float)
        inc, dec = math.radians(self.inclination_deg), math.radians(self.declination_deg)
        return self.intensity_uT * np.array([math.cos(inc) * math.sin(dec), math.cos(inc) * math.cos(dec),
                                             -math.sin(inc)])

    @property
    def field_summary(self) -> tuple[float, float, float]:
        """Intensity (µT), inclination (degrees below the horizontal) and declination
        (degrees East) of the Earth field, whichever way it was given."""
        b = self.field_n()
        return (float(np.linalg.norm(b)), math.degrees(math.atan2(-b[2], math.hypot(b[0], b[1]))),
                math.degrees(math.atan2(b[0], b[1])))


def simulate_magnetometer(state: MotionState, cfg: MagnetometerSimConfig, *, seed: int, name: str) -> np.ndarray:
    """(N, 3) readings (µT, body frame) of the magnetometer of system ``name`` along ``state``."""
    b_n = np.tile(cfg.field_n(), (len(state.pos), 1))
    for zone in cfg.disturbances:
        d2 = np.sum((state.pos[:, :2] - zone.position_m) ** 2, axis=1) / zone.radius_m**2
        b_n += np.where(d2 < 1.0, (1.0 - d2) ** 2, 0.0)[:, None] * np.asarray(zone.field_uT)
    m_b = np.einsum("nji,nj->ni", dcm_from_quat(state.q_nb), b_n)
    hard, white = (np.random.Generator(np.random.PCG64(s))
                   for s in system_seed(seed, f"{name}#magnetometer").spawn(2))
    m_b += np.asarray(cfg.hard_iron_uT) + cfg.hard_iron_sd_uT * hard.standard_normal(3)
    return m_b + cfg.noise_uT * white.standard_normal(m_b.shape)
