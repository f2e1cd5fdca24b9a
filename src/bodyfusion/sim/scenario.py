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

``path``: see :mod:`bodyfusion.sim.paths`; ``gait``: :class:`bodyfusion.sim.gait_config.GaitConfig`;
``systems.<name>``: dispatched on ``kind`` to the plugin that simulates it (each plugin's
``fusion_simulation_kinds`` hook returns its kinds, :class:`bodyfusion.sim.context.SystemKind`:
a strict section model and a simulation function that writes the plugin's layout section);
``layout``: any part of the
layout (constraints, fuser, a system's detector or filter ...), deep-merged over what
the simulator generates (except ``layout.outages``, which is appended to the outages the
systems generate).

``kind: foot_imu`` (:class:`bodyfusion.plugins.foot_ins.simulation.FootImuSystem`): an IMU on
one foot; it writes ``<system>_imu.csv`` (with the true ``stance``) and a ``foot_ins`` section.

``kind: hand_phone`` (:class:`bodyfusion.plugins.hand_pdr.simulation.HandPhoneSystem`, motion in :mod:`bodyfusion.sim.hand`, receiver
in :mod:`bodyfusion.sim.gnss`): a phone held in front of the body with a GNSS receiver; it
writes ``<system>_imu.csv`` (with a ``step`` column: 1 at each true heel strike, and
``mag_x, mag_y, mag_z`` in µT with a ``magnetometer``) and
``<system>_gnss.csv``, a ``plugin: hand_pdr`` section, and its GNSS ``outages`` into the
layout's ``outages`` list (fixes are not removed from the file). ``geodetic_origin``
(default :data:`DEFAULT_GEODETIC_ORIGIN`) goes into the layout when a system uses GNSS
or the scenario sets it.

``kind: uwb_tag`` (:class:`bodyfusion.plugins.uwb.simulation.UwbTagSystem`): a UWB tag on another simulated
system (``host``) ranging to anchors and to tags on other systems, with NLOS bursts and
dropouts; it writes ``<system>_ranges.csv`` and a ``plugin: uwb`` section, and no truth
rows. Aiding kinds are simulated after the systems they ride on.

:func:`simulate` writes into ``out_dir``: ``<system>_imu.csv`` per IMU, ``truth.csv``
(``system,t,east_m,north_m,up_m``, one row per system per sample) and ``config.yaml``,
a layout that ``fusion run`` runs as is.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import Field, field_validator

from bodyfusion.core import registry as plugin_registry
from bodyfusion.base.errors import ConfigError
from bodyfusion.base.sections import StrictModel
from bodyfusion.core.layout import Layout, apply_overrides, read_yaml, validate_section
from bodyfusion.sim.context import DEFAULT_GEODETIC_ORIGIN, SimContext, SystemKind
from bodyfusion.sim.files import FLOAT_FORMAT
from bodyfusion.sim.gait import plan_gait
from bodyfusion.sim.gait_config import GaitConfig
from bodyfusion.sim.paths import PATH_KINDS, PathConfig

__all__ = ["LoadedScenario", "Scenario", "SimulationResult", "TRUTH_COLUMNS", "load_scenario", "simulate"]

TRUTH_COLUMNS = ("system", "t", "east_m", "north_m", "up_m")
TRUTH_FILE = "truth.csv"
CONFIG_FILE = "config.yaml"


class Scenario(StrictModel):
    """The scenario file. ``path`` and each ``systems`` section are validated afterwards by
    the model their ``kind`` names (:data:`bodyfusion.sim.paths.PATH_KINDS`, the plugins'
    simulated kinds)."""

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
    """A validated scenario: the file's model, its path section, each system's section and
    the kind (the plugin) that simulates it."""

    scenario: Scenario
    path: PathConfig
    systems: dict[str, Any]
    kinds: dict[str, SystemKind] = field(default_factory=dict)


def load_scenario(path: str | Path, overrides: list[str] | None = None) -> LoadedScenario:
    """Read, override and validate a scenario file (path and systems by their ``kind``)."""
    path = Path(path)
    raw = apply_overrides(read_yaml(path), overrides or [])
    base_dir = path.resolve().parent
    scenario = validate_section(Scenario, raw, key="", path=path, base_dir=base_dir)
    path_model = _kind_model(PATH_KINDS, scenario.path, "path", path)
    path_cfg = validate_section(path_model, scenario.path, key="path", path=path, base_dir=base_dir)
    known = plugin_registry.get_registry().simulation_kinds()
    systems: dict[str, Any] = {}
    kinds: dict[str, SystemKind] = {}
    for name, section in scenario.systems.items():
        model = _kind_model({k: v.config for k, v in known.items()}, section, f"systems.{name}", path)
        systems[name] = validate_section(model, section, key=f"systems.{name}", path=path, base_dir=base_dir)
        kinds[name] = known[systems[name].kind]
    layout_systems = scenario.layout.get("systems") or {}
    if not isinstance(layout_systems, dict):
        raise ConfigError("layout.systems", "must be a mapping of system names", path)
    for name in layout_systems:
        if name not in systems:
            raise ConfigError(f"layout.systems.{name}", f"not a simulated system (have {sorted(systems)})", path)
    return LoadedScenario(scenario, path_cfg, systems, kinds)


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
    scenario, systems, kinds = loaded.scenario, loaded.systems, loaded.kinds
    try:
        plan = plan_gait(loaded.path.build(), scenario.gait, scenario.rate_hz)
    except ConfigError as err:
        raise ConfigError(err.key, err.reason, scenario_path) from None
    out_dir.mkdir(parents=True, exist_ok=True)
    origin = scenario.geodetic_origin if scenario.geodetic_origin is not None else DEFAULT_GEODETIC_ORIGIN
    ctx = SimContext(scenario.rate_hz, scenario.gravity_mps2, scenario.gait, plan, plan.t, int(seed), out_dir,
                     tuple(float(v) for v in origin))

    for name in sorted(systems, key=lambda n: kinds[n].aids):  # aiding kinds last
        try:
            ctx.outputs[name] = kinds[name].simulate(name, systems[name], ctx)
        except ConfigError as err:
            if err.path is not None:
                raise
            raise ConfigError(err.key, err.reason, scenario_path) from None
    outputs = {name: ctx.outputs[name] for name in systems}

    truth_path = out_dir / TRUTH_FILE
    with truth_path.open("w", newline="") as fh:
        fh.write(",".join(TRUTH_COLUMNS) + "\n")
        for name, out in outputs.items():
            fmt = name.replace("%", "%%") + "," + ",".join([FLOAT_FORMAT] * 4)
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
