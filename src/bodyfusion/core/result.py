"""What a run produced: the systems with their histories, the trajectories, the truth and the
scores, the fuser's and the smoothers' reports (:class:`RunResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bodyfusion.core.fuser import FuserReport
from bodyfusion.core.layout import LoadedLayout
from bodyfusion.core.system import AidingSource, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory, TruthTrack
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore


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
    smoothed_constraints: dict | None = None
    """Counts of the constraints applied to the smoothed tracks (``smoother.constrain_smoothed``)."""

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
