"""Layout section of a hand-held phone running PDR corrected by GNSS (``plugin: hand_pdr``)."""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, field_validator, model_validator

from bodyfusion.base.sections import DataPath, KeyedError, StrictModel, TableSection
from bodyfusion.io.imu import ImuCsvConfig


class GnssSourceConfig(TableSection):
    """Where the GNSS fixes come from: a CSV with named columns (or a table with those columns
    given in memory), an NMEA 0183 log, a u-blox UBX log (its NAV-PVT messages,
    :func:`bodyfusion.io.gnss.read_ubx`), or the GNSS lines of the phone log (``phone_log``: the
    system's own ``phone_log`` file)."""

    format: Literal["csv", "nmea", "ubx", "phone_log"] = "csv"
    """csv, nmea, ubx or phone_log."""
    path: DataPath | None = None
    """File of fixes (csv, nmea); relative to the layout file (unset: the csv table given in memory)."""
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

    def needs_data(self) -> bool:
        """A csv or nmea source reads its file or table; phone_log fixes come with the phone's log."""
        return self.format != "phone_log"

    def required_columns(self) -> list[str]:
        """A csv's named columns (NMEA sentences and the phone log have none)."""
        return super().required_columns() if self.format == "csv" else []


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
    weinberg_k: float = Field(default=0.48, gt=0, le=10.0)
    constant_m: float = Field(default=0.7, gt=0)


class PdrFilterConfig(StrictModel):
    """The PDR error filter ([KFSC2015] eqs. 38–44), state [δE, δN, δU, δψ, δS, δb, δβE, δβN, δc].

    PDR. step_length_sd_m: white step-length error σ_S; heading_noise_density: gyro angle
    random walk, rad/√s; gyro_bias_sd: steady-state σ of the first-order Gauss–Markov gyro
    bias (rad/s) with ``correlation_time_s`` (1/α); unset, 0.01 for a ``phone_log``
    (consumer phones: one IPIN 2023 phone reads −1.5 °/s standing still) and 0.002 for an
    ``imu`` CSV; height_noise_density: random walk of the height, m/√s. A wrong step model
    (Weinberg K) is a scale error common to every step: estimated as the state δc with
    initial σ ``step_scale_sd`` (relative, 0.1 = 10 %) and random walk
    ``step_scale_random_walk`` (1/√s); σ 0 (the default, the paper's white step errors
    only) leaves the scale at 1. Off by default: on the IPIN 2023 logs the phone's GNSS
    track is shorter than the walk (corners cut) and the state takes that for a 10–25 %
    step-scale error.

    GNSS position. Per-axis σ_k of fix k from the receiver's accuracy (``accuracy_to_sigma``
    × accuracy) or ``default_sigma_m``. GNSS errors are correlated in time (multipath,
    atmosphere, a receiver converging) and grow with the accuracy the receiver reports:
    the horizontal error of fix k is σ_k (√ρ β_k + √(1 − ρ) v_k), v white and β a unit
    first-order Gauss–Markov process (two states, correlation time ``gnss_bias_time_s``),
    ρ = ``gnss_correlated_fraction`` the correlated share of the variance (0: white fixes,
    no β). So a minute of fixes is not taken for a minute of independent evidence.
    Chi-square gating with ``gate_probability``; after ``reset_after_rejections`` fixes in
    a row fail the gate the filter has lost the GNSS (its position is wrong, or the GNSS
    jumped): the position is forgotten and taken again from the fix, however far (0: never);
    the systems a constraint holds to the phone move with it when the move is longer than the
    limit (:meth:`~bodyfusion.core.fuser.Fuser.follow_position_resets`). Skipped:
    a fix whose reported ground speed exceeds ``max_speed_mps`` (more than a walking
    pedestrian's: the receiver's solution moving on its own, converging from a cold start
    or jumping between multipath solutions; nor can it be the start), and a fix that
    repeats the previous one's position exactly (a receiver holding its solution while
    the phone stands: no new measurement).

    GNSS heading (eq. 44, σ ``gnss_heading_sd_deg``) and the weights of the heading
    hypotheses: only from fixes taken while the phone walks (a step detected in the last
    ``walking_window_s``) and is held steadily (its Up direction in the phone frame turned
    by no more than ``pose_change_deg`` over any ``pose_window_s`` of the last
    ``pose_window_s``: otherwise it is being put away, swung or raised, and its yaw says
    nothing of the walking direction); the course also needs a speed of at least
    ``min_speed_for_heading_mps`` and a reported accuracy of at most
    ``max_accuracy_for_heading_m`` (a course from jitter or from a poor fix is noise).
    """

    step_length_sd_m: float = Field(default=0.1, gt=0)
    heading_noise_density: float = Field(default=0.002, ge=0)
    gyro_bias_sd: float | None = Field(default=None, ge=0, le=100.0)
    correlation_time_s: float = Field(default=300.0, gt=0)
    height_noise_density: float = Field(default=0.05, ge=0)
    accuracy_to_sigma: float = Field(default=0.66, gt=0, le=100.0)
    default_sigma_m: float = Field(default=5.0, gt=0)
    gnss_heading_sd_deg: float = Field(default=15.0, gt=0)
    min_speed_for_heading_mps: float = Field(default=0.8, ge=0)
    max_accuracy_for_heading_m: float = Field(default=10.0, gt=0)
    walking_window_s: float = Field(default=2.0, gt=0)
    pose_change_deg: float = Field(default=30.0, gt=0)
    pose_window_s: float = Field(default=2.0, gt=0)
    max_speed_mps: float = Field(default=2.5, gt=0)
    gate_probability: float = Field(default=0.999, gt=0, lt=1)
    reset_after_rejections: int = Field(default=10, ge=0, le=1_000_000)
    gnss_correlated_fraction: float = Field(default=0.8, ge=0, lt=1)
    gnss_bias_time_s: float = Field(default=60.0, gt=0)
    step_scale_sd: float = Field(default=0.0, ge=0, le=10.0)
    step_scale_random_walk: float = Field(default=1e-4, ge=0)


