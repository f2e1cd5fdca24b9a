"""Layout section of a foot-mounted INS (``plugin: foot_ins``)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from bodyfusion.base.sections import DataPath, KeyedError, StrictModel
from bodyfusion.core.layout import PositionFrame
from bodyfusion.io.imu import ImuCsvConfig
from bodyfusion.nav.stance_detectors import STANCE_DETECTORS, StanceDetector


ENSEMBLE_KINDS = ("enekf", "cenekf")
COLOURED_KINDS = ("ckf", "cenekf")
MAX_MEMBERS = 2000
"""Largest ensemble: 2000 members run about 300 samples/s (100 members: 5,300), so a minute of
100 Hz data per foot takes 20 s; larger ensembles would run for hours on a walk."""
STANCE_WIDTH_M = 0.2
"""Lateral distance between the feet of a person standing (m): where an unset initial position
puts the feet of a layout, either side of the origin."""
BODY_POSITION_SD_M = 0.05
"""One-sigma of a foot's initial position placed by the body (m): stances vary."""
MAX_WINDOW = 1000
"""Largest stance-detector window, samples (10 s at 100 Hz: longer than any stance)."""


class FootFilterConfig(StrictModel):
    """Error-state filter settings. Noise densities: accelerometer m/s^2/√Hz, gyroscope
    rad/s/√Hz; bias random walks m/s^3/√Hz and rad/s^2/√Hz; ZUPT σ in m/s, ZARU σ in rad/s."""

    kind: Literal["ekf", "ckf", "enekf", "cenekf"] = "ekf"
    """Estimator: ``ekf`` (15-state error-state EKF); ``ckf`` (the EKF with the zero-velocity
    update under coloured measurement noise, [Xu2024] eqs. 5–18); ``enekf`` (ensemble EKF
    whose members carry the attitude quaternion, [Deng2026] eqs. 1–19); ``cenekf`` (the
    ensemble filter with the coloured noise in an augmented state, eqs. 5–7)."""
    colour_factor: float = Field(default=0.0, ge=0, lt=1)
    """Colour factor α of the stance noise v_k = α v_{k−1} + ξ_k, in [0, 1) (ckf, cenekf)."""
    members: int = Field(default=100, ge=2, le=MAX_MEMBERS)
    """Ensemble size M, 2 to :data:`MAX_MEMBERS` (enekf, cenekf)."""
    acc_noise_density: float = Field(default=0.02, gt=0)
    """Accelerometer white noise, m/s^2/√Hz."""
    gyro_noise_density: float = Field(default=0.002, gt=0)
    """Gyroscope white noise, rad/s/√Hz."""
    acc_bias_random_walk: float = Field(default=1e-4, ge=0)
    """Accelerometer bias random walk, m/s^3/√Hz."""
    gyro_bias_random_walk: float = Field(default=1e-5, ge=0)
    """Gyroscope bias random walk, rad/s^2/√Hz."""
    acc_bias_tau_s: float | None = Field(default=None, gt=0)
    """Correlation time τ of a first-order Gauss–Markov accelerometer bias, s: the bias and
    its estimate decay as e^(−t/τ), driven by ``acc_bias_random_walk`` (σ √(2/τ) for a
    stationary σ). null: a random walk. The ensemble kinds keep the random walk."""
    gyro_bias_tau_s: float | None = Field(default=None, gt=0)
    """Correlation time τ of a first-order Gauss–Markov gyroscope bias, s (as ``acc_bias_tau_s``)."""
    zupt_sigma_mps: float = Field(default=0.01, gt=0)
    """Zero-velocity pseudo-measurement noise, m/s; for ckf and cenekf the σ of the white
    driving noise ξ of the coloured noise."""
    zupt_gate_probability: float | None = Field(default=0.999, gt=0, lt=1)
    """Chi-square gate of every zero-velocity update (ekf, ckf; 3 degrees of freedom): a
    consistent update passes with this probability; beyond the gate the update is de-weighted
    to the gate (bounded influence, :mod:`bodyfusion.nav.zupt`) and counted. null: off."""
    zupt_pivot_m: float = Field(default=0.1, ge=0, le=0.5)
    """Distance (m) from the IMU to the point the foot rolls about in stance (heel, ball): a
    stance sample's zero velocity has σ √(zupt_sigma² + (pivot |ω|)²), ω its angular rate
    (:func:`bodyfusion.nav.zupt.stance_velocity_sigma`): a rolling foot is not at rest. 0: off."""
    zaru_sigma_radps: float | None = Field(default=None, gt=0)
    """Zero-angular-rate update noise, rad/s; unset: no ZARU."""
    earth_rate: bool = False
    """Include the Earth rotation rate in the mechanisation."""


