"""Writers of the run outputs named in docs/contract.md: metrics.json (with each system's
consistency ``health``), the trajectory files (:mod:`bodyfusion.outputs.trajectories`: trajectories.csv
and .parquet, tum/, track.geojson), plots (nees.png where truth exists)."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.base.files import sole_writer, staged_outputs
from bodyfusion.base.forking import Forked
from bodyfusion.base.interrupts import deferred
from bodyfusion.outputs.covariances import write_covariances_parquet
from bodyfusion.outputs.trajectories import (
    ROWS,
    write_geojson,
    write_strides_csv,
    write_trajectories_csv,
    write_trajectories_parquet,
    write_tum,
)
from bodyfusion.results.run_result import RunResult
from bodyfusion.evaluation.figure_process import FigureProcess
from bodyfusion.evaluation.metrics import loop_closure_m, outage_errors, path_length_m

log = logging.getLogger(__name__)


def _json_safe(value):
    """NaN and inf (e.g. the error statistics of a system with no finite error) become null:
    strict JSON has no NaN."""
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def _median_p99(values: np.ndarray) -> dict[str, float]:
    a = np.asarray(values, dtype=float)
    if a.size == 0:
        return {"median": 0.0, "p99": 0.0}
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99))}


def _outage_block(result: RunResult, name: str) -> dict[str, float]:
    """``outage_end_error_m`` / ``outage_max_error_m`` of a system with GNSS outages in the
    layout and dense truth: the largest over its outages of :func:`bodyfusion.evaluation.metrics.outage_errors`'
    end and maximum errors (m)."""
    truth = result.truths.get(name)
    windows = [(o.start_s, o.duration_s) for o in result.loaded.layout.outages if o.system == name]
    if truth is None or truth.sparse or not windows:
        return {}
    errs = [outage_errors(result.trajectories[name], truth, result.transform, s, d) for s, d in windows]
    return {"outage_end_error_m": float(np.max([e["end_error_m"] for e in errs])),
            "outage_max_error_m": float(np.max([e["max_error_m"] for e in errs]))}


def metrics_document(result: RunResult, config_label: str, total_wall_s: float) -> dict:
    """The metrics.json document (docs/contract.md), plus per-system diagnostics."""
    layout = result.loaded.layout
    loop = layout.truth is not None and layout.truth.loop
    systems: dict[str, dict] = {}
    health = result.health()
    for name, system in result.systems.items():
        traj = result.trajectories[name]
        block: dict = {"samples": system.samples}
        score = result.scores.get(name)
        if score is not None:
            block.update(score.metrics)
        else:
            block["distance_m"] = path_length_m(traj.pos_n)
        if loop and "loop_closure_m" not in block:
            block["loop_closure_m"] = loop_closure_m(traj)
        block.update(_outage_block(result, name))
        if name in result.sensor_alone:
            alone = result.sensor_alone[name]
            p75 = alone["horizontal_error_m"]["p75"]
            block["sensor_alone"] = {**alone, "fused_over_alone_p75": block["horizontal_error_m"]["p75"] / p75
                                     if p75 > 0 else None}
        if name in result.whole_run:
            block["whole_run"] = result.whole_run[name]
        if name in result.whole_run_smoothed:
            block["whole_run_smoothed"] = result.whole_run_smoothed[name]
        block["diagnostics"] = system.diagnostics()
        block["health"] = health[name]
        systems[name] = block
    t = result.transform
    doc: dict = {
        "config": config_label,
        "config_sha256": result.loaded.sha256,
        "alignment": layout.truth.alignment if result.scores else "none",
        "evaluation": {
            "error_epochs": "truth epochs; estimate interpolated linearly to them",
            "transform": {"rotation_deg": float(np.rad2deg(t.rotation_rad)),
                          "translation_m": [float(v) for v in t.translation_m],
                          "vertical_offset_m": float(t.vertical_offset_m)},
        },
        "frame": result.frame.to_dict(),
        "heading_alignment_deg": {k: float(np.rad2deg(v)) for k, v in result.heading_rotations_rad.items()},
        "heading_ties": {tie.system: tie.summary() for tie in result.fuser.heading_ties},
        "health": {"findings": [f.to_dict() for f in result.findings]},
        "systems": systems,
    }
    if result.live_smoothing is not None:
        doc["live_smoothing"] = result.live_smoothing
    if layout.constraints:
        rep = result.fuser
        lam = np.asarray(rep.multipliers)
        doc["constraints"] = {
            "method": rep.method, "epochs": rep.epochs, "activations": rep.activations,
            "tail_truncations": rep.tail_truncations,
            "solver_fallbacks": rep.solver_fallbacks, "not_converged": rep.not_converged,
            "max_violation_before_m": rep.max_violation_before_m,
            "max_violation_after_m": rep.max_violation_after_m,
            "multipliers": {"mean": float(lam.mean()) if lam.size else 0.0,
                            "max": float(lam.max()) if lam.size else 0.0},
            "solve_time_us": _median_p99(rep.solve_times_us),
            **({"limits": rep.limits.summary()} if rep.limits is not None else {}),
        }
    if result.smoothed_constraints is not None:
        doc.setdefault("constraints", {})["smoothed"] = result.smoothed_constraints
    if result.aiding:  # aiding sources (UWB tags): no trajectory, their diagnostics
        doc["aiding"] = {name: {"samples": src.samples, **src.diagnostics(), "health": src.health()}
                         for name, src in result.aiding.items()}
    inp = result.input_report
    doc["input"] = {"dropped_samples": inp.dropped_samples, "reordered_samples": inp.reordered_samples,
                    "notes": inp.notes, "warnings": inp.warnings}
    samples = result.samples
    nav_s = result.timings_s["navigation_s"]
    doc["runtime"] = {"wall_s": total_wall_s, "samples": samples,
                      "samples_per_s": samples / nav_s if nav_s > 0 else 0.0,
                      **{k: v for k, v in result.timings_s.items()}}
    return doc


def _write_tracks(result: RunResult, out_dir: Path) -> None:
    """The TUM files (a folder) and, for a geo-referenced run, track.geojson."""
    decimate = result.loaded.layout.output.decimate
    write_tum(out_dir / "tum", result.trajectories, result.truths, decimate)
    if result.frame.geodetic_origin is not None:
        write_geojson(out_dir / "track.geojson", result.trajectories, result.truths, result.frame.geodetic_origin,
                      decimate)


OUTPUT_NAMES = ("metrics.json", "trajectories.csv", "trajectories.parquet", "covariances.parquet", "strides.csv",
                "tum", "track.geojson")
"""The data files and folders a run writes (docs/contract.md) beside its plots."""
PLOT_STEMS = ("trajectory", "error_vs_time", "error_cdf", "nees")
"""The plots' file names without their format's suffix (:mod:`bodyfusion.evaluation.plots`)."""


def output_name(name: str) -> bool:
    """Whether ``name`` is a file or folder a run writes (:data:`OUTPUT_NAMES`, the plots)."""
    stem, _, suffix = name.rpartition(".")
    return name in OUTPUT_NAMES or (stem in PLOT_STEMS and suffix in ("png", "pdf", "svg"))


def earlier_run(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds an earlier run's outputs: a metrics.json of this project's
    (strict JSON with its ``config_sha256`` and ``runtime``)."""
    try:
        doc = json.loads((out_dir / "metrics.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and "config_sha256" in doc and "runtime" in doc


def check_output_folder(out_dir: Path, overwrite: bool = False) -> bool:
    """Before a run: refuse (FusionError naming the folder and the files) a ``--out`` holding any
    file or folder a run writes (:func:`output_name`: an earlier run's outputs, or files of those
    names of the user's own), unless ``overwrite``: nothing is replaced that the user did not ask
    to replace. Other files there are never touched. Returns whether an earlier run's outputs
    are there (replaced, with ``overwrite``). A ``--out`` that cannot be a folder this process
    writes in (a file, under a file, a dangling link, a folder it may not write) is refused as
    well, before the run rather than after it."""
    if not out_dir.is_dir():
        _check_creatable(out_dir)
        return False
    if not os.access(out_dir, os.W_OK | os.X_OK):
        raise FusionError(f"{out_dir}: cannot write the outputs: the folder is not writable")
    taken = [p.name for p in sorted(out_dir.iterdir()) if output_name(p.name)]
    earlier = earlier_run(out_dir)
    if taken and not overwrite:
        held = "an earlier run's outputs" if earlier else "files no earlier run wrote"
        raise FusionError(f"{out_dir}: holds {held} ({', '.join(taken)}), which a run would replace; give another "
                          "--out, or --overwrite to replace them")
    return earlier


def _check_creatable(out_dir: Path) -> None:
    """Refuse (FusionError naming it) an output folder path that is not a folder and cannot be
    made one: a file or device there, a dangling link, a file or an unwritable folder above it."""
    if out_dir.is_symlink() or out_dir.exists():
        what = "a link to the missing " + os.readlink(out_dir) if not out_dir.exists() else "not a folder"
        raise FusionError(f"{out_dir}: cannot create output folder: it is {what}")
    parent = out_dir.absolute().parent
    while not parent.exists() and not parent.is_symlink():
        parent = parent.parent
    if not parent.is_dir():
        raise FusionError(f"{out_dir}: cannot create output folder: {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise FusionError(f"{out_dir}: cannot create output folder: {parent} is not writable")


def write_outputs(result: RunResult, out_dir: Path, config_label: str, total_wall_s: float,
                  figure_process: FigureProcess | None = None) -> None:
    """metrics.json, the trajectory files and (unless switched off) the PNG plots. With more
    than :data:`~bodyfusion.outputs.trajectories.ROWS` rows of tracks, the TUM files and track.geojson
    are written in a forked process (:class:`~bodyfusion.base.forking.Forked`) while this one
    writes the rest; the plots by ``figure_process`` when given one. Every file is written into a
    staging folder inside ``out_dir`` and, once all are written, put in place of the previous ones
    (:func:`~bodyfusion.base.files.staged_outputs`, metrics.json last), one run at a time
    (:func:`~bodyfusion.base.files.sole_writer`); a write that fails part-way (a full disk, a
    read-only folder) is a :class:`FusionError` naming the folder, every previous file kept. A
    SIGINT or SIGTERM taken while writing is answered once every file is in place
    (:func:`~bodyfusion.base.interrupts.deferred`): the folder holds one run's files, never some of
    each."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise FusionError(f"{out_dir}: cannot create output folder: {err.strerror}") from None
    try:
        log.info("writing the outputs to %s", out_dir)
        with deferred(), sole_writer(out_dir), staged_outputs(out_dir, last=("metrics.json",), owned=output_name) as staging:
            _write_all(result, staging, config_label, total_wall_s, figure_process)
    except OSError as err:
        raise FusionError(f"{out_dir}: cannot write the outputs: {err.strerror or err} (the files of an earlier run "
                          "there are kept whole)") from None


def _write_all(result: RunResult, staging: Path, config_label: str, total_wall_s: float,
               figure_process: FigureProcess | None) -> None:
    """Every output of ``result`` into the folder ``staging`` (:func:`write_outputs`)."""
    output = result.loaded.layout.output
    if output.plots and figure_process is not None:
        log.info("plotting beside the other outputs")
        figure_process.submit(staging, result, output.figures)
    long = sum(len(track.t) for track in result.trajectories.values()) // output.decimate > ROWS  # worth a fork
    beside = Forked(lambda: _write_tracks(result, staging), fork=long)  # at the same time as the two tables
    write_trajectories_csv(staging / "trajectories.csv", result.trajectories, output.decimate)
    write_strides_csv(staging / "strides.csv", result.systems)
    write_trajectories_parquet(staging / "trajectories.parquet", result.trajectories, decimate=output.decimate,
                               config_sha256=result.loaded.sha256, frame=result.frame)
    write_covariances_parquet(staging / "covariances.parquet", result.systems, decimate=output.decimate)
    doc = metrics_document(result, config_label, total_wall_s)
    (staging / "metrics.json").write_text(json.dumps(_json_safe(doc), indent=2, allow_nan=False) + "\n")
    beside.result()
    if output.plots and figure_process is not None:
        figure_process.written()
    elif output.plots:
        from bodyfusion.evaluation import plots  # matplotlib loads only when plots are asked for

        log.info("plotting")
        plots.write_run_plots(staging, result, output.figures)
