"""Data containers passed between readers, systems, the fuser and scoring.

Frames and units: navigation frame is local East-North-Up (ENU) in metres;
time in seconds (float64); specific force in m/s^2; angular rate in rad/s.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import ClassVar

import numpy as np

LOG = logging.getLogger("bodyfusion")


@contextlib.contextmanager
def log_silenced() -> Iterator[None]:
    """The package's log off within the block (a live pass reading a context whose findings an
    earlier pass already said)."""
    LOG.disabled = True
    try:
        yield
    finally:
        LOG.disabled = False
"""The package's logger, parent of every module's (``logging.getLogger(__name__)``): warnings about
the input and the run go here; the command line shows them on stderr (:mod:`bodyfusion.cli`)."""


@dataclass
class InputReport:
    """What a reader changed in the raw input, by explicit policy, and what looked wrong.

    dropped_samples: samples removed (duplicate or backward timestamps, per policy).
    reordered_samples: samples moved to restore time order (policy ``sort``).
    notes: what a policy did. warnings: one line each about input that looks wrong (units,
    rate, gaps, clipping, a missing still interval...), also logged on :data:`LOG`.
    """

    dropped_samples: int = 0
    reordered_samples: int = 0
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def warn(self, message: str) -> None:
        """Record a one-line warning and log it."""
        self.warnings.append(message)
        LOG.warning(message)

    def merge(self, other: "InputReport") -> "InputReport":
        return InputReport(
            self.dropped_samples + other.dropped_samples,
            self.reordered_samples + other.reordered_samples,
            self.notes + other.notes,
            self.warnings + other.warnings,
        )


@dataclass
class ImuChecks:
    """What :func:`bodyfusion.io.imu_checks.check_imu` found in one stream. Rates in Hz, times in s.

    ``gap_index``: sample indices i whose step t[i] − t[i−1] is a gap; ``gap_missing_s``:
    the time missing in each (step minus one nominal period)."""

    source: str
    rate_hz: float
    rest_specific_force_mps2: float
    max_angular_rate_radps: float
    gap_index: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    gap_missing_s: np.ndarray = field(default_factory=lambda: np.empty(0))
    clipped_acc_samples: int = 0
    clipped_gyro_samples: int = 0
    clipping: dict = field(default_factory=dict)
    """``"acc"`` / ``"gyro"`` → the :class:`bodyfusion.nav.saturation.Clipping` found (where any)."""
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        """Plain-JSON figures for metrics.json."""
        return {"rate_hz": self.rate_hz, "rest_specific_force_mps2": self.rest_specific_force_mps2,
                "max_angular_rate_radps": self.max_angular_rate_radps, "gaps": int(self.gap_index.size),
                "gap_missing_s": float(self.gap_missing_s.sum()), "clipped_acc_samples": self.clipped_acc_samples,
                "clipped_gyro_samples": self.clipped_gyro_samples, "warnings": len(self.warnings)}


@dataclass
class ImuStream:
    """Strictly increasing IMU samples.

    t: (N,) s.  acc_b: (N, 3) specific force, body frame, m/s^2.
    gyro_b: (N, 3) angular rate, body frame, rad/s.
    stance: (N,) bool stance labels given with the data, or None.
    checks: what :func:`bodyfusion.io.imu_checks.check_imu` found (None: not checked).
    """

    t: np.ndarray
    acc_b: np.ndarray
    gyro_b: np.ndarray
    stance: np.ndarray | None = None
    source: str = ""
    report: InputReport = field(default_factory=InputReport)
    checks: ImuChecks | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Trajectory:
    """Estimated track of one system in the navigation frame (ENU, m).

    t: (N,) s.  pos_n: (N, 3) m.  pos_sd: (N, 3) one-sigma position, m.  pos_cov_en: (N,)
    east–north position covariance, m² (None: not given, taken as 0).  vel_n: (N, 3) velocity,
    ENU m/s, and q_nb: (N, 4) attitude quaternion (scalar first, body to ENU), where the system
    estimates them (None: it does not).  motion_cov: (N, 9) their covariance where given: the
    velocity variances east, north, up (m²/s²), then the attitude error's covariance (δθ in the
    navigation frame, q_true = [1, δθ/2] ⊗ q_nb; rad²) packed EE, NN, UU, EN, EU, NU.
    """

    t: np.ndarray
    pos_n: np.ndarray
    pos_sd: np.ndarray
    pos_cov_en: np.ndarray | None = None
    vel_n: np.ndarray | None = None
    q_nb: np.ndarray | None = None
    motion_cov: np.ndarray | None = None

    def horizontal_covariance(self) -> np.ndarray:
        """(N, 2, 2) east–north position covariance, m²."""
        cov = np.empty((len(self.t), 2, 2))
        cov[:, 0, 0] = self.pos_sd[:, 0] ** 2
        cov[:, 1, 1] = self.pos_sd[:, 1] ** 2
        cov[:, 0, 1] = cov[:, 1, 0] = 0.0 if self.pos_cov_en is None else self.pos_cov_en
        return cov


@dataclass(frozen=True)
class NavigationFrame:
    """The frame a run's trajectories are in: local East-North-Up, metres, its origin the
    ``geodetic_origin`` (lat deg, lon deg, ellipsoidal height m) where known, else the start of
    the run; azimuths from ``heading_reference`` (``north``: a system with a geographic heading,
    GNSS or a magnetometer, set it; else the name of the system whose initial heading every
    other was aligned to, so north is unknown). Times in s of the input's clock.
    :data:`UNITS` gives the unit of every quantity a result carries."""

    geodetic_origin: tuple[float, float, float] | None = None
    heading_reference: str = "north"

    UNITS: ClassVar[Mapping[str, str]] = MappingProxyType({
        "t": "s", "position": "m", "velocity": "m/s", "attitude": "deg", "quaternion": "1 (scalar first, body to ENU)",
        "position_covariance": "m^2", "error": "m", "nees": "1"})
    """Unit of each quantity in a run's results."""

    def to_dict(self) -> dict:
        """The frame as outputs record it (the Parquet schema's ``bodyfusion.frame``, metrics.json ``frame``)."""
        origin = None if self.geodetic_origin is None else dict(zip(("lat_deg", "lon_deg", "height_m"),
                                                                    map(float, self.geodetic_origin)))
        return {"name": "ENU", "axes": ["east", "north", "up"], "unit": "m",
                "origin": "the geodetic origin" if origin else "the start of the run (no geodetic origin)",
                "geodetic_origin": origin, "heading_reference": self.heading_reference,
                "alignment": "none (before any evaluation alignment)",
                "time": {"unit": "s", "epoch": "the input's clock (no absolute epoch)"}}

    def describe(self) -> str:
        """One line: origin and where azimuths are taken from."""
        origin = ("the run's start" if self.geodetic_origin is None else
                  "lat {:.6f}°, lon {:.6f}°, h {:.1f} m".format(*self.geodetic_origin))
        heading = {"north": "azimuths from North", "unknown": "azimuths from an unknown direction"}.get(
            self.heading_reference, f"azimuths from {self.heading_reference}'s initial heading (North unknown)")
        return f"ENU, metres, origin at {origin}; {heading}"

    @classmethod
    def from_dict(cls, doc: dict | None) -> NavigationFrame:
        """The frame :meth:`to_dict` wrote (a folder without one: ENU from the start, heading unknown)."""
        if not doc:
            return cls(None, "unknown")
        origin = doc.get("geodetic_origin")
        return cls(None if origin is None else (origin["lat_deg"], origin["lon_deg"], origin["height_m"]),
                   doc.get("heading_reference", "unknown"))


@dataclass
class TruthTrack:
    """Reference positions of one system, ENU m; ``sparse`` for surveyed points."""

    t: np.ndarray
    pos_n: np.ndarray
    sparse: bool = False
