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
import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from pydantic import Field

from bodyfusion.core import registry as plugin_registry
from bodyfusion.base.errors import ConfigError, FusionError
from bodyfusion.base.files import refuse_to_replace, sole_writer, staged_outputs
from bodyfusion.base.progress import ProgressCallback
from bodyfusion.base.sections import GeodeticPoint, StrictModel
from bodyfusion.core.layout import Layout
from bodyfusion.core.layout_io import apply_overrides, read_yaml, validate_section
from bodyfusion.sim.context import DEFAULT_GEODETIC_ORIGIN, SimContext, SystemKind, SystemOutput
from bodyfusion.sim.files import FLOAT_FORMAT, printed, savetxt_rows
from bodyfusion.sim.gait import plan_gait
from bodyfusion.sim.gait_config import GaitConfig
from bodyfusion.sim.paths import PATH_KINDS, PathConfig

log = logging.getLogger(__name__)

__all__ = [
    "TRUTH_COLUMNS",
    "LoadedScenario",
    "Scenario",
    "Simulated",
    "SimulationResult",
    "load_scenario",
    "simulate",
    "simulated",
]

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
    geodetic_origin: GeodeticPoint | None = None
    """(lat deg, lon deg, h m) of the ENU frame; unset: :data:`DEFAULT_GEODETIC_ORIGIN`."""
    layout: dict[str, Any] = Field(default_factory=dict)


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


def _kind_model(table: dict[str, type[StrictModel]], section: Any, key: str, path: Path | None) -> type[StrictModel]:
    kind = section.get("kind") if isinstance(section, dict) else None
    if kind not in table:
        reason = "missing key kind" if kind is None else f"unknown kind {kind!r}"
        raise ConfigError(f"{key}.kind", f"{reason} (known: {', '.join(sorted(table))})", path)
    return table[kind]


@dataclass
class LoadedScenario:
    """A validated scenario: the file's model, its path section, each system's section, the kind
    (the plugin) that simulates it, and its ``file`` (None: a scenario dict)."""

    scenario: Scenario
    path: PathConfig
    systems: dict[str, Any]
    kinds: dict[str, SystemKind] = field(default_factory=dict)
    file: Path | None = None


def load_scenario(source: str | Path | Mapping[str, Any],
                  overrides: Sequence[str] | Mapping[str, Any] | None = None) -> LoadedScenario:
    """Read (a YAML file, or a scenario dict), override and validate a scenario (path and
    systems by their ``kind``)."""
    path = Path(source) if isinstance(source, (str, Path)) else None
    raw = apply_overrides(read_yaml(path) if path is not None else dict(source), overrides or [])
    base_dir = path.resolve().parent if path is not None else Path.cwd()
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
    return LoadedScenario(scenario, path_cfg, systems, kinds, path)