class DetectorConfig(StrictModel):
    """Zero-velocity detector: ``kind`` selects one of :mod:`bodyfusion.nav.stance_detectors`
    (``adaptive``, the default: SHOE with a threshold that follows the gait; ``shoe``: OpenShoe's
    fixed threshold; ``magnitude``; ``axes_band``; ``labels``: the data's stance column; or a
    registered one), and the fields below set its parameters; a field left unset is the
    detector's own default, a field the detector does not take is refused. Stance runs shorter
    than ``min_stance_s`` and swing gaps shorter than ``min_swing_s`` are then removed."""

    kind: str = "adaptive"
    """The detector (:data:`bodyfusion.nav.stance_detectors.STANCE_DETECTORS`)."""
    window: int | None = Field(default=None, ge=1, le=MAX_WINDOW)
    """Samples per test window, at most :data:`MAX_WINDOW` (shoe, magnitude, axes_band: 5;
    adaptive: 25 ms at the recording's rate)."""
    threshold: float | None = Field(default=None, gt=0, le=1e12)
    """shoe, adaptive: the SHOE γ below which a window is stance (3e4, OpenShoe's); magnitude:
    the largest | ‖f‖ − g |, m/s^2 (0.5)."""
    motion_threshold: float | None = Field(default=None, gt=0, le=1e12)
    """adaptive: the SHOE statistic above which a sample is never stance (1e7: an RMS angular
    rate of ~5.5 rad/s at the default σ_ω)."""
    margin_decades: float | None = Field(default=None, gt=0)
    """adaptive: how far (decades of the statistic) above its gait cycle's floor stance reaches (0.5)."""
    prominence_decades: float | None = Field(default=None, gt=0)
    """adaptive: how far (decades) a cycle's swing must rise above its floor for the cycle to
    be a gait (1.0; below it only ``threshold`` applies: standing, fidgeting)."""
    sigma_acc: float | None = Field(default=None, gt=0, le=100.0)
    """shoe, adaptive: accelerometer noise σ_a, m/s^2 (0.01)."""
    sigma_gyro: float | None = Field(default=None, gt=0, le=100.0)
    """shoe, adaptive: gyroscope noise σ_ω, rad/s (0.1 °/s)."""
    low: float | None = Field(default=None, ge=-1e4, le=1e4)
    """axes_band: the band's lower edge, m/s^2 (g − 1)."""
    high: float | None = Field(default=None, ge=-1e4, le=1e4)
    """axes_band: the band's upper edge, m/s^2 (g + 1)."""
    min_stance_s: float = Field(default=0.0, ge=0)
    """Shortest stance kept, s (0: every one)."""
    min_swing_s: float = Field(default=0.0, ge=0)
    """Shortest swing kept between two stances, s (0: every one)."""

    @model_validator(mode="after")
    def _known_detector(self) -> DetectorConfig:
        detector = STANCE_DETECTORS.get(self.kind)
        if detector is None:
            raise KeyedError("kind", f"unknown stance detector {self.kind!r} (have {', '.join(sorted(STANCE_DETECTORS))})")
        taken = set(detector.parameters())
        for name in DETECTOR_PARAMETERS:
            if getattr(self, name) is not None and name not in taken:
                raise KeyedError(name, f"the {self.kind} detector takes no {name} (it takes "
                                       f"{', '.join(detector.parameters()) or 'nothing'})")
        try:
            self.detector()
        except ValueError as err:  # the detector's own checks: the first parameter it names is the key
            named = [name for name in DETECTOR_PARAMETERS if name in str(err) and getattr(self, name) is not None]
            raise KeyedError(named[0] if named else "kind", str(err)) from None
        return self

    def detector(self) -> StanceDetector:
        """The detector, made with the parameters set here (ValueError from its own checks)."""
        params = {name: getattr(self, name) for name in DETECTOR_PARAMETERS if getattr(self, name) is not None}
        return STANCE_DETECTORS[self.kind](**params)


DETECTOR_PARAMETERS = ("window", "threshold", "motion_threshold", "margin_decades", "prominence_decades", "sigma_acc",
                       "sigma_gyro", "low", "high")
"""The fields of :class:`DetectorConfig` that are a detector's parameters (by the same names)."""


