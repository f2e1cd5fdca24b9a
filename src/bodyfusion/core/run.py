"""``fusion run``: build a layout's systems, fuse them, score against truth, write outputs."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymap3d

from bodyfusion.core.layout import LoadedLayout, apply_axis_map, load_layout
from bodyfusion.nav.earth import normal_gravity
from bodyfusion.core.errors import ConfigError
from bodyfusion.core.fuser import Fuser, FuserReport
from bodyfusion.core.heading import align_headings
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore, score_systems
from bodyfusion.core.output import write_outputs
from bodyfusion.io.phone_log import read_getsensordata
from bodyfusion.core.registry import get_registry
from bodyfusion.io.readers import read_truth_csv, read_truth_long_csv
from bodyfusion.plugins.foot_ins.smoothing import smooth_systems
from bodyfusion.core.system import AidingSource, LayoutContext, SensorSystem
from bodyfusion.core.types import InputReport, Trajectory, TruthTrack


@dataclass
class RunResult:
    """Everything a run produced: systems (with their histories), trajectories, scores."""

    loaded: LoadedLayout
    systems: dict[str, SensorSystem]
    trajectories: dict[str, Trajectory]
    truths: dict[str, TruthTrack]
    transform: PlanarTransform
    scores: dict[str, SystemScore]
    fuser: FuserReport
    heading_rotations_rad: dict[str, float]
    geodetic_origin: tuple[float, float, float] | None
    timings_s: dict[str, float]
    aiding: dict[str, AidingSource] = field(default_factory=dict)
    """Aiding sources (UWB tags...): no trajectory; diagnostics in metrics.json ``aiding``."""

    @property
    def samples(self) -> int:
        """Input samples of every system and aiding source together."""
        return int(np.sum([s.samples for s in (*self.systems.values(), *self.aiding.values())]))

    @property
    def input_report(self) -> InputReport:
        report = InputReport()
        for s in (*self.systems.values(), *self.aiding.values()):
            report = report.merge(s.input_report)
        return report


def layout_context(loaded: LoadedLayout, seed: int = 0) -> LayoutContext:
    lay = loaded.layout
    g = lay.gravity_mps2 if lay.gravity_mps2 is not None else normal_gravity(lay.latitude_deg, lay.height_m)
    outages: dict[str, tuple[tuple[float, float], ...]] = {}
    for o in lay.outages:
        outages[o.system] = (*outages.get(o.system, ()), (o.start_s, o.duration_s))
    return LayoutContext(gravity_mps2=g, latitude_deg=lay.latitude_deg, base_dir=loaded.path.resolve().parent,
                         seed=seed, geodetic_origin=lay.geodetic_origin, outages=outages)


def build_systems(loaded: LoadedLayout, context: LayoutContext) -> dict[str, SensorSystem | AidingSource]:
    """One system (or aiding source) per layout entry; a plugin's config error is reported
    against the layout file."""
    registry = get_registry()
    systems = {}
    for name, cfg in loaded.system_configs.items():
        try:
            systems[name] = registry.system_class(cfg.plugin)(name, cfg, context)
        except ConfigError as err:
            if err.path is not None:
                raise
            raise ConfigError(err.key, err.reason, loaded.path) from None
    return systems


def geodetic_origin(loaded: LoadedLayout, systems: dict[str, SensorSystem]) -> tuple[float, float, float] | None:
    """The ENU frame's origin: the layout's, else the first system's that has one (its first fix)."""
    if loaded.layout.geodetic_origin is not None:
        return loaded.layout.geodetic_origin
    return next((s.geodetic_origin for s in systems.values() if getattr(s, "geodetic_origin", None)), None)


def load_truth(loaded: LoadedLayout, origin: tuple[float, float, float] | None = None) -> dict[str, TruthTrack]:
    truth = loaded.layout.truth
    if truth is None or truth.path is None:
        return {}
    if truth.format == "phone_log":
        ref = read_getsensordata(truth.path).reference
        if ref is None:
            raise ConfigError("truth.path", "the log has no POSI lines", loaded.path)
        if origin is None:
            raise ConfigError("geodetic_origin", "surveyed truth needs a geodetic origin", loaded.path)
        e, n, _ = pymap3d.geodetic2enu(ref.lat_deg, ref.lon_deg, np.full(len(ref.t), origin[2]), *origin)
        pos = np.column_stack([e, n, np.zeros(len(ref.t))])
        return {name: TruthTrack(ref.t, pos, sparse=True) for name in truth.score_systems}
    if truth.format == "long":
        tracks = read_truth_long_csv(truth.path, sparse=truth.sparse)
        return {name: tr for name, tr in tracks.items() if name in loaded.layout.systems}
    tracks = read_truth_csv(truth.path, position_columns=truth.systems, time_column=truth.time_column,
                            time_scale=truth.time_scale, rate_hz=truth.rate_hz, skip_rows=truth.skip_rows,
                            delimiter=truth.delimiter, sparse=truth.sparse)
    return {name: TruthTrack(tr.t, apply_axis_map(truth.axes, tr.pos_n), tr.sparse) for name, tr in tracks.items()}


def run_layout(loaded: LoadedLayout, seed: int = 0) -> RunResult:
    """Run a validated layout in-process (no files written)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    context = layout_context(loaded, seed)
    built = build_systems(loaded, context)
    aiding = {name: s for name, s in built.items() if isinstance(s, AidingSource)}
    systems = {name: s for name, s in built.items() if name not in aiding}
    origin = geodetic_origin(loaded, systems)
    truths = load_truth(loaded, origin)
    timings["load_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    rotations = align_headings(systems, loaded.layout.heading_alignment)
    report = Fuser(systems, loaded.layout.fuser, loaded.layout.constraints, aiding).run()
    timings["navigation_s"] = time.perf_counter() - t0

    if loaded.layout.smoother.kind != "none":
        t0 = time.perf_counter()
        smooth_systems(systems, loaded.layout.smoother, loaded.layout.constraints, loaded.layout.fuser)
        timings["smoothing_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    trajectories = {name: s.trajectory() for name, s in systems.items()}
    truth_cfg = loaded.layout.truth
    if truths:
        transform, scores = score_systems(trajectories, truths, alignment=truth_cfg.alignment,
                                          loop=truth_cfg.loop, alignment_distance_m=truth_cfg.alignment_distance_m)
    else:
        transform, scores = PlanarTransform.identity(), {}
    timings["scoring_s"] = time.perf_counter() - t0
    return RunResult(loaded, systems, trajectories, truths, transform, scores, report, rotations, origin, timings,
                     aiding)


def run(config_path: str | Path, overrides: list[str] | None = None, out_dir: str | Path | None = None,
        seed: int = 0) -> tuple[RunResult, Path]:
    """Load, run, and write outputs; returns the result and the output folder."""
    t0 = time.perf_counter()
    loaded = load_layout(config_path, overrides)
    result = run_layout(loaded, seed)
    out = Path(out_dir) if out_dir is not None else (loaded.layout.output.dir or Path("out") / loaded.name)
    write_outputs(result, out, str(config_path), total_wall_s=time.perf_counter() - t0)
    return result, out
