"""Simulated foot IMUs (scenario ``kind: foot_imu``): the foot's motion from the planned gait,
its IMU with the error model of the scenario, and the ``foot_ins`` layout section that runs it.

The layout section is built with the plugin's own models (:class:`FootInsConfig` and its
parts): the filter is told the simulated sensor's own error model — its noise densities, its
bias drift (a Gauss–Markov bias with its correlation time when that is all the bias is, else
the random walk of the same driving density), the uncertainty of the initial biases the
still-window average leaves, the ZUPT σ of the simulated stance (:func:`stance_sigma_mps`) —
the initial position and the heading of the IMU's x axis at the first sample (true, or with a
drawn error of ``heading_error_sd_deg``).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.base.seeding import system_seed
from bodyfusion.plugins.foot_ins.config import FootFilterConfig, FootInsConfig, InitialStateConfig
from bodyfusion.sim.context import SimContext, SystemKind, SystemOutput, layout_section
from bodyfusion.sim.files import imu_csv_section, imu_file
from bodyfusion.sim.foot_motion import stance_drift
from bodyfusion.sim.gait_config import StanceNoiseConfig
from bodyfusion.sim.imu import ImuErrorConfig, measured_imu

IMU_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z", "stance")
"""Columns of a simulated foot IMU CSV: time (s), specific force (m/s^2), rate (rad/s), the true stance label."""

HEADING_SD_FLOOR_DEG = 0.05
"""Initial heading σ (deg) a simulated foot filter is told when it is given the true heading."""

STILL_ZUPT_SIGMA_MPS = 1e-4
"""ZUPT σ (m/s) for a simulated foot at rest in stance: the zero velocity is exact, and 0.1 mm/s
keeps the update well conditioned (one sample of ICM-20948 noise at 125 Hz moves the velocity
by 0.15 mm/s)."""


class FootImuSystem(StrictModel):
    """An IMU strapped to one foot (``kind: foot_imu``); ``mount_yaw_deg`` turns it on the
    foot clockwise seen from above (its x axis then points that far right of the toe);
    ``stance_noise`` (default none) lets the foot drift with an AR(1) velocity in stance
    (:class:`bodyfusion.sim.gait_config.StanceNoiseConfig`; draws from ``system_seed(seed, name + "#stance")``);
    ``heading_error_sd_deg``: σ of the error of the initial heading written into the
    config (0: the true heading; draw from ``system_seed(seed, name + "#heading")``)."""

    kind: Literal["foot_imu"]
    foot: Literal["left", "right"]
    imu: ImuErrorConfig = Field(default_factory=ImuErrorConfig)
    mount_yaw_deg: float = Field(default=0.0, ge=-180, le=180)
    stance_noise: StanceNoiseConfig | None = None
    heading_error_sd_deg: float = Field(default=0.0, ge=0, le=90)


def stance_sigma_mps(stance_noise: StanceNoiseConfig | None) -> float:
    """The ZUPT σ (m/s) of the simulated stance: the stationary σ_ξ / √(1 − α²) of its AR(1)
    velocity, or :data:`STILL_ZUPT_SIGMA_MPS` for a foot at rest."""
    if stance_noise is None or stance_noise.sigma_mps == 0:
        return STILL_ZUPT_SIGMA_MPS
    return max(stance_noise.sigma_mps / math.sqrt(1.0 - stance_noise.colour_factor**2), STILL_ZUPT_SIGMA_MPS)


def simulate_foot_imu(name: str, cfg: FootImuSystem, ctx: SimContext) -> SystemOutput:
    """The foot's IMU file (``<name>_imu.csv``, true stance labels in ``stance``, read by the
    section ``data``), its truth and its ``foot_ins`` layout section."""
    motion = ctx.plan.feet[cfg.foot].mounted(cfg.mount_yaw_deg)
    t = ctx.t
    if cfg.stance_noise is not None:
        rng = np.random.Generator(np.random.PCG64(system_seed(ctx.seed, f"{name}#stance")))
        motion = stance_drift(motion, t.size, cfg.stance_noise, rng)
    acc, gyro = measured_imu(motion, t, ctx.rate_hz, ctx.gravity_mps2, cfg.imu, ctx.seed, name)
    imu = imu_file("data", f"{name}_imu.csv", IMU_COLUMNS, t, acc, gyro, flags=motion.stance_flags(t.size))

    pos = motion.evaluate(t).pos
    azimuth = math.degrees(float(motion.footprint_az[0])) + cfg.mount_yaw_deg
    if cfg.heading_error_sd_deg > 0:
        rng = np.random.Generator(np.random.PCG64(system_seed(ctx.seed, f"{name}#heading")))
        azimuth += cfg.heading_error_sd_deg * float(rng.standard_normal())
    errors = cfg.imu.resolve()
    noise = {key: float(value) for key, value in (
        ("acc_noise_density", errors.acc.noise_density), ("gyro_noise_density", errors.gyro.noise_density),
        ("acc_bias_random_walk", errors.acc.bias_drift_density),
        ("gyro_bias_random_walk", errors.gyro.bias_drift_density),
        ("acc_bias_tau_s", errors.acc.gauss_markov_tau_s), ("gyro_bias_tau_s", errors.gyro.gauss_markov_tau_s))
        if value}
    # the filter starts with the heading and bias uncertainty the simulated sensor has:
    # the gyro bias after the still window's average, the accelerometer's turn-on and drift σ
    priors = {key: float(value) for key, value in (
        ("gyro_bias_sd_radps", errors.gyro.initial_bias_sd(ctx.plan.start_still_s)),
        ("acc_bias_sd_mps2", errors.acc.initial_bias_sd())) if value > 0}
    section = FootInsConfig(
        plugin="foot_ins",
        data=imu_csv_section(Path(imu.name), IMU_COLUMNS, stance_column="stance"),
        filter=FootFilterConfig(kind="ekf", earth_rate=False, zupt_sigma_mps=stance_sigma_mps(cfg.stance_noise),
                                **noise),
        initial=InitialStateConfig(position_m=tuple(float(v) for v in pos[0]), heading_deg=float(azimuth % 360.0),
                                   heading_sd_deg=max(cfg.heading_error_sd_deg, HEADING_SD_FLOOR_DEG), **priors))
    return SystemOutput(t, pos, layout_section(section), int(t.size), [imu])


SIMULATION_KINDS = [SystemKind("foot_imu", FootImuSystem, simulate_foot_imu, "foot_ins")]
"""What this plugin simulates (returned by its ``fusion_simulation_kinds`` hook)."""
