"""What a run produced: the systems with their histories, the trajectories in their frame, the
truth, the scores and the consistency figures, the fuser's and the smoothers' reports, the
findings (:class:`RunResult`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np

from bodyfusion.core.fuser import FuserReport
from bodyfusion.core.layout import LoadedLayout
from bodyfusion.core.system import AidingSource, CovarianceHistory, SensorSystem
from bodyfusion.base.findings import Finding
from bodyfusion.base.types import InputReport, NavigationFrame, Trajectory, TruthTrack
from bodyfusion.evaluation.consistency import NeesTrack
from bodyfusion.nav.filter_health import CovarianceHealth
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore

if TYPE_CHECKING:  # pandas loads when a table is asked for, xarray when a dataset is
    import pandas as pd
    import xarray as xr


_MAPPINGS = ("systems", "trajectories", "truths", "scores", "heading_rotations_rad", "timings_s", "aiding", "nees",
             "sensor_alone", "whole_run", "whole_run_smoothed")


@dataclass(frozen=True)
class RunResult:
    """Everything a run produced: systems (with their histories), trajectories in ``frame``
    (units: :data:`~bodyfusion.base.types.NavigationFrame.UNITS`), scores, findings; its tables
    as pandas DataFrames (:meth:`to_frame`, :meth:`states`, :meth:`covariances`, :meth:`events`,
    :meth:`innovations`, :meth:`constraint_events`, :meth:`errors`, :meth:`truth_frame`), each
    with the frame and units in its ``attrs``, and a system's as an xarray Dataset
    (:meth:`to_xarray`).

    Frozen: its attributes cannot be set and its mappings are read-only views. Building one
    copies nothing: it holds what the run made. It is a
    :class:`~bodyfusion.evaluation.scored_run.ScoredRun`: the figures
    (:mod:`bodyfusion.evaluation.plots`) take it as it is."""

    loaded: LoadedLayout
    systems: Mapping[str, SensorSystem]
    trajectories: Mapping[str, Trajectory]
    truths: Mapping[str, TruthTrack]
    transform: PlanarTransform
    scores: Mapping[str, SystemScore]
    fuser: FuserReport
    heading_rotations_rad: Mapping[str, float]
    frame: NavigationFrame
    """The navigation frame of ``trajectories``: ENU m, its geodetic origin where known, its heading reference."""
    timings_s: Mapping[str, float]
    aiding: Mapping[str, AidingSource] = field(default_factory=dict)
    """Aiding sources (UWB tags...): no trajectory; diagnostics in metrics.json ``aiding``."""
    smoothed_constraints: dict | None = None
    """Counts of the constraints applied to the smoothed tracks (``smoother.constrain_smoothed``)."""
    nees: Mapping[str, NeesTrack] = field(default_factory=dict)
    """Horizontal NEES against truth of every scored system (after the evaluation alignment)."""
    sensor_alone: Mapping[str, dict] = field(default_factory=dict)
    """Per system with an absolute sensor (a phone's GNSS) and geo-referenced truth: the errors
    of that sensor used alone (:func:`bodyfusion.evaluation.metrics.sensor_alone_score`)."""
    whole_run: Mapping[str, dict] = field(default_factory=dict)
    """A live run that kept a bounded history: per system with truth, the errors of every state it
    emitted (:class:`~bodyfusion.evaluation.streamed_scores.StreamedScores`), where ``scores``
    cover the part kept."""
    whole_run_smoothed: Mapping[str, dict] = field(default_factory=dict)
    """A live run with ``smoother.kind: fixed-lag``: per system in its smoothed stream with truth,
    the errors of every smoothed state it emitted (as ``whole_run``)."""
    live_smoothing: dict | None = None
    """A live run with ``smoother.kind: fixed-lag``: its smoothed stream's ``epochs``, each system's
    live smoother's diagnostics (``systems``) and the systems ``not_smoothed`` with why
    (:mod:`bodyfusion.live.smoothed`)."""
    findings: tuple[Finding, ...] = ()
    """Health findings of the run (:class:`~bodyfusion.base.findings.Finding`): the systems', the
    fuser's and the evaluation's, in that order."""

    def __post_init__(self) -> None:
        for name in _MAPPINGS:  # read-only views of the run's own dicts: nothing copied
            object.__setattr__(self, name, MappingProxyType(getattr(self, name)))
        object.__setattr__(self, "findings", tuple(self.findings))

    def health(self) -> dict[str, dict]:
        """metrics.json ``systems.<name>.health``: each system's own figures
        (:meth:`~bodyfusion.core.system.SensorSystem.health`), ``trajectory_covariance`` (the
        checks of the output trajectory's east–north covariance at every epoch, smoothed when
        smoothed), where truth exists, ``nees``, and ``findings``: the run's findings about
        this system."""
        out = {}
        for name, system in self.systems.items():
            traj = self.trajectories[name]
            out[name] = {**system.health(),
                         "trajectory_covariance": CovarianceHealth.of(traj.horizontal_covariance(), traj.t).to_dict(),
                         **({"nees": self.nees[name].summary()} if name in self.nees else {}),
                         "findings": [f.to_dict() for f in self.findings if f.system == name]}
        return out

    @property
    def samples(self) -> int:
        """Input samples of every system and aiding source together."""
        return int(np.sum([s.samples for s in (*self.systems.values(), *self.aiding.values())]))

    # --- tables ------------------------------------------------------------------------

    @staticmethod
    def _in_frame(table: pd.DataFrame, frame: dict | str) -> pd.DataFrame:
        """``table`` with ``attrs`` ``frame`` (its positions' frame) and ``units`` (of each quantity)."""
        table.attrs.update(frame=frame, units=dict(NavigationFrame.UNITS))
        return table

    # Each returns a pandas DataFrame (results/frames.py, imported when a table is asked
    # for: a run from the command line needs none, and pandas takes a while to load).

    def system(self, name: str) -> SensorSystem:
        """The navigation system ``name`` (KeyError naming the systems there are)."""
        if name not in self.systems:
            raise KeyError(f"no system {name!r} in this run (have {sorted(self.systems)})")
        return self.systems[name]

    def to_frame(self) -> pd.DataFrame:
        """Trajectories in long form: ``system``, ``t`` (s), ``east_m``, ``north_m``, ``up_m`` (ENU,
        navigation frame, as trajectories.csv), ``sd_east_m``, ``sd_north_m``, ``sd_up_m``,
        ``cov_east_north_m2``, and where the system estimates them ``v_east_mps``,
        ``v_north_mps``, ``v_up_mps``, ``heading_deg``, ``pitch_deg``, ``roll_deg``
        (:func:`bodyfusion.results.frames.trajectories`)."""
        from bodyfusion.results import frames

        return self._in_frame(frames.trajectories(self.trajectories, self.systems), self.frame.to_dict())

    def truth_frame(self) -> pd.DataFrame:
        """The truth tracks in long form: ``system``, ``t`` (s), ``east_m``, ``north_m``, ``up_m``."""
        from bodyfusion.results import frames

        return frames.truth(self.truths)

    def errors(self) -> pd.DataFrame:
        """Errors against truth at the truth epochs, after the evaluation alignment
        (:func:`bodyfusion.results.frames.errors`)."""
        from bodyfusion.results import frames

        return self._in_frame(frames.errors(self.scores), "the truth's, the estimates after the evaluation alignment")

    def states(self, name: str) -> pd.DataFrame:
        """System ``name``'s estimated states over time, in the column names every plugin shares
        (:meth:`bodyfusion.core.system.SensorSystem.states`): the foot INS every sample's
        position, velocity, attitude and biases; the hand PDR at each step and update its
        position, walking heading, gyro bias, GNSS bias, step scale (and holding offset); the
        random walk its position."""
        import pandas as pd

        return self._in_frame(pd.DataFrame(self.system(name).states()), self.frame.to_dict())

    def covariances(self, name: str) -> CovarianceHistory:
        """System ``name``'s covariance over time as it stores it
        (:class:`~bodyfusion.core.system.CovarianceHistory`: ``t``, ``states``, ``matrix`` (N, k, k),
        NaN where not stored; ``to_frame()`` for columns): the foot INS the position block
        (variances and the east–north covariance) of every sample; the hand PDR its whole
        error-state covariance at each step and update; the random walk its whole (position)
        covariance at every sample."""
        return self.system(name).covariance_history()

    def to_xarray(self, name: str) -> xr.Dataset:
        """System ``name``'s trajectory, covariance history and errors against truth as one
        :class:`xarray.Dataset` with the states' names and every unit in its attributes
        (:func:`bodyfusion.results.arrays.system_dataset`; the optional dependency xarray:
        ``pip install "bodyfusion[xarray]"``)."""
        from bodyfusion.results.arrays import system_dataset

        return system_dataset(name, self.system(name), self.trajectories[name], self.scores.get(name),
                              self.frame.to_dict())

    def events(self) -> pd.DataFrame:
        """Gait events of every system: ``system``, ``event`` (``stance``: the foot INS's
        detected stance phases; ``step``: the hand PDR's steps), ``t``, ``t_end``, ``duration_s``
        and, for steps, ``length_m``."""
        from bodyfusion.results import frames

        return frames.events(self.systems)

    def strides(self) -> pd.DataFrame:
        """Every foot system's strides (strides.csv): ``system``, ``stride``, ``t_start``,
        ``t_end`` (s), ``length_m``, ``duration_s``, ``speed_mps``, ``climb_m``, ``clearance_m``,
        ``motion`` (:mod:`bodyfusion.plugins.foot_ins.strides` for the foot INS)."""
        from bodyfusion.results import frames

        return frames.strides(self.systems)

    def innovations(self) -> pd.DataFrame:
        """Every recorded update: ``system``, ``t``, ``aiding`` (``zupt``, ``position_fix``,
        ``gnss_position``, ``gnss_course``, ``magnetometer``, ``anchor_range``, ``peer_range``),
        ``nis`` (before any gate), ``dof``, ``accepted`` and a range's ``end``."""
        from bodyfusion.results import frames

        return frames.innovations({**self.systems, **self.aiding})

    def constraint_events(self) -> pd.DataFrame:
        """Every constraint at every sync epoch: ``t``, ``pair``, ``system_a``, ``system_b``,
        ``kind``, ``limit_m``, ``distance_before_m``, ``distance_after_m``, ``multiplier``,
        ``active`` (empty without constraints or with ``fuser.method: none``)."""
        from bodyfusion.results import frames

        return frames.constraint_events(self.fuser.constraint_log)

    @property
    def input_report(self) -> InputReport:
        report = InputReport()
        for s in (*self.systems.values(), *self.aiding.values()):
            report = report.merge(s.input_report)
        return report
