"""What a report reads: a run folder (``fusion run``) or a study folder (``fusion study``), from
its files only (docs/contract.md), so any such folder can be reported on, anywhere.

A run folder holds ``metrics.json`` and ``trajectories.csv`` (ENU m in the navigation frame,
before the evaluation alignment; s). Its truth, where the folder holds one, is ``truth.csv``
(the long format of ``fusion simulate``) or ``tum/<system>_truth.txt`` (TUM: ``t x y z qx qy qz
qw``); the estimates are mapped into the truth's frame by the evaluation transform recorded in
``metrics.json`` and scored at the truth epochs as the run scored them. A study folder holds
``summary.csv`` and ``results.parquet`` (and ``study.json``).
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from bodyfusion.base.errors import FusionError, InputError
from bodyfusion.base.types import NavigationFrame, Trajectory, TruthTrack
from bodyfusion.evaluation.metrics import PlanarTransform, score_systems
from bodyfusion.evaluation.scored_run import ScoredTracks
from bodyfusion.io.trajectory_files import read_trajectories
from bodyfusion.io.truth import read_truth_long_csv



@dataclass(frozen=True)
class RunFolder:
    """A run folder's contents: ``metrics`` (metrics.json), the ``tracks`` it holds (the
    trajectories in the frame metrics.json records, the truths in their own frame, the recorded
    evaluation transform and the scores it gives; no NEES series) and where the truth came from
    (``truth_source``, None: no truth in the folder)."""

    folder: Path
    metrics: dict[str, Any]
    tracks: ScoredTracks
    truth_source: str | None = None


@dataclass
class StudyFolder:
    """A study folder's contents: ``summary`` (summary.csv rows, cells as text, empty: none),
    ``study`` (study.json, {} if absent) and the ``runs`` results.parquet holds (None: absent)."""

    folder: Path
    summary: list[dict[str, str]]
    study: dict[str, Any]
    runs: int | None


def _read_json(path: Path) -> dict[str, Any]:
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise InputError(path, f"not JSON: {err.msg}", line=err.lineno) from None
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror}") from None
    if not isinstance(doc, dict):
        raise InputError(path, "expected a JSON object")
    return doc


def read_tum_truth(path: Path, *, sparse: bool = False) -> TruthTrack:
    """A TUM file (``t x y z qx qy qz qw`` per line, s and m) as a truth track."""
    try:
        rows = np.loadtxt(path, ndmin=2, usecols=(0, 1, 2, 3))
    except (ValueError, OSError) as err:
        raise InputError(path, f"not a TUM trajectory (t x y z qx qy qz qw): {err}") from None
    return TruthTrack(rows[:, 0], rows[:, 1:4], sparse=sparse)


def _truths(folder: Path, metrics: dict[str, Any]) -> tuple[dict[str, TruthTrack], str | None]:
    """The folder's truth for the systems of ``metrics``: truth.csv, else tum/<system>_truth.txt.
    Truth scored by its surveyed points (``distance_source`` ``estimate``) is sparse."""
    systems = metrics.get("systems", {})
    sparse = {name for name, block in systems.items() if block.get("distance_source") == "estimate"}
    if (folder / "truth.csv").is_file():
        tracks = read_truth_long_csv(folder / "truth.csv")
        return {n: TruthTrack(tr.t, tr.pos_n, n in sparse) for n, tr in tracks.items() if n in systems}, "truth.csv"
    tum = {name: folder / "tum" / f"{name}_truth.txt" for name in systems}
    found = {name: read_tum_truth(path, sparse=name in sparse) for name, path in tum.items() if path.is_file()}
    return found, "tum/<system>_truth.txt" if found else None


def _transform(metrics: dict[str, Any]) -> PlanarTransform:
    tf = metrics.get("evaluation", {}).get("transform", {})
    return PlanarTransform(np.deg2rad(float(tf.get("rotation_deg") or 0.0)),
                           np.asarray(tf.get("translation_m") or [0.0, 0.0], dtype=float),
                           float(tf.get("vertical_offset_m") or 0.0))


def read_run_folder(folder: Path) -> RunFolder:
    """A run folder (module docstring); the estimates with truth scored as the run scored them."""
    metrics = _read_json(folder / "metrics.json")
    if not (folder / "trajectories.csv").is_file():
        raise FusionError(f"{folder}: no trajectories.csv beside metrics.json: not a complete run folder")
    trajectories = read_trajectories(folder / "trajectories.csv")
    truths, source = _truths(folder, metrics)
    transform = _transform(metrics)
    aligned = {n: Trajectory(tr.t, transform.apply(tr.pos_n), tr.pos_sd) for n, tr in trajectories.items()}
    scorable = {n: tr for n, tr in truths.items() if n in aligned and tr.t.size}
    try:
        _, scores = score_systems(aligned, scorable, alignment="none")
    except FusionError as err:  # a truth on another clock than the estimates
        raise FusionError(f"{folder}: {err}") from None
    frame = NavigationFrame.from_dict(metrics.get("frame"))
    tracks = ScoredTracks(trajectories, truths, transform, scores, frame=frame)
    return RunFolder(folder, metrics, tracks, source)


def read_study_folder(folder: Path) -> StudyFolder:
    """A study folder (module docstring)."""
    summary: list[dict[str, str]] = []
    if (folder / "summary.csv").is_file():
        with (folder / "summary.csv").open(newline="") as fh:
            summary = list(csv.DictReader(fh))
    study = _read_json(folder / "study.json") if (folder / "study.json").is_file() else {}
    runs = None
    if (folder / "results.parquet").is_file():
        import pyarrow.parquet as pq

        try:
            runs = pq.read_metadata(folder / "results.parquet").num_rows
        except (pa.ArrowInvalid, OSError) as err:
            raise InputError(folder / "results.parquet", f"not a Parquet file: {err}") from None
    return StudyFolder(folder, summary, study, runs)


def read_folder(folder: str | Path) -> RunFolder | StudyFolder:
    """A run folder (it holds metrics.json) or a study folder (summary.csv or results.parquet);
    anything else is a :class:`FusionError` naming the folder and what it lacks."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FusionError(f"{folder}: no such folder")
    if (folder / "metrics.json").is_file():
        return read_run_folder(folder)
    if (folder / "summary.csv").is_file() or (folder / "results.parquet").is_file():
        return read_study_folder(folder)
    raise FusionError(f"{folder}: not a run or study folder: no metrics.json (fusion run) "
                      "and no summary.csv or results.parquet (fusion study)")
