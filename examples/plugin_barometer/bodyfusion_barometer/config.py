"""Layout section of the barometric altimeter (``plugin: barometer``).

Every parameter carries ``Field(description=...)``: the rule ``bodyfusion.testing`` checks.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from bodyfusion.base.sections import DataPath, StrictModel


class PressureCsvConfig(StrictModel):
    """A pressure log as CSV with a header row: one row per sample."""

    path: DataPath = Field(description="CSV file; relative paths resolve against the layout file's folder.")
    time_column: str = Field(default="t_s", description="Column of the sample time; seconds after time_scale.")
    time_scale: float = Field(default=1.0, gt=0, description="Factor turning the time column into seconds.")
    pressure_column: str = Field(default="pressure_pa", description="Column of the static pressure.")
    pressure_unit: Literal["Pa", "hPa"] = Field(default="Pa", description="Unit of the pressure column.")
    delimiter: str = Field(default=",", description="Field separator of the CSV.")


class BaroFilterConfig(StrictModel):
    """Noise of the 4-state error filter [δE, δN, δU (m), δb (Pa)]."""

    pressure_sigma_pa: float = Field(default=3.0, gt=0, description="One-sigma noise of a pressure sample (Pa).")
    height_random_walk: float = Field(
        default=0.3, ge=0, description="How fast the carrier's true height may wander: random walk, m/√s.")
    bias_random_walk: float = Field(
        default=0.2, ge=0, description="Drift of the pressure bias (weather, temperature): random walk, Pa/√s.")
    horizontal_random_walk: float = Field(
        default=1.5, ge=0, description="Growth of the East/North uncertainty the barometer cannot observe: m/√s.")


class BaroInitialConfig(StrictModel):
    """The start: where the carrier is and how well that is known; the pressure reference."""

    position_m: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="Start position, ENU (m); Up is the height of the reference pressure.")
    horizontal_sd_m: float = Field(
        default=1000.0, gt=0, description="One-sigma East/North uncertainty at the start (m): large, the "
        "barometer knows nothing of them.")
    height_sd_m: float = Field(default=0.1, gt=0, description="One-sigma height uncertainty at the start (m).")
    bias_sd_pa: float = Field(default=5.0, gt=0, description="One-sigma pressure bias at the start (Pa).")
    reference_pressure_pa: float | None = Field(
        default=None, gt=10_000, lt=120_000, description="Pressure (Pa) at the start height; default: the mean "
        "of the first reference_window_s of data.")
    reference_window_s: float = Field(
        default=1.0, gt=0, description="Window at the start (s) whose mean pressure is the reference.")
    reference_temperature_k: float = Field(
        default=288.15, gt=150, lt=350, description="Air temperature at the start height (K), for the "
        "standard-atmosphere lapse rate.")


class BarometerConfig(StrictModel):
    """A barometric altimeter: height from static pressure, its bias estimated."""

    plugin: Literal["barometer"] = Field(default="barometer", description="This plugin's name.")
    data: PressureCsvConfig = Field(description="Where the pressure samples are.")
    filter: BaroFilterConfig = Field(default_factory=BaroFilterConfig, description="Filter noise settings.")
    initial: BaroInitialConfig = Field(default_factory=BaroInitialConfig, description="Initial state.")