class PdrInitialConfig(StrictModel):
    """Initial state: position (ENU, m; ``gnss``: the first fix that its successor confirms,
    see :class:`~bodyfusion.plugins.hand_pdr.system.HandPdr`), heading (azimuth of walking,
    degrees clockwise from North; ``auto``: aligned to the other systems; ``gnss_track``:
    unknown at the start and acquired from the GNSS while the phone walks by a bank of
    ``heading_hypotheses`` filters spread round the circle, weighted by their likelihood
    of the fixes and collapsed into one once the mixture's heading σ is at most
    ``heading_resolved_sd_deg``, see :mod:`bodyfusion.plugins.hand_pdr.hypotheses`), and
    one-sigma uncertainties (``position_sd_m`` of a given position; a ``gnss`` start is
    taken with the fix's own σ; ``heading_sd_deg`` of a numeric or ``auto`` heading)."""

    position_m: tuple[float, float, float] | Literal["gnss"] = "gnss"
    heading_deg: float | Literal["gnss_track", "auto"] = "gnss_track"
    heading_hypotheses: int = Field(default=16, ge=4, le=360)
    """Hypotheses of the ``gnss_track`` bank; each starts with σ = 180° / count."""
    heading_resolved_sd_deg: float = Field(default=15.0, gt=0, le=90)
    """Heading σ of the mixture (degrees) at which the bank collapses into one filter."""
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


class QuasiStaticConfig(StrictModel):
    """Rejects magnetometer samples whose device azimuth turned differently from the gyro's
    azimuth: standard deviation of (ψ_d − ψ_gyro) over the last ``window_s`` above
    ``tolerance_deg`` (a bent field, or a phone swinging so the levelling fails). Needs no
    site values."""

    window_s: float = Field(default=2.0, gt=0)
    """Window before each sample, s."""
    tolerance_deg: float = Field(default=6.0, gt=0)
    """Accepted standard deviation of ψ_d − ψ_gyro over the window, degrees."""