class InitialStateConfig(StrictModel):
    """Initial state at the first sample: position (ENU m), heading (azimuth of the
    horizontal projection of the body ``heading_axis``, degrees clockwise from North, or
    ``auto``, the default: aligned with the other systems of the layout, and 0 for a system
    alone; :mod:`bodyfusion.core.heading`), and one-sigma uncertainties.

    The IMU is levelled and its gyro bias estimated on the first still interval of the
    recording (:mod:`bodyfusion.nav.initial_alignment`): at least ``stationary_s`` long, with the
    spreads of specific force and angular rate within ``still_acc_sd_mps2`` and
    ``still_gyro_sd_radps``. Motion before it is navigated backward from it to give the
    state at the first sample. Without any still interval the first of the quietest windows is
    used, the level and gyro-bias σ at least the standard errors of its means (a warning
    says so)."""

    position_m: tuple[float, float, float] | None = None
    """Initial position, ENU m. Unset: the origin for a foot alone; in a layout of several
    systems, the foot's place in a stance at the origin: half of :data:`STANCE_WIDTH_M` to the
    left or right of the walking direction (``foot``), with ``position_sd_m`` at least
    :data:`BODY_POSITION_SD_M` (twice that when the side is unknown)."""
    heading_deg: float | Literal["auto"] = "auto"
    heading_axis: Literal["x", "y", "z"] = "x"
    """Body axis whose heading ``heading_deg`` gives; if it is within 30° of vertical at
    rest, the most horizontal axis is used instead (a warning says so)."""
    stationary_s: float = Field(default=0.5, gt=0)
    """Shortest still interval used for levelling and the gyro bias, s."""
    still_acc_sd_mps2: float = Field(default=0.2, gt=0)
    """Largest spread √(Σ var) of the specific force over a still window, m/s^2."""
    still_gyro_sd_radps: float = Field(default=0.05, gt=0)
    """Largest spread √(Σ var) of the angular rate over a still window, rad/s."""
    position_sd_m: float = Field(default=1e-3, gt=0)
    """Initial position one-sigma, m."""
    velocity_sd_mps: float = Field(default=1e-2, gt=0)
    """Initial velocity one-sigma, m/s."""
    level_sd_deg: float = Field(default=1.0, gt=0)
    """Initial roll and pitch one-sigma, degrees."""
    heading_sd_deg: float = Field(default=1.0, gt=0)
    """Initial heading one-sigma, degrees."""
    acc_bias_sd_mps2: float = Field(default=0.05, gt=0)
    """Initial accelerometer bias one-sigma, m/s^2."""
    gyro_bias_sd_radps: float = Field(default=1e-3, gt=0)
    """Initial gyroscope bias one-sigma (after the stationary-window estimate), rad/s."""


class PositionFixConfig(PositionFrame):
    """Absolute position fixes (ENU, m) from a CSV: applied at the last IMU sample at or
    before each fix time, with noise σ (m) and chi-square innovation gating
    (``gate_probability`` of a consistent fix passing; 3 degrees of freedom).
    ``frame`` declares the file's axes (``enu``, ``ned`` or a signed axis map)."""

    path: DataPath
    """CSV file of fixes; relative to the layout file."""
    columns: tuple[str, str, str]
    """Header names of the three position columns."""
    time_column: str | None = None
    """Column of fix times, multiplied by time_scale to give seconds."""
    time_scale: float = Field(default=1.0, gt=0, le=1e6)
    """Factor from the time column to seconds."""
    rate_hz: float | None = Field(default=None, gt=0)
    """Fixed fix rate (Hz) when the file has no time column."""
    delimiter: str = ","
    """Field separator."""
    sigma_m: float = Field(default=0.3, gt=0)
    """Fix noise one-sigma per axis, m."""
    gate_probability: float = Field(default=0.99, gt=0, lt=1)

    @model_validator(mode="after")
    def _time_source(self) -> "PositionFixConfig":
        if (self.time_column is None) == (self.rate_hz is None):
            raise ValueError("give exactly one of time_column or rate_hz")
        return self


class FootInsConfig(StrictModel):
    """A foot-mounted IMU with strapdown navigation, ZUPT and a 15-state error filter."""

    plugin: Literal["foot_ins"] = "foot_ins"
    foot: Literal["left", "right"] | None = None
    """Which foot wears it; unset: from the system's name (``left`` or ``right`` in it), else unknown."""
    data: ImuCsvConfig
    filter: FootFilterConfig = Field(default_factory=FootFilterConfig)
    detector: DetectorConfig = Field(default_factory=DetectorConfig)
    initial: InitialStateConfig = Field(default_factory=InitialStateConfig)
    position_fixes: PositionFixConfig | None = None

    @model_validator(mode="after")
    def _labels_need_a_stance_column(self) -> "FootInsConfig":
        if self.detector.kind == "labels" and self.data.stance_column is None:
            raise KeyedError("detector.kind", "labels need data.stance_column")
        return self

    @model_validator(mode="after")
    def _colour_needs_a_coloured_kind(self) -> "FootInsConfig":
        f = self.filter
        if f.colour_factor != 0.0 and f.kind not in COLOURED_KINDS:
            raise KeyedError("filter.colour_factor", f"applies to filter.kind ckf or cenekf, not {f.kind}")
        return self
