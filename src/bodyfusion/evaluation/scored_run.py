"""What the figures and the report draw: a run's trajectories, its truth, the evaluation
alignment, the scores and NEES it gives, in a frame with units (:class:`ScoredRun`).

A run's result (:class:`bodyfusion.results.run_result.RunResult`) is one; :class:`ScoredTracks`
is the same content and nothing else, small enough to hand to a figure process and read back
from a run folder (:func:`bodyfusion.evaluation.report_data.read_run_folder`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Protocol, runtime_checkable

from bodyfusion.base.types import NavigationFrame, Trajectory, TruthTrack
from bodyfusion.evaluation.consistency import NeesTrack
from bodyfusion.evaluation.metrics import PlanarTransform, SystemScore


@runtime_checkable
class ScoredRun(Protocol):
    """A run as the figures see it. ``trajectories``: system → track in ``frame`` (before the
    alignment); ``truths``: system → truth in its own frame; ``transform``: the evaluation
    alignment that maps estimates into the truth's frame; ``scores`` and ``nees``: system → its
    errors and horizontal NEES at the truth epochs (empty without truth)."""

    @property
    def trajectories(self) -> Mapping[str, Trajectory]: ...

    @property
    def truths(self) -> Mapping[str, TruthTrack]: ...

    @property
    def transform(self) -> PlanarTransform: ...

    @property
    def scores(self) -> Mapping[str, SystemScore]: ...

    @property
    def nees(self) -> Mapping[str, NeesTrack]: ...

    @property
    def frame(self) -> NavigationFrame: ...


def _read_only(mapping: Mapping | None) -> Mapping:
    return MappingProxyType(dict(mapping or {}))


@dataclass(frozen=True)
class ScoredTracks:
    """A :class:`ScoredRun` and nothing more: frozen, its mappings read-only, built from references
    (no array is copied). :meth:`of` takes the parts of any :class:`ScoredRun`."""

    trajectories: Mapping[str, Trajectory] = field(default_factory=dict)
    truths: Mapping[str, TruthTrack] = field(default_factory=dict)
    transform: PlanarTransform = field(default_factory=PlanarTransform.identity)
    scores: Mapping[str, SystemScore] = field(default_factory=dict)
    nees: Mapping[str, NeesTrack] = field(default_factory=dict)
    frame: NavigationFrame = field(default_factory=NavigationFrame)

    def __post_init__(self) -> None:
        for name in ("trajectories", "truths", "scores", "nees"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))

    @classmethod
    def of(cls, run: ScoredRun) -> ScoredTracks:
        """The figures' content of ``run`` (a :class:`~bodyfusion.results.run_result.RunResult`)."""
        return cls(run.trajectories, run.truths, run.transform, run.scores, run.nees, run.frame)

    def __reduce__(self):  # a mapping proxy does not pickle: hand the mappings over as dicts
        return (type(self), (*(dict(getattr(self, n)) for n in ("trajectories", "truths")), self.transform,
                             dict(self.scores), dict(self.nees), self.frame))