class MagnetometerConfig(StrictModel):
    """Heading aiding by the magnetometer.

    Measurement: the tilt-compensated azimuth of the phone axis ``axis_b`` (the field's
    horizontal part, levelled with the accelerometer's gravity direction), plus the
    ``declination_deg`` (east of true North positive) → device azimuth ψ_d, degrees
    clockwise from true North. The phone is held at a nearly constant yaw offset o to the
    walking direction, ψ = ψ_d + o: o is an error state (random walk ``offset_random_walk``,
    degrees/√s). ``offset_deg``: its prior (degrees, with σ ``offset_sd_deg``) or ``auto``:
    set from the first accepted sample, o = ψ̂ − ψ_d, with the heading's uncertainty plus
    the measurement's (then the magnetometer holds the heading but cannot find it). Updates
    at most ``rate_hz`` per second (a decimation of the samples), σ ``sigma_deg``,
    chi-square gated with ``gate_probability``, after the ``field_check`` against the site's
    Earth field (null, the default: none; it needs the site's values) and the site-free
    ``quasi_static`` check (null: none). Data: the ``columns`` of the ``imu`` CSV (in
    ``unit``), or the MAGN lines of the ``phone_log`` (µT).

    Defaults that depend on the data (unset, they are filled in by :class:`HandPdrConfig`):
    a ``phone_log`` is an Android phone, whose sensor frame has y towards the top of the
    screen, held in front to read it (the top pointing where one walks): ``enabled`` when
    the log has MAGN lines, ``axis_b`` [0, 1, 0], ``offset_deg`` 0. An ``imu`` CSV's frame
    is the writer's: off, ``axis_b`` [1, 0, 0], ``offset_deg`` auto.
    """

    enabled: bool | None = None
    sigma_deg: float = Field(default=10.0, gt=0)
    declination_deg: float = Field(default=0.0, ge=-180, le=180)
    axis_b: tuple[float, float, float] | None = None
    """Phone-frame axis whose azimuth is the device azimuth (best one that stays horizontal)."""
    offset_deg: float | Literal["auto"] | None = None
    offset_sd_deg: float = Field(default=20.0, gt=0)
    offset_random_walk: float = Field(default=0.2, ge=0)
    gate_probability: float = Field(default=0.99, gt=0, lt=1)
    rate_hz: float = Field(default=1.0, gt=0)
    field_check: FieldCheckConfig | None = None
    quasi_static: QuasiStaticConfig | None = Field(default_factory=QuasiStaticConfig)
    columns: tuple[str, str, str] | None = None
    """Header names of the magnetometer x, y, z columns of the ``imu`` CSV (phone frame);
    cells may be empty where the magnetometer has no sample."""
    unit: Literal["uT", "nT", "G"] = "uT"
    """Unit of the CSV columns: µT, nT or gauss (100 µT)."""

    @field_validator("axis_b")
    @classmethod
    def _unit_axis(cls, v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is not None and not 0.5 < math.hypot(*v) < 2.0:
            raise ValueError("give a unit vector of the phone frame, e.g. [1, 0, 0]")
        return v


class HandPdrConfig(StrictModel):
    """A phone held in the hand: PDR from its IMU, corrected by GNSS.

    Data: either ``imu`` (a CSV, see :class:`bodyfusion.io.imu.ImuCsvConfig`) or ``phone_log``
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
        phone, m = self.phone_log is not None, self.magnetometer  # the data's defaults (MagnetometerConfig)
        if m.enabled is None and not phone:
            m.enabled = False
        if m.axis_b is None:
            m.axis_b = (0.0, 1.0, 0.0) if phone else (1.0, 0.0, 0.0)
        if m.offset_deg is None:
            m.offset_deg = 0.0 if phone else "auto"
        if self.filter.gyro_bias_sd is None:
            self.filter.gyro_bias_sd = 0.01 if phone else 0.002
        if self.gnss is not None and self.gnss.format == "phone_log" and self.phone_log is None:
            raise KeyedError("gnss.format", "phone_log GNSS needs the system's phone_log")
        if self.gnss is None and ("gnss" in (self.initial.position_m, ) or self.initial.heading_deg == "gnss_track"):
            raise KeyedError("initial", "without gnss, give initial.position_m and a numeric or auto heading_deg")
        if self.magnetometer.enabled and self.imu is not None and self.magnetometer.columns is None:
            raise KeyedError("magnetometer.columns", "a magnetometer read from the imu CSV needs its three columns")
        return self
