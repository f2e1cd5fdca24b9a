"""``fusion run``: a layout's systems built (:mod:`~bodyfusion.runner.assemble`), fused, smoothed,
scored against truth (:mod:`bodyfusion.evaluation`), and its outputs written
(:mod:`bodyfusion.outputs`)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from bodyfusion.base.errors import FusionError, NotReady
from bodyfusion.base.interrupts import answer_pending
from bodyfusion.base.progress import ProgressCallback
from bodyfusion.base.types import LOG
from bodyfusion.core.capabilities import AbsoluteFixes, Smoothing, offers
from bodyfusion.core.compile_ahead import compile_fuser_ahead, finish_compiling_ahead
from bodyfusion.core.data_tables import require_data
from bodyfusion.core.epoch_state import EpochOutput
from bodyfusion.core.fuser import Fuser
from bodyfusion.core.heading import align_headings, heading_ties
from bodyfusion.core.health import CovarianceMonitor
from bodyfusion.core.layout import LoadedLayout, load_layout
from bodyfusion.core.limits import resolve_constraints
from bodyfusion.core.progress import FusionProgress
from bodyfusion.core.smoothing import constrain_trajectories, plan_smoothing, smooth_systems
from bodyfusion.core.system import AidingSource, Plugin, SensorSystem
from bodyfusion.evaluation.consistency import horizontal_nees
from bodyfusion.evaluation.figure_process import FigureProcess
from bodyfusion.evaluation.consistency_findings import nees_findings, nis_findings
from bodyfusion.evaluation.findings import large_error_findings, sensor_alone_findings, truth_separation_findings
from bodyfusion.evaluation.metrics import PlanarTransform, score_systems, sensor_alone_score
from bodyfusion.results.run_result import RunResult
from bodyfusion.runner.assemble import build_systems, geodetic_origin, layout_context, load_truth, navigation_frame
from bodyfusion.runner.truth import check_truth_overlap

__all__ = ["Fusion", "finish_fusion", "prepare_fusion", "run", "run_layout"]

log = logging.getLogger(__name__)


@dataclass
class Fusion:
    """A layout's systems built, aligned and handed to the fuser (:func:`prepare_fusion`), for
    :func:`finish_fusion` to run to the end (a live run advances ``fuser`` as its data arrive
    first: :mod:`bodyfusion.live`)."""

    loaded: LoadedLayout
    built: dict[str, Plugin]
    systems: dict[str, SensorSystem]
    aiding: dict[str, AidingSource]
    monitors: dict[str, CovarianceMonitor]
    fuser: Fuser
    constraints: list
    rotations: dict
    origin: tuple[float, float, float] | None
    truths: dict
    tracker: FusionProgress | None
    timings: dict[str, float] = field(default_factory=dict)
    t_fusing: float = 0.0
    """When the navigation began (s, :func:`time.perf_counter`)."""
    growing: bool = False
    """Built on the first part of a live run's recordings (the truth is checked against them at
    the finish)."""
    truth_spans: dict | None = None
    """The truth tracks' own spans (first, last epoch, s) where ``truths`` hold a part of them (a
    live run that read its truth as it went and kept the last part)."""


def prepare_fusion(loaded: LoadedLayout, seed: int = 0, progress: ProgressCallback | None = None,
                   output: EpochOutput | None = None, lookahead_s: float | None = None,
                   complete: bool = False, read_truth: bool = True) -> Fusion:
    """Build a validated layout's systems (the layout validated again as a whole first:
    :meth:`~bodyfusion.core.layout.LoadedLayout.checked`), read its truth, align the systems'
    headings and hand them to a :class:`~bodyfusion.core.fuser.Fuser` (emitting ``output`` epochs
    when given one). ``progress(done, total)`` is told the seconds of data fused
    (:class:`~bodyfusion.core.progress.FusionProgress`). ``lookahead_s``: the recordings are the
    first part of a live run's (:mod:`bodyfusion.live`): once aligned, every system decides its
    samples that far behind its newest (:meth:`~bodyfusion.core.capabilities.Streaming.start_streaming`);
    ``complete``: the live run's recordings are whole already (a system may not refuse them).
    On a live run's first part, a heading alignment without enough travel is
    :class:`~bodyfusion.base.errors.NotReady` and the truth is checked at the finish. Without
    ``read_truth`` the truth is left to the caller (a live run that reads it as it goes sets
    ``truths`` before the finish)."""
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    loaded = loaded.checked()
    require_data(loaded.layout, loaded.system_configs, loaded.path)
    ahead = compile_fuser_ahead(loaded.layout)  # a first run: the fuser's kernels compiled beside the systems'
    context = layout_context(loaded, seed, {"core.fuser": ahead} if ahead is not None else None,
                             growing=lookahead_s is not None and not complete)
    log.info("reading the data of %s", ", ".join(f"{n} ({c.plugin})" for n, c in loaded.system_configs.items()))
    built = build_systems(loaded, context)
    finish_compiling_ahead(context.compiling_ahead)  # before anything advances: the kernels are in the cache
    aiding = {name: s for name, s in built.items() if isinstance(s, AidingSource)}
    systems = {name: s for name, s in built.items() if name not in aiding}
    plan_smoothing(systems, loaded.layout.smoother)
    origin = geodetic_origin(loaded, systems)
    truths = load_truth(loaded, origin) if read_truth else {}
    growing = lookahead_s is not None and not complete
    if not growing:  # a live run's recordings are checked against the truth once complete (finish_fusion)
        check_truth_overlap(truths, {name: (s.t_start, s.t_end) for name, s in systems.items()}, loaded.path)
    timings["load_s"] = time.perf_counter() - t0

    t_fusing = time.perf_counter()
    if loaded.layout.constraints and loaded.layout.fuser.method == "none":
        LOG.warning("%s: fuser.method is none: the %d constraint(s) of the layout are not enforced",
                    loaded.path.name if loaded.path else loaded.name, len(loaded.layout.constraints))
    try:
        rotations = align_headings(systems, loaded.layout.heading_alignment)
    except FusionError as err:
        if lookahead_s is None or complete:
            raise
        raise NotReady(f"{err} yet") from None  # a live run's first part: its systems may walk on
    if lookahead_s is not None:
        for s in built.values():
            s.start_streaming(lookahead_s)
    tracker = FusionProgress(systems, progress) if progress is not None else None
    monitors = {name: CovarianceMonitor(tracker.track(s) if tracker else s) for name, s in systems.items()}
    log.info("fusing %d system(s) and %d aiding source(s): fuser.method %s, %d constraint(s)", len(systems),
             len(aiding), loaded.layout.fuser.method, len(loaded.layout.constraints))
    ties = heading_ties(systems, loaded.layout.heading_alignment)
    constraints, follows = resolve_constraints(loaded.layout.constraints,
                                               {name: s.body_part for name, s in built.items()}, loaded.layout.body)
    fuser = Fuser(monitors, loaded.layout.fuser, constraints, aiding, ties, follows, loaded.layout.body, output)
    if (loaded.layout.smoother.smooths_jointly(loaded.layout.fuser) and fuser.joint is not None
            and all(offers(systems[s.name], Smoothing) for s in fuser.joint.systems)):
        fuser.joint.keep_corrections()  # for the joint smoother (a member that does not smooth: none)
    return Fusion(loaded, built, systems, aiding, monitors, fuser, constraints, rotations, origin, truths, tracker,
                  timings, t_fusing, growing)


def run_layout(loaded: LoadedLayout, seed: int = 0, progress: ProgressCallback | None = None) -> RunResult:
    """Run a validated layout in-process (no files written): :func:`prepare_fusion`, then
    :func:`finish_fusion`."""
    return finish_fusion(prepare_fusion(loaded, seed, progress))


def finish_fusion(fusion: Fusion) -> RunResult:
    """Fuse to the end of the data (:meth:`~bodyfusion.core.fuser.Fuser.finish`), smooth, score
    against the truth and gather the health findings."""
    loaded, systems, aiding, constraints, truths = (fusion.loaded, fusion.systems, fusion.aiding, fusion.constraints,
                                                   fusion.truths)
    timings = fusion.timings
    report = fusion.fuser.finish()
    if fusion.growing:
        check_truth_overlap(truths, {name: (s.t_start, s.t_end) for name, s in systems.items()}, loaded.path,
                            fusion.truth_spans)
    for monitor in fusion.monitors.values():
        monitor.flush()
    if fusion.tracker is not None:
        fusion.tracker.finish()
    timings["navigation_s"] = time.perf_counter() - fusion.t_fusing
    log.debug("fused in %.2f s: %d constraint epoch(s), %d active", timings["navigation_s"], report.epochs,
              report.activations)

    smoothed: dict[str, dict] = {}
    if loaded.layout.smoother.kind != "none":
        t0 = time.perf_counter()
        log.info("smoothing (smoother.kind %s)", loaded.layout.smoother.kind)
        joint = fusion.fuser.joint
        smoothed = smooth_systems(systems, loaded.layout.smoother, joint.corrections if joint is not None else None)
        timings["smoothing_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    trajectories = {name: s.trajectory() for name, s in systems.items()}
    smoothed_constraints = None
    constrain = loaded.layout.smoother.constrain_smoothed
    if constrain is None:  # not where the smoother took the constraints in (joint)
        constrain = loaded.layout.fuser.method != "none" and not any("joint" in d for d in smoothed.values())
    if constrain and loaded.layout.constraints and smoothed:
        trajectories, smoothed_constraints = constrain_trajectories(trajectories, set(smoothed), constraints,
                                                                    loaded.layout.fuser)
    truth_cfg = loaded.layout.truth
    if truths:
        log.info("scoring %s against the truth (alignment %s)", ", ".join(truths), truth_cfg.alignment)
        transform, scores = score_systems(trajectories, truths, alignment=truth_cfg.alignment,
                                          loop=truth_cfg.loop, alignment_distance_m=truth_cfg.alignment_distance_m)
    else:
        transform, scores = PlanarTransform.identity(), {}
    nees = {name: horizontal_nees(trajectories[name], score, transform, truth_cfg.alignment)
            for name, score in scores.items()}
    alone = {name: sensor_alone_score(*fixes, truths[name]) for name in scores if truth_cfg.alignment == "none"
             and offers(systems[name], AbsoluteFixes) and (fixes := systems[name].absolute_fixes()) is not None}
    timings["scoring_s"] = time.perf_counter() - t0
    log.debug("stage times: %s", ", ".join(f"{k} {v:.3f}" for k, v in timings.items()))
    findings = [f for s in (*systems.values(), *aiding.values()) for f in s.findings()]
    if report.limits is not None:
        findings += report.limits.findings()
        findings += truth_separation_findings(constraints, report.constraint_log, truths)
    findings += sensor_alone_findings(scores, alone)
    spans = {name: (s.t_start, s.t_end) for name, s in systems.items()}
    spans.update({name: (float(t[0]), float(t[-1])) if len(t := s.measurement_times()) else (0.0, 0.0)
                  for name, s in aiding.items()})
    findings += nis_findings({name: s.health().get("nis", {}) for name, s in {**systems, **aiding}.items()}, spans)
    findings += nees_findings(nees)
    findings += large_error_findings(scores, findings)
    return RunResult(loaded, systems, trajectories, truths, transform, scores, report, fusion.rotations,
                     navigation_frame(loaded, systems, fusion.origin), timings, aiding, smoothed_constraints, nees,
                     sensor_alone=alone, findings=tuple(findings))


def run(config_path: str | Path, overrides: list[str] | None = None, out_dir: str | Path | None = None,
        seed: int = 0, progress: ProgressCallback | None = None,
        figure_process: FigureProcess | None = None, overwrite: bool = False) -> tuple[RunResult, Path]:
    """Load, run (``progress`` as :func:`run_layout` takes it), write outputs (the plots by
    ``figure_process`` when given one) and say the run's health findings on the log (stderr from
    the command line), one line each; returns the result and the output folder. A folder already
    holding outputs is refused before the run (:func:`~bodyfusion.outputs.write.check_output_folder`;
    ``overwrite``: replace them)."""
    # imported here: the writers bring Arrow (~30 MB resident), which a live run without files
    # never needs
    from bodyfusion.outputs.write import check_output_folder, write_outputs

    t0 = time.perf_counter()
    log.info("loading %s", config_path)
    loaded = load_layout(config_path, overrides)
    out = Path(out_dir) if out_dir is not None else (loaded.layout.output.dir or Path("out") / loaded.name)
    check_output_folder(out, overwrite)
    result = run_layout(loaded, seed, progress)
    answer_pending()  # interrupted where the exception was dropped (numba compiling): the earlier outputs stay
    write_outputs(result, out, str(config_path), total_wall_s=time.perf_counter() - t0, figure_process=figure_process)
    for finding in result.findings:  # on stderr, as in metrics.json
        LOG.log(logging.WARNING if finding.severity == "warning" else logging.INFO, "%s", finding.line())
    return result, out
