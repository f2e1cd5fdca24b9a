"""Layout section of a hand-held phone running PDR corrected by GNSS (``plugin: hand_pdr``)."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, field_validator, model_validator

from fusion.config import DataPath, ImuCsvConfig, KeyedError, StrictModel


class GnssSourceConfig(StrictModel):
    """Where the GNSS fixes come from: a CSV with named columns, an NMEA 0183 log, or the
    GNSS lines of the phone log (``phone_log``: the system's own ``phone_log`` file)."""

    format: Literal["csv", "nmea", "phone_log"] = "csv"
    """csv, nmea or phone_log."""
    path: DataPath | None = None
    """File of fixes (csv, nmea); relative to the layout file."""
    time_column: str = "t"
    """CSV column of fix times, s (on the IMU's clock)."""
    lat_column: str = "lat_deg"
    """CSV column of latitudes, degrees."""
    lon_column: str = "lon_deg"
    """CSV column of longitudes, degrees."""
    height_column: str | None = "height_m"
    """CSV column of ellipsoidal heights, m (none: 0)."""
    accuracy_column: str | None = "accuracy_m"
    """CSV column of the receiver's horizontal accuracy, m (none: use ``default_sigma_m``)."""
    speed_column: str | None = "speed_mps"
    """CSV column of ground speed, m/s."""
    course_column: str | None = "course_deg"
    """CSV column of course over ground, degrees clockwise from North."""

    @model_validator(mode="after")
    def _path_for_files(self) -> "GnssSourceConfig":
        if self.format != "phone_log" and self.path is None:
            raise KeyedError("path", f"a {self.format} GNSS source needs a path")
        return self


class StepConfig(StrictModel):
    """Step detection on the low-passed specific-force magnitude and step length.

    A step is a peak of ‖f‖ − g (low-passed at ``lowpass_hz``) above ``threshold_mps2``,
    at least ``min_interval_s`` after the previous one. Length: Weinberg's
    K·(a_max − a_min)^(1/4) over the step (``weinberg``) or ``constant_m``.
    """

    threshold_mps2: float = Field(default=1.0, gt=0)
    min_interval_s: float = Field(default=0.35, gt=0)
    lowpass_hz: float = Field(default=3.0, gt=0)
    length: Literal["weinberg", "constant"] = "weinberg"
    weinberg_k: float = Field(default=0.48, gt=0)
    constant_m: float = Field(default=0.7, gt=0)


class PdrFilterConfig(StrictModel):
    """The PDR error filter (PDR/GNSS paper eqs. 38–44), state [δE, δN, δU, δψ, δS, δb, δβE, δβN].

    step_length_sd_m: white step-length error σ_S; heading_noise_density: gyro angle
    random walk, rad/√s; gyro_bias_sd: steady-state σ of the first-order Gauss–Markov
    gyro bias (rad/s) with ``correlation_time_s`` (1/α); height_noise_density: random walk
    of the height, m/√s; GNSS: per-axis σ from the receiver's accuracy
    (``accuracy_to_sigma`` × accuracy) or ``default_sigma_m``; GNSS heading (eq. 44)
    only above ``min_speed_for_heading_mps`` with σ ``gnss_heading_sd_deg``;
    chi-square gating with ``gate_probability``. GNSS errors are correlated in time
    (multipath, atmosphere): a horizontal first-order Gauss–Markov bias with σ
    ``gnss_bias_sd_m`` and correlation time ``gnss_bias_time_s`` is estimated beside the
    white noise (two more states; σ 0 switches it off), so that a minute of fixes is not
    taken for a minute of independent evidence. A wrong step model (Weinberg K) is a scale
    error common to every step: estimated as the state δc with initial σ ``step_scale_sd``
    (relative, 0.1 = 10 %) and random walk ``step_scale_random_walk`` (1/√s); σ 0 (the
    default, the paper's white step errors only) leaves the scale at 1. Off by default:
    on the IPIN 2023 logs the phone's GNSS track is shorter than the walk (corners cut)
    and the state takes that for a 10–25 % step-scale error.
    """

    step_length_sd_m: float = Field(default=0.1, gt=0)
    heading_noise_density: float = Field(default=0.002, ge=0)
    gyro_bias_sd: float = Field(default=0.002, ge=0)
    correlation_time_s: float = Field(default=300.0, gt=0)
    height_noise_density: float = Field(default=0.05, ge=0)
    accuracy_to_sigma: float = Field(default=0.66, gt=0)
    default_sigma_m: float = Field(default=5.0, gt=0)
    gnss_heading_sd_deg: float = Field(default=15.0, gt=0)
    min_speed_for_heading_mps: float = Field(default=0.8, ge=0)
    gate_probability: float = Field(default=0.999, gt=0, lt=1)
    gnss_bias_sd_m: float = Field(default=3.0, ge=0)
    gnss_bias_time_s: float = Field(default=60.0, gt=0)
    step_scale_sd: float = Field(default=0.0, ge=0)
    step_scale_random_walk: float = Field(default=1e-4, ge=0)


class PdrInitialConfig(StrictModel):
    """Initial state: position (ENU, m; ``gnss``: the first fix), heading (azimuth of walking,
    degrees clockwise from North; ``gnss_track``: the rotation that best aligns the first
    ``align_distance_m`` of PDR track with the GNSS track; ``auto``: aligned to the other
    systems), and one-sigma uncertainties."""

    position_m: tuple[float, float, float] | Literal["gnss"] = "gnss"
    heading_deg: float | Literal["gnss_track", "auto"] = "gnss_track"
    align_distance_m: float = Field(default=15.0, gt=0)
    position_sd_m: float = Field(default=5.0, gt=0)
    """Initial horizontal position one-sigma, m."""
    heading_sd_deg: float = Field(default=10.0, gt=0)
    """Initial heading one-sigma, degrees."""
    height_sd_m: float = Field(default=5.0, gt=0)
    """Initial height one-sigma, m."""


class FieldCheckConfig(StrictModel):
    """Rejects magnetometer samples that do not look like the undisturbed Earth field (steel,
    motors and electronics indoors bend it): the magnitude ‖m‖ outside ``expected_uT`` ±
    ``tolerance_uT``, or the dip (the field's angle below the horizontal, degrees, positive
    pointing down as in the northern hemisphere) outside ``inclination_deg`` ±
    ``inclination_tolerance_deg`` (``inclination_deg`` unset: the magnitude only). Take the
    site's values from a geomagnetic model (WMM, IGRF)."""

    expected_uT: float = Field(default=48.0, gt=0)
    """Intensity of the Earth field at the site, µT."""
    tolerance_uT: float = Field(default=8.0, gt=0)
    """Accepted |‖m‖ − expected_uT|, µT."""
    inclination_deg: float | None = Field(default=None, ge=-90, le=90)
    """Dip of the Earth field at the site, degrees below the horizontal (none: not checked)."""
    inclination_tolerance_deg: float = Field(default=10.0, gt=0)
    """Accepted |dip − inclination_deg|, degrees."""


class MagnetometerConfig(StrictModel):
    """Heading aiding by the magnetometer (off unless ``enabled``).

    Measurement: the tilt-compensated azimuth of the phone axis ``axis_b`` (the field's
    horizontal part, levelled with the accelerometer's gravity direction), plus the
    ``declination_deg`` (east of true North positive) → device azimuth ψ_d, degrees
    clockwise from true North. The phone is held at a nearly constant yaw offset o to the
    walking direction, ψ = ψ_d + o: o is an error state (random walk ``offset_random_walk``,
    degrees/√s). ``offset_deg``: its prior (degrees, with σ ``offset_sd_deg``) or ``auto``:
    set from the first accepted sample, o = ψ̂ − ψ_d, with the heading's uncertainty plus
    the measurement's. Updates at most ``rate_hz`` per second (a decimation of the samples),
    σ ``sigma_deg``, chi-square gated with ``gate_probability``, after the ``field_check``
    (null: none). Data: the ``columns`` of the ``imu`` CSV (in ``unit``), or the MAGN lines
    of the ``phone_log`` (µT).
    """

    enabled: bool = False
    sigma_deg: float = Field(default=10.0, gt=0)
    declination_deg: float = Field(default=0.0, ge=-180, le=180)
    axis_b: tuple[float, float, float] = (1.0, 0.0, 0.0)
    """Phone-frame axis whose azimuth is the device azimuth (best one that stays horizontal)."""
    offset_deg: float | Literal["auto"] = "auto"
    offset_sd_deg: float = Field(default=30.0, gt=0)
    offset_random_walk: float = Field(default=0.2, ge=0)
    gate_probability: float = Field(default=0.99, gt=0, lt=1)
    rate_hz: float = Field(default=1.0, gt=0)
    field_check: FieldCheckConfig | None = Field(default_factory=FieldCheckConfig)
    columns: tuple[str, str, str] | None = None
    """Header names of the magnetometer x, y, z columns of the ``imu`` CSV (phone frame);
    cells may be empty where the magnetometer has no sample."""
    unit: Literal["uT", "nT", "G"] = "uT"
    """Unit of the CSV columns: µT, nT or gauss (100 µT)."""

    @field_validator("axis_b")
    @classmethod
    def _unit_axis(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if not 0.5 < math.hypot(*v) < 2.0:
            raise ValueError("give a unit vector of the phone frame, e.g. [1, 0, 0]")
        return v


class HandPdrConfig(StrictModel):
    """A phone held in the hand: PDR from its IMU, corrected by GNSS.

    Data: either ``imu`` (a CSV, see :class:`fusion.config.ImuCsvConfig`) or ``phone_log``
    (a GetSensorData log: its ACCE/GYRO lines, its GNSS lines with ``gnss.format:
    phone_log`` and its MAGN lines for the ``magnetometer``). ``geodetic_origin``: (lat
    deg, lon deg, height m) of the ENU frame; default the layout's origin, else the first
    fix. ``outages``: GNSS masked windows (start s, duration s).
    """

    plugin: Literal["hand_pdr"] = "hand_pdr"
    imu: ImuCsvConfig | None = None
    phone_log: DataPath | None = None
    gnss: GnssSourceConfig | None = None
    step: StepConfig = Field(default_factory=StepConfig)
    filter: PdrFilterConfig = Field(default_factory=PdrFilterConfig)
    initial: PdrInitialConfig = Field(default_factory=PdrInitialConfig)
    magnetometer: MagnetometerConfig = Field(default_factory=MagnetometerConfig)

    @model_validator(mode="after")
    def _one_imu_source(self) -> "HandPdrConfig":
        if (self.imu is None) == (self.phone_log is None):
            raise KeyedError("imu", "give exactly one of imu or phone_log")
        if self.gnss is not None and self.gnss.format == "phone_log" and self.phone_log is None:
            raise KeyedError("gnss.format", "phone_log GNSS needs the system's phone_log")
        if self.gnss is None and ("gnss" in (self.initial.position_m, ) or self.initial.heading_deg == "gnss_track"):
            raise KeyedError("initial", "without gnss, give initial.position_m and a numeric or auto heading_deg")
        if self.magnetometer.enabled and self.imu is not None and self.magnetometer.columns is None:
            raise KeyedError("magnetometer.columns", "a magnetometer read from the imu CSV needs its three columns")
        return self
