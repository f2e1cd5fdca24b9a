"""A run's progress: the seconds of data the fuser has carried its systems through, on average."""

from __future__ import annotations

from collections.abc import Mapping

from bodyfusion.base.progress import ProgressCallback, Throttled
from bodyfusion.core.system import SensorSystem


class FusionProgress:
    """Reports the mean over the systems of t_now − t_start out of the mean of t_end − t_start (s of
    data) to ``callback`` (at most every :data:`~bodyfusion.base.progress.REFRESH_S`) each time the fuser
    advances one of the systems :meth:`track` wrapped; :meth:`finish` reports the end."""

    def __init__(self, systems: Mapping[str, SensorSystem], callback: ProgressCallback) -> None:
        self.systems = list(systems.values())
        self._spans = [(float(s.t_start), max(0.0, float(s.t_end - s.t_start))) for s in self.systems]
        self.total = sum(span for _, span in self._spans) / max(1, len(self._spans))
        self.callback = Throttled(callback)

    def track(self, system: SensorSystem) -> SensorSystem:
        """``system`` as the fuser sees it, reporting after each advance."""
        return _Tracked(system, self)  # type: ignore[return-value]

    def update(self) -> None:
        done = sum(min(max(s.t_now - t0, 0.0), span) for s, (t0, span) in zip(self.systems, self._spans))
        self.callback(min(done / len(self._spans), self.total), self.total)

    def finish(self) -> None:
        self.callback(self.total, self.total)


class _Tracked:
    """Every attribute is the system's own; ``advance`` also reports the progress."""

    def __init__(self, system: SensorSystem, progress: FusionProgress) -> None:
        self.monitored = system
        self._progress = progress

    def __getattr__(self, name: str):
        return getattr(self.monitored, name)

    def advance(self, t: float) -> None:
        self.monitored.advance(t)
        self._progress.update()