@dataclass
class Simulated:
    """A simulated walk held in memory (:func:`simulated`): the scenario it came from, the seed
    and overrides, the walk's ``plan``, every system's output (truth, layout section, files) and
    ``layout``, the layout ``config.yaml`` holds (its sections name the files)."""

    loaded: LoadedScenario
    seed: int
    overrides: list[str]
    plan: Any
    outputs: dict[str, SystemOutput]
    layout: dict[str, Any]

    @property
    def name(self) -> str:
        return str(self.layout["name"])

    def truth_columns(self) -> dict[str, np.ndarray]:
        """``truth.csv`` as its columns hold it: ``system``, ``t``, ``east_m``, ``north_m``, ``up_m``
        (10 significant digits, as printed)."""
        outs = [(name, out) for name, out in self.outputs.items() if len(out.truth_t)]
        data = np.concatenate([np.column_stack([out.truth_t, out.truth_pos]) for _, out in outs])
        return {"system": np.concatenate([np.full(len(out.truth_t), name, dtype=object) for name, out in outs]),
                **{col: printed(data[:, j], FLOAT_FORMAT) for j, col in enumerate(TRUTH_COLUMNS[1:])}}

    def in_memory(self) -> tuple[dict[str, Any], dict[str, dict[str, np.ndarray]]]:
        """The layout with its sensor and truth sections reading tables in memory (no paths), and
        those tables by the dotted key of their section (``systems.<name>.<section>``, ``truth``):
        the columns the files would hold, so a run on them equals a run on the files."""
        layout = copy.deepcopy(self.layout)
        tables: dict[str, dict[str, np.ndarray]] = {}
        for name, out in self.outputs.items():
            for file in out.files:
                layout["systems"][name][file.section].pop("path")
                tables[f"systems.{name}.{file.section}"] = file.columns
        layout["truth"].pop("path")
        tables["truth"] = self.truth_columns()
        return layout, tables

    def relaid(self, loaded: LoadedScenario, overrides: Sequence[str] | Mapping[str, Any] | None,
               outages: Mapping[str, Sequence[tuple[float, float]]]) -> Simulated:
        """This walk and its data under the scenario ``loaded`` (the same scenario with other
        overrides of its ``layout`` section and of the ``outages`` of its systems), each system in
        ``outages`` with those (start s, duration s) windows: what :func:`simulated` gives for it,
        without simulating again. A system's outages only mask its data in the layout (its GNSS
        fixes stay in the file), so the data are the same; everything else that differs between
        the two scenarios must be in their ``layout`` sections (the caller's promise)."""
        outputs = {name: out if name not in outages else dataclasses.replace(out, outages=[
            {"system": name, "start_s": float(start), "duration_s": float(duration)}
            for start, duration in outages[name]]) for name, out in self.outputs.items()}
        return _assembled(loaded, self.seed, overrides, self.plan, outputs)

    def write(self, out_dir: str | Path, overwrite: bool = False) -> SimulationResult:
        """Write the sensor files, ``truth.csv`` and ``config.yaml`` into ``out_dir`` (created if
        needed): what ``fusion simulate`` writes. A folder already holding a file of those names
        is refused (:class:`~bodyfusion.base.errors.FusionError` naming them) unless
        ``overwrite``; the set is written into a staging folder and put in place together
        (:func:`~bodyfusion.base.files.staged_outputs`), so a write that fails keeps every earlier file."""
        out_dir = Path(out_dir)
        names = [f.name for out in self.outputs.values() for f in out.files] + [TRUTH_FILE, CONFIG_FILE]
        refuse_to_replace(out_dir, names, overwrite, "the simulation")
        log.info("writing the sensor files, %s and %s to %s", TRUTH_FILE, CONFIG_FILE, out_dir)
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
            with sole_writer(out_dir), staged_outputs(out_dir, last=(CONFIG_FILE,)) as staging:
                self._write_files(staging)
        except OSError as err:
            raise FusionError(f"{out_dir}: cannot write the simulation: {err.strerror or err} (the files there "
                              "are kept whole)") from None
        files = {name: [out_dir / f.name for f in out.files] for name, out in self.outputs.items()}
        return SimulationResult(out_dir=out_dir, config_path=out_dir / CONFIG_FILE, truth_path=out_dir / TRUTH_FILE,
                                samples={n: out.samples for n, out in self.outputs.items()},
                                distance_m=self.plan.distance_m, duration_s=float(self.plan.t[-1]), files=files)

    def _write_files(self, folder: Path) -> None:
        """Every file of :meth:`write` into ``folder``."""
        for out in self.outputs.values():
            for f in out.files:
                f.write(folder / f.name)
        with (folder / TRUTH_FILE).open("w", newline="") as fh:
            fh.write(",".join(TRUTH_COLUMNS) + "\n")
            for name, out in self.outputs.items():
                fmt = name.replace("%", "%%") + "," + ",".join([FLOAT_FORMAT] * 4)
                savetxt_rows(fh, [out.truth_t, out.truth_pos], fmt)
        source = self.loaded.file.name if self.loaded.file is not None else "a scenario"
        header = (f"# Simulated by `fusion simulate` from {source} (seed {self.seed}"
                  + (f", overrides: {' '.join(self.overrides)}" if self.overrides else "") + ").\n"
                  f"# {self.plan.distance_m:.2f} m walked in {self.plan.t[-1]:.2f} s; truth in {TRUTH_FILE}, "
                  "no alignment.\n")
        (folder / CONFIG_FILE).write_text(header + yaml.safe_dump(self.layout, sort_keys=False,
                                                                   default_flow_style=None))


