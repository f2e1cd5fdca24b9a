"""What a run produced: the systems with their histories, the trajectories, the truth, the
scores and the consistency figures, the fuser's and the smoothers' reports (:class:`RunResult`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bodyfusion.core.fuser import FuserReport
from bodyfusion.core.layout import LoadedLayout
from bodyfusion.core.system import AidingSource, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory, TruthTrack
from bodyfusion.evaluation.consistency import CovarianceHealth, NeesTrack
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
    nees: dict[str, NeesTrack] = field(default_factory=dict)
    """Horizontal NEES against truth of every scored system (after the evaluation alignment)."""

    def health(self) -> dict[str, dict]:
        """metrics.json ``systems.<name>.health``: each system's own figures
        (:meth:`~bodyfusion.core.system.SensorSystem.health`), ``trajectory_covariance`` (the
        checks of the output trajectory's east–north covariance at every epoch, smoothed when
        smoothed) and, where truth exists, ``nees``."""
        out = {}
        for name, system in self.systems.items():
            traj = self.trajectories[name]
            out[name] = {**system.health(),
                         "trajectory_covariance": CovarianceHealth.of(traj.horizontal_covariance(), traj.t).to_dict(),
                         **({"nees": self.nees[name].summary()} if name in self.nees else {})}
        return out

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
