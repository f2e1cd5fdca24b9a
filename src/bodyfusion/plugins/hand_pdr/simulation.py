"""Simulated hand-held phones (scenario ``kind: hand_phone``): the phone's motion in front of
the walking body (:mod:`bodyfusion.sim.hand`), its IMU (and magnetometer) with the scenario's
error model, its GNSS receiver (:mod:`bodyfusion.sim.gnss`), and the ``hand_pdr`` layout
section that runs it, built with the plugin's own models."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.plugins.hand_pdr.config import (FieldCheckConfig, GnssSourceConfig, HandPdrConfig, MagnetometerConfig,
                                                PdrInitialConfig)
from bodyfusion.sim.context import SimContext, SystemKind, SystemOutput, layout_section
from bodyfusion.sim.files import imu_csv_section, imu_file
from bodyfusion.sim.gnss import GnssReceiverConfig, gnss_file, simulate_fixes
from bodyfusion.sim.hand import HandSwayConfig, hand_motion, heel_strikes
from bodyfusion.sim.imu import ImuErrorConfig, measured_imu
from bodyfusion.sim.magnetometer import MagnetometerSimConfig, simulate_magnetometer

IMU_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z", "step")
"""Columns of a simulated phone IMU CSV: time (s), specific force (m/s^2), rate (rad/s), 1 at each true heel strike."""
MAG_COLUMNS = ("mag_x", "mag_y", "mag_z")
"""Magnetometer columns (µT) of a phone's IMU CSV, before ``step``, when it has one."""


class HandPhoneSystem(StrictModel):
    """A phone held in front of the body with a GNSS receiver (``kind: hand_phone``).

    ``offset_m``: (forward, left, up) from the body path point, in the walking frame;
    ``bounce_m``: vertical body bounce amplitude (one period per step);
    ``lateral_sway_m``: body sway towards the stance foot (one period per stride);
    ``sway``: the hand's own smooth random wobble; ``heading_smoothing_m``: arc length over
    which the body frame's heading is smoothed at the path's corners; ``mount_yaw_deg``: the phone's x axis
    turned clockwise (from above) from the walking direction; ``gnss``: the receiver
    (``null`` for none); ``magnetometer``: the phone's magnetometer (default none; its
    columns go into the IMU CSV and an enabled ``magnetometer`` section, with the field
    check set to the simulated Earth field, into the layout). Motion in
    :mod:`bodyfusion.sim.hand`, receiver in :mod:`bodyfusion.sim.gnss`, magnetometer in
    :mod:`bodyfusion.sim.magnetometer`.
    """

    kind: Literal["hand_phone"]
    imu: ImuErrorConfig = Field(default_factory=lambda: ImuErrorConfig(preset="phone"))
    offset_m: tuple[float, float, float] = (0.3, -0.2, 1.1)
    bounce_m: float = Field(default=0.03, ge=0, le=0.2)
    lateral_sway_m: float = Field(default=0.02, ge=0, le=0.2)
    mount_yaw_deg: float = Field(default=0.0, ge=-180, le=180)
    sway: HandSwayConfig = Field(default_factory=HandSwayConfig)
    heading_smoothing_m: float = Field(default=1.0, gt=0)
    gnss: GnssReceiverConfig | None = Field(default_factory=GnssReceiverConfig)
    magnetometer: MagnetometerSimConfig | None = None


def simulate_hand_phone(name: str, cfg: HandPhoneSystem, ctx: SimContext) -> SystemOutput:
    """The phone's IMU file (``<name>_imu.csv``, read by the section ``imu``), its GNSS fixes
    (``<name>_gnss.csv``, section ``gnss``) with their outages for the layout's ``outages`` list,
    its truth and its ``hand_pdr`` section."""
    cycle_s, _ = ctx.gait.cycle_s()
    motion = hand_motion(ctx.plan, int(round(cycle_s * ctx.rate_hz)), seed=ctx.seed, name=name,
                         offset_m=cfg.offset_m, bounce_m=cfg.bounce_m, lateral_sway_m=cfg.lateral_sway_m,
                         mount_yaw_deg=cfg.mount_yaw_deg, sway=cfg.sway,
                         heading_smoothing_m=cfg.heading_smoothing_m)
    t = ctx.t
    acc, gyro = measured_imu(motion, t, ctx.rate_hz, ctx.gravity_mps2, cfg.imu, ctx.seed, name)
    steps = np.zeros(t.size, dtype=bool)
    steps[heel_strikes(ctx.plan)] = True
    state = motion.evaluate(t)
    mag = cfg.magnetometer
    m_b = np.empty((t.size, 0)) if mag is None else simulate_magnetometer(state, mag, seed=ctx.seed, name=name)
    columns = IMU_COLUMNS[:7] + (MAG_COLUMNS if mag is not None else ()) + IMU_COLUMNS[7:]
    files = [imu_file("imu", f"{name}_imu.csv", columns, t, acc, gyro, m_b, flags=steps)]

    _, az0 = ctx.plan.path.start
    section: dict[str, Any] = {
        "plugin": "hand_pdr",
        "imu": imu_csv_section(Path(files[0].name), IMU_COLUMNS),
        "initial": PdrInitialConfig(position_m=tuple(float(v) for v in state.pos[0]),
                                    heading_deg=float(math.degrees(az0) % 360.0)),
    }
    if mag is not None:
        intensity, inclination, declination = mag.field_summary
        section["magnetometer"] = MagnetometerConfig(
            enabled=True, columns=MAG_COLUMNS, declination_deg=declination,
            field_check=FieldCheckConfig(expected_uT=intensity, inclination_deg=inclination))
    outages: list[dict[str, Any]] = []
    if cfg.gnss is not None:
        fixes, _ = simulate_fixes(motion, float(t[-1]), ctx.geodetic_origin, cfg.gnss, seed=ctx.seed, name=name)
        files.append(gnss_file("gnss", f"{name}_gnss.csv", fixes))
        section["gnss"] = GnssSourceConfig(format="csv", path=files[-1].name)
        outages = [{"system": name, "start_s": float(o.start_s), "duration_s": float(o.duration_s)}
                   for o in cfg.gnss.outages]
    return SystemOutput(t, state.pos, layout_section(HandPdrConfig(**section)), int(t.size), files, outages=outages,
                        uses_geodetic_origin=cfg.gnss is not None)


SIMULATION_KINDS = [SystemKind("hand_phone", HandPhoneSystem, simulate_hand_phone, "hand_pdr")]
"""What this plugin simulates (returned by its ``fusion_simulation_kinds`` hook)."""
