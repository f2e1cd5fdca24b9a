"""Scenario files and :func:`simulate`: a walk, the systems worn, and what to write.

A scenario (YAML, validated strictly: unknown keys are errors)::

    name: dual_foot_square            # default: the file's stem
    rate_hz: 100                      # IMU sample rate (Hz); samples at t = k / rate_hz
    gravity_mps2: 9.80665             # g used for the IMU and written into config.yaml
    path: {kind: rectangle, length_m: 20, width_m: 10, laps: 2, clockwise: true}
    gait: {stride_m: 1.4, cadence_steps_per_min: 108, stance_fraction: 0.6}
    systems:
      left_foot:  {kind: foot_imu, foot: left,  imu: {preset: icm20948}}
      right_foot: {kind: foot_imu, foot: right, imu: {preset: icm20948}, mount_yaw_deg: 7}
      hand_phone: {kind: hand_phone, imu: {preset: phone}, gnss: {outages: [{start_s: 120, duration_s: 60}]}}
    geodetic_origin: [49.4613, 11.1109, 390.0]   # lat, lon, h of the ENU frame (for GNSS)
    layout: {}                        # merged over the generated config.yaml

``path``: see :mod:`bodyfusion.sim.paths`; ``gait``: :class:`bodyfusion.sim.gait.GaitConfig`;
``systems.<name>``: dispatched on ``kind`` through :data:`SYSTEM_KINDS` (each kind has
its own strict model and simulation function, so later kinds — a hand-held phone, a
GNSS receiver, a UWB tag — plug in by adding one entry); ``layout``: any part of the
layout (constraints, fuser, a system's detector or filter ...), deep-merged over what
the simulator generates (except ``layout.outages``, which is appended to the outages the
systems generate).

``kind: hand_phone`` (:class:`HandPhoneSystem`, motion in :mod:`bodyfusion.sim.hand`, receiver
in :mod:`bodyfusion.sim.gnss`): a phone held in front of the body with a GNSS receiver; it
writes ``<system>_imu.csv`` (with a ``step`` column: 1 at each true heel strike, and
``mag_x, mag_y, mag_z`` in µT with a ``magnetometer``) and
``<system>_gnss.csv``, a ``plugin: hand_pdr`` section, and its GNSS ``outages`` into the
layout's ``outages`` list (fixes are not removed from the file). ``geodetic_origin``
(default :data:`DEFAULT_GEODETIC_ORIGIN`) goes into the layout when a system uses GNSS
or the scenario sets it.

``kind: uwb_tag`` (:class:`bodyfusion.sim.uwb.UwbTagSystem`): a UWB tag on another simulated
system (``host``) ranging to anchors and to tags on other systems, with NLOS bursts and
dropouts; it writes ``<system>_ranges.csv`` and a ``plugin: uwb`` section, and no truth
rows. Aiding kinds are simulated after the systems they ride on.

:func:`simulate` writes into ``out_dir``: ``<system>_imu.csv`` per IMU, ``truth.csv``
(``system,t,east_m,north_m,up_m``, one row per system per sample) and ``config.yaml``,
a layout that ``fusion run`` runs as is.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from pydantic import Field, field_validator

from bodyfusion.core.layout import Layout, StrictModel, apply_overrides, read_yaml, validate_section
from bodyfusion.core.errors import ConfigError
from bodyfusion.core.seeding import system_seed
from bodyfusion.sim.context import DEFAULT_GEODETIC_ORIGIN, SimContext, SystemOutput
from bodyfusion.sim.gait import GaitConfig, StanceNoiseConfig, plan_gait, stance_drift
from bodyfusion.sim.gnss import GnssReceiverConfig, simulate_fixes, write_gnss_csv
from bodyfusion.sim.hand import HandSwayConfig, hand_motion, heel_strikes
from bodyfusion.sim.imu import ImuErrorConfig, corrupt, error_generators, ideal_imu
from bodyfusion.sim.magnetometer import MagnetometerSimConfig, simulate_magnetometer
from bodyfusion.sim.paths import PATH_KINDS, PathConfig
from bodyfusion.sim.uwb import UwbTagSystem, simulate_uwb_tag

__all__ = [
    "DEFAULT_GEODETIC_ORIGIN",
    "FootImuSystem",
    "HAND_IMU_COLUMNS",
    "HAND_MAG_COLUMNS",
    "HandPhoneSystem",
    "IMU_COLUMNS",
    "LoadedScenario",
    "Scenario",
    "SimContext",
    "SimulationResult",
    "SystemKind",
    "SystemOutput",
    "SYSTEM_KINDS",
    "TRUTH_COLUMNS",
    "load_scenario",
    "simulate",
]

IMU_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z", "stance")
HAND_IMU_COLUMNS = ("t", "acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z", "step")
HAND_MAG_COLUMNS = ("mag_x", "mag_y", "mag_z")
"""Magnetometer columns (µT) of a hand phone's IMU CSV, before ``step``, when it has one."""
TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")
TRUTH_FILE = "truth.csv"
CONFIG_FILE = "config.yaml"
_FLOAT = "%.10g"