def simulated(scenario: str | Path | Mapping[str, Any], seed: int = 0,
              overrides: Sequence[str] | Mapping[str, Any] | None = None,
              progress: ProgressCallback | None = None) -> Simulated:
    """Simulate a scenario (a YAML file, or a scenario dict) in memory: no file is written.

    Same scenario, overrides and seed → the same numbers, and :meth:`Simulated.write` the same
    bytes in every file. ``progress(done, total)`` is told the systems simulated."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ConfigError("seed", f"must be a non-negative integer, got {seed!r}")
    loaded = load_scenario(scenario, overrides)
    scenario_path = loaded.file
    scenario_cfg, systems, kinds = loaded.scenario, loaded.systems, loaded.kinds
    try:
        plan = plan_gait(loaded.path.build(), scenario_cfg.gait, scenario_cfg.rate_hz)
    except ConfigError as err:
        raise ConfigError(err.key, err.reason, scenario_path) from None
    origin = scenario_cfg.geodetic_origin if scenario_cfg.geodetic_origin is not None else DEFAULT_GEODETIC_ORIGIN
    ctx = SimContext(scenario_cfg.rate_hz, scenario_cfg.gravity_mps2, scenario_cfg.gait, plan, plan.t, int(seed),
                     tuple(float(v) for v in origin))

    log.info("planned the walk: %.1f m in %.1f s at %g Hz", plan.distance_m, plan.t[-1], scenario_cfg.rate_hz)
    for done, name in enumerate(sorted(systems, key=lambda n: kinds[n].aids)):  # aiding kinds last
        if progress is not None:
            progress(done, len(systems))
        log.info("simulating %s (%s)", name, systems[name].kind)
        try:
            ctx.outputs[name] = kinds[name].simulate(name, systems[name], ctx)
        except ConfigError as err:
            if err.path is not None:
                raise
            raise ConfigError(err.key, err.reason, scenario_path) from None
    if progress is not None:
        progress(len(systems), len(systems))
    return _assembled(loaded, int(seed), overrides, plan, {name: ctx.outputs[name] for name in systems})


def _assembled(loaded: LoadedScenario, seed: int, overrides: Sequence[str] | Mapping[str, Any] | None, plan: Any,
               outputs: dict[str, SystemOutput]) -> Simulated:
    """The simulated walk with the layout ``config.yaml`` holds: the systems' sections and
    outages, the truth, then the scenario's ``layout`` merged over them."""
    scenario_cfg = loaded.scenario
    origin = scenario_cfg.geodetic_origin if scenario_cfg.geodetic_origin is not None else DEFAULT_GEODETIC_ORIGIN
    layout: dict[str, Any] = {
        "name": scenario_cfg.name or (loaded.file.stem if loaded.file is not None else "scenario"),
        "gravity_mps2": scenario_cfg.gravity_mps2,
    }
    if scenario_cfg.geodetic_origin is not None or any(out.uses_geodetic_origin for out in outputs.values()):
        layout["geodetic_origin"] = [float(v) for v in origin]
    layout["systems"] = {n: out.layout for n, out in outputs.items()}
    outages = [o for out in outputs.values() for o in out.outages]
    if outages:
        layout["outages"] = outages
    layout["truth"] = {"path": TRUTH_FILE, "format": "long", "alignment": "none", "loop": plan.path.closed}
    over = dict(scenario_cfg.layout)
    if outages and isinstance(over.get("outages"), list):
        over["outages"] = outages + list(over["outages"])
    layout = _deep_merge(layout, over)
    validate_section(Layout, layout, key="layout", path=loaded.file, base_dir=None)
    return Simulated(loaded, seed, list(_override_texts(overrides)), plan, outputs, layout)


def _override_texts(overrides: Sequence[str] | Mapping[str, Any] | None) -> list[str]:
    """Overrides as the ``KEY=VALUE`` texts config.yaml's header names."""
    if isinstance(overrides, Mapping):
        return [f"{k}={v}" for k, v in overrides.items()]
    return list(overrides or [])


def simulate(scenario_path: Path, out_dir: Path, seed: int = 0, overrides: list[str] | None = None,
             progress: ProgressCallback | None = None, overwrite: bool = False) -> SimulationResult:
    """Simulate the scenario at ``scenario_path`` into ``out_dir`` (created if needed; files of
    the names it writes there refused unless ``overwrite``: :meth:`Simulated.write`);
    ``progress`` as :func:`simulated` takes it.

    Same scenario, overrides and seed → the same bytes in every file."""
    return simulated(scenario_path, seed, overrides, progress).write(out_dir, overwrite)