class Scenario(StrictModel):
    """The scenario file. ``path`` and each ``systems`` section are validated afterwards by
    the model their ``kind`` names (:data:`bodyfusion.sim.paths.PATH_KINDS`, :data:`SYSTEM_KINDS`)."""

    name: str | None = None
    rate_hz: float = Field(default=100.0, gt=0)
    gravity_mps2: float = Field(default=9.80665, gt=9.7, lt=9.9)
    path: dict[str, Any]
    gait: GaitConfig = Field(default_factory=GaitConfig)
    systems: dict[str, dict[str, Any]] = Field(min_length=1)
    geodetic_origin: tuple[float, float, float] | None = None
    """(lat deg, lon deg, h m) of the ENU frame; unset: :data:`DEFAULT_GEODETIC_ORIGIN`."""
    layout: dict[str, Any] = Field(default_factory=dict)

    @field_validator("geodetic_origin")
    @classmethod
    def _origin_range(cls, v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is not None and (abs(v[0]) > 90 or abs(v[1]) > 180):
            raise ValueError("latitude must be within ±90 deg and longitude within ±180 deg")
        return v


class FootImuSystem(StrictModel):
    """An IMU strapped to one foot (``kind: foot_imu``); ``mount_yaw_deg`` turns it on the
    foot clockwise seen from above (its x axis then points that far right of the toe);
    ``stance_noise`` (default none) lets the foot drift with an AR(1) velocity in stance
    (:class:`bodyfusion.sim.gait.StanceNoiseConfig`; draws from ``system_seed(seed, name + "#stance")``);
    ``heading_error_sd_deg``: σ of the error of the initial heading written into the
    config (0: the true heading; draw from ``system_seed(seed, name + "#heading")``)."""

    kind: Literal["foot_imu"]
    foot: Literal["left", "right"]
    imu: ImuErrorConfig = Field(default_factory=ImuErrorConfig)
    mount_yaw_deg: float = Field(default=0.0, ge=-180, le=180)
    stance_noise: StanceNoiseConfig | None = None
    heading_error_sd_deg: float = Field(default=0.0, ge=0, le=90)


@dataclass(frozen=True)
class SystemKind:
    """A ``systems.<name>.kind``: its section model, its simulation function and the
    plugin the layout section it writes is for."""

    config: type[StrictModel]
    simulate: Callable[[str, Any, SimContext], SystemOutput]
    plugin: str
    aids: bool = False
    """An aiding kind (a UWB tag): simulated after the systems, whose truth it needs."""


@dataclass
class SimulationResult:
    """What :func:`simulate` wrote: files, samples per system, distance walked (m)."""

    out_dir: Path
    config_path: Path
    truth_path: Path
    samples: dict[str, int]
    distance_m: float
    duration_s: float
    files: dict[str, list[Path]] = field(default_factory=dict)


# --------------------------------------------------------------------------- foot IMU


def _write_imu_csv(path: Path, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, stance: np.ndarray) -> None:
    table = np.column_stack([t, acc, gyro, stance.astype(float)])
    np.savetxt(path, table, fmt=[_FLOAT] * 7 + ["%d"], delimiter=",", header=",".join(IMU_COLUMNS),
               comments="")


def imu_data_section(csv_path: Path, columns: tuple[str, ...]) -> dict[str, Any]:
    """The layout's reading of an IMU CSV written here (``t``, then acc x y z, gyro x y z)."""
    return {"path": csv_path.name, "time_column": "t", "acc_columns": list(columns[1:4]),
            "gyro_columns": list(columns[4:7])}


def measured_imu(motion, name: str, imu: ImuErrorConfig, ctx: SimContext) -> tuple[np.ndarray, np.ndarray]:
    """What the IMU of system ``name`` riding ``motion`` reports: ideal specific force and
    rate at the scenario's samples, corrupted by its error model from its own random streams."""
    sc = ctx.scenario
    acc, gyro = ideal_imu(motion, ctx.t, sc.gravity_mps2)
    errors = imu.resolve()
    rngs = error_generators(ctx.seed, name)
    return (corrupt(acc, sc.rate_hz, errors.acc, rngs, "acc"),
            corrupt(gyro, sc.rate_hz, errors.gyro, rngs, "gyro"))


HEADING_SD_FLOOR_DEG = 0.05
"""Initial heading σ (deg) a simulated foot filter is told when it is given the true heading."""


def _simulate_foot_imu(name: str, cfg: FootImuSystem, ctx: SimContext) -> SystemOutput:
    motion = ctx.plan.feet[cfg.foot].mounted(cfg.mount_yaw_deg)
    t = ctx.t
    if cfg.stance_noise is not None:
        rng = np.random.Generator(np.random.PCG64(system_seed(ctx.seed, f"{name}#stance")))
        motion = stance_drift(motion, t.size, cfg.stance_noise, rng)
    acc, gyro = measured_imu(motion, name, cfg.imu, ctx)
    stance = motion.stance_flags(t.size)
    csv_path = ctx.out_dir / f"{name}_imu.csv"
    _write_imu_csv(csv_path, t, acc, gyro, stance)

    pos = motion.evaluate(t).pos
    azimuth = math.degrees(float(motion.footprint_az[0])) + cfg.mount_yaw_deg
    if cfg.heading_error_sd_deg > 0:
        rng = np.random.Generator(np.random.PCG64(system_seed(ctx.seed, f"{name}#heading")))
        azimuth += cfg.heading_error_sd_deg * float(rng.standard_normal())
    errors = cfg.imu.resolve()
    filt: dict[str, Any] = {"kind": "ekf", "earth_rate": False}
    for key, value in (("acc_noise_density", errors.acc.noise_density),
                       ("gyro_noise_density", errors.gyro.noise_density),
                       ("acc_bias_random_walk", errors.acc.bias_drift_density),
                       ("gyro_bias_random_walk", errors.gyro.bias_drift_density)):
        if value > 0:
            filt[key] = float(value)
    section = {
        "plugin": "foot_ins",
        "data": {**imu_data_section(csv_path, IMU_COLUMNS), "stance_column": "stance"},
        "filter": filt,
        "initial": {
            "position_m": [float(v) for v in pos[0]],
            "heading_deg": float(azimuth % 360.0),
            "heading_sd_deg": max(cfg.heading_error_sd_deg, HEADING_SD_FLOOR_DEG),
        },
    }
    # the filter starts with the heading and bias uncertainty the simulated sensor has:
    # the gyro bias after the still window's average, the accelerometer's turn-on and drift σ
    for key, value in (("gyro_bias_sd_radps", errors.gyro.initial_bias_sd(ctx.plan.start_still_s)),
                       ("acc_bias_sd_mps2", errors.acc.initial_bias_sd())):
        if value > 0:
            section["initial"][key] = float(value)
    return SystemOutput(t, pos, section, int(t.size), [csv_path])


# --------------------------------------------------------------------------- hand-held phone


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


def _simulate_hand_phone(name: str, cfg: HandPhoneSystem, ctx: SimContext) -> SystemOutput:
    sc = ctx.scenario
    cycle_s, _ = sc.gait.cycle_s()
    motion = hand_motion(ctx.plan, int(round(cycle_s * sc.rate_hz)), seed=ctx.seed, name=name,
                         offset_m=cfg.offset_m, bounce_m=cfg.bounce_m, lateral_sway_m=cfg.lateral_sway_m,
                         mount_yaw_deg=cfg.mount_yaw_deg, sway=cfg.sway,
                         heading_smoothing_m=cfg.heading_smoothing_m)
    t = ctx.t
    acc, gyro = measured_imu(motion, name, cfg.imu, ctx)
    steps = np.zeros(t.size, dtype=bool)
    steps[heel_strikes(ctx.plan)] = True
    state = motion.evaluate(t)
    mag = cfg.magnetometer
    m_b = np.empty((t.size, 0)) if mag is None else simulate_magnetometer(state, mag, seed=ctx.seed, name=name)
    columns = HAND_IMU_COLUMNS[:7] + (HAND_MAG_COLUMNS if mag is not None else ()) + HAND_IMU_COLUMNS[7:]
    imu_path = ctx.out_dir / f"{name}_imu.csv"
    table = np.column_stack([t, acc, gyro, m_b, steps.astype(float)])
    np.savetxt(imu_path, table, fmt=[_FLOAT] * (len(columns) - 1) + ["%d"], delimiter=",",
               header=",".join(columns), comments="")
    files = [imu_path]

    pos = state.pos
    _, az0 = ctx.plan.path.start
    section: dict[str, Any] = {
        "plugin": "hand_pdr",
        "imu": imu_data_section(imu_path, HAND_IMU_COLUMNS),
    }
    if mag is not None:
        intensity, inclination, declination = mag.field_summary
        section["magnetometer"] = {"enabled": True, "columns": list(HAND_MAG_COLUMNS), "declination_deg": declination,
                                   "field_check": {"expected_uT": intensity, "inclination_deg": inclination}}
    outages: list[dict[str, Any]] = []
    if cfg.gnss is not None:
        fixes, _ = simulate_fixes(motion, float(t[-1]), ctx.geodetic_origin, cfg.gnss, seed=ctx.seed, name=name)
        gnss_path = ctx.out_dir / f"{name}_gnss.csv"
        write_gnss_csv(gnss_path, fixes)
        files.append(gnss_path)
        section["gnss"] = {"format": "csv", "path": gnss_path.name}
        outages = [{"system": name, "start_s": float(o.start_s), "duration_s": float(o.duration_s)}
                   for o in cfg.gnss.outages]
    section["initial"] = {
        "position_m": [float(v) for v in pos[0]],
        "heading_deg": float(math.degrees(az0) % 360.0),
    }
    return SystemOutput(t, pos, section, int(t.size), files, outages=outages,
                        uses_geodetic_origin=cfg.gnss is not None)


SYSTEM_KINDS: dict[str, SystemKind] = {
    "foot_imu": SystemKind(FootImuSystem, _simulate_foot_imu, "foot_ins"),
    "hand_phone": SystemKind(HandPhoneSystem, _simulate_hand_phone, "hand_pdr"),
    "uwb_tag": SystemKind(UwbTagSystem, simulate_uwb_tag, "uwb", aids=True),
}
"""``systems.<name>.kind`` → how to validate and simulate it."""


# --------------------------------------------------------------------------- scenario


def _deep_merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _deep_merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _kind_model(table: dict[str, type[StrictModel]], section: Any, key: str, path: Path) -> type[StrictModel]:
    kind = section.get("kind") if isinstance(section, dict) else None
    if kind not in table:
        reason = "missing key kind" if kind is None else f"unknown kind {kind!r}"
        raise ConfigError(f"{key}.kind", f"{reason} (known: {', '.join(sorted(table))})", path)
    return table[kind]


@dataclass
class LoadedScenario:
    """A validated scenario: the file's model, its path section and each system's section."""

    scenario: Scenario
    path: PathConfig
    systems: dict[str, Any]


def load_scenario(path: str | Path, overrides: list[str] | None = None) -> LoadedScenario:
    """Read, override and validate a scenario file (path and systems by their ``kind``)."""
    path = Path(path)
    raw = apply_overrides(read_yaml(path), overrides or [])
    base_dir = path.resolve().parent
    scenario = validate_section(Scenario, raw, key="", path=path, base_dir=base_dir)
    path_model = _kind_model(PATH_KINDS, scenario.path, "path", path)
    path_cfg = validate_section(path_model, scenario.path, key="path", path=path, base_dir=base_dir)
    systems: dict[str, Any] = {}
    for name, section in scenario.systems.items():
        model = _kind_model({k: v.config for k, v in SYSTEM_KINDS.items()}, section, f"systems.{name}", path)
        systems[name] = validate_section(model, section, key=f"systems.{name}", path=path, base_dir=base_dir)
    layout_systems = scenario.layout.get("systems") or {}
    if not isinstance(layout_systems, dict):
        raise ConfigError("layout.systems", "must be a mapping of system names", path)
    for name in layout_systems:
        if name not in systems:
            raise ConfigError(f"layout.systems.{name}", f"not a simulated system (have {sorted(systems)})", path)
    return LoadedScenario(scenario, path_cfg, systems)


def simulate(scenario_path: Path, out_dir: Path, seed: int = 0,
             overrides: list[str] | None = None) -> SimulationResult:
    """Simulate the scenario at ``scenario_path`` into ``out_dir`` (created if needed).

    Same scenario, overrides and seed → the same bytes in every file.
    """
    scenario_path = Path(scenario_path)
    out_dir = Path(out_dir)
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError("seed", f"must be a non-negative integer, got {seed!r}")
    loaded = load_scenario(scenario_path, overrides)
    scenario, systems = loaded.scenario, loaded.systems
    try:
        plan = plan_gait(loaded.path.build(), scenario.gait, scenario.rate_hz)
    except ConfigError as err:
        raise ConfigError(err.key, err.reason, scenario_path) from None
    out_dir.mkdir(parents=True, exist_ok=True)
    ctx = SimContext(scenario, plan, plan.t, int(seed), out_dir)

    for name in sorted(systems, key=lambda n: SYSTEM_KINDS[systems[n].kind].aids):  # aiding kinds last
        ctx.outputs[name] = SYSTEM_KINDS[systems[name].kind].simulate(name, systems[name], ctx)
    outputs = {name: ctx.outputs[name] for name in systems}

    truth_path = out_dir / TRUTH_FILE
    with truth_path.open("w", newline="") as fh:
        fh.write(",".join(TRUTH_COLUMNS) + "\n")
        for name, out in outputs.items():
            fmt = name.replace("%", "%%") + "," + ",".join([_FLOAT] * 4)
            np.savetxt(fh, np.column_stack([out.truth_t, out.truth_pos]), fmt=fmt)

    name = scenario.name or scenario_path.stem
    layout: dict[str, Any] = {
        "name": name,
        "gravity_mps2": scenario.gravity_mps2,
    }
    if scenario.geodetic_origin is not None or any(out.uses_geodetic_origin for out in outputs.values()):
        layout["geodetic_origin"] = list(ctx.geodetic_origin)
    layout["systems"] = {n: out.layout for n, out in outputs.items()}
    outages = [o for out in outputs.values() for o in out.outages]
    if outages:
        layout["outages"] = outages
    layout["truth"] = {"path": TRUTH_FILE, "format": "long", "alignment": "none", "loop": plan.path.closed}
    over = dict(scenario.layout)
    if outages and isinstance(over.get("outages"), list):
        over["outages"] = outages + list(over["outages"])
    layout = _deep_merge(layout, over)
    validate_section(Layout, layout, key="layout", path=scenario_path, base_dir=out_dir)
    config_path = out_dir / CONFIG_FILE
    header = (f"# Simulated by `fusion simulate` from {scenario_path.name} (seed {int(seed)}"
              + (f", overrides: {' '.join(overrides)}" if overrides else "") + ").\n"
              f"# {plan.distance_m:.2f} m walked in {plan.t[-1]:.2f} s; truth in {TRUTH_FILE}, no alignment.\n")
    config_path.write_text(header + yaml.safe_dump(layout, sort_keys=False, default_flow_style=None))

    return SimulationResult(
        out_dir=out_dir,
        config_path=config_path,
        truth_path=truth_path,
        samples={n: out.samples for n, out in outputs.items()},
        distance_m=plan.distance_m,
        duration_s=float(plan.t[-1]),
        files={n: out.files for n, out in outputs.items()},
    )
