"""The fuser's clock: which events happen when, found as the systems' data are decided.

The fuser acts at events: a sync epoch of the constrained systems (a constraint solve), a
measurement of an aiding source, a heading tie's epoch, and, for a live run, an output epoch
(a state emitted). A batch run knows every event before it starts; a live run knows them up to
a horizon: the time up to which every system's samples and sync events are final
(:meth:`~bodyfusion.core.system.SensorSystem.decided_until`). :class:`EventSchedule` gives the
events in (h₀, h], for successive horizons h₀ < h, so that the union over any sequence of
horizons is the batch run's set of events and each slice is in the batch run's order
(time, then kind: measurements, heading ties, constraints, outputs). A batch run is the
one slice (−∞, ∞]. An aiding source whose measurements are taken as they come (a live UWB tag)
may gain measurements at or before a horizon already passed: they are not given, and the
source is told (:meth:`~bodyfusion.core.system.AidingSource.record_late`).

Epoch times follow ``fuser.epochs`` (:func:`epoch_times`): ``events`` — every sync time of the
systems; ``interval`` — every ``interval_s`` from the latest start; ``sample`` — every sample.
Within the span all of them cover (after the latest start, up to the earliest end).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from bodyfusion.core.layout import FuserConfig
from bodyfusion.core.system import AidingSource, SensorSystem

MEASUREMENT, TIE, CONSTRAINT, OUTPUT = 0, 1, 2, 3
"""Event kinds, in the order the fuser takes events of one time."""

Event = tuple[float, int, int, int]
"""(t s, kind, source index, measurement index): what happens at t."""


def epoch_times(systems: Sequence[SensorSystem], config: FuserConfig, after: float = -math.inf,
                until: float = math.inf) -> np.ndarray:
    """Sync epochs (s) inside the span all ``systems`` cover (``fuser.epochs``: module docstring),
    those in (``after``, ``until``] only. ``interval`` epochs are t₀ + Δ + kΔ as
    ``np.arange(t₀ + Δ, t₁, Δ)`` makes them, whichever slice asks."""
    t0 = max(s.t_start for s in systems)
    t1 = min(s.t_end for s in systems)
    if config.epochs == "interval":
        step = config.interval_s
        start = t0 + step
        delta = (start + step) - start  # the step np.arange takes: its k-th element is start + k·delta
        stop = min(t1, until)
        first = 0 if not math.isfinite(after) else max(0, int(math.floor((after - start) / delta)))
        last = max(first, int(math.ceil((stop - start) / delta)) + 1)
        times = start + np.arange(first, last) * delta
        times = times[times < t1]
    else:
        parts = [s.sync_times() if config.epochs == "events" else s.sample_times() for s in systems]
        times = np.unique(np.concatenate([p[(p > after) & (p <= until)] for p in parts]))
    return times[(times > t0) & (times <= t1) & (times > after) & (times <= until)]


class EventSchedule:
    """The events of a fuser's run, slice by slice of its horizon (module docstring).

    ``constrained``: the systems whose sync epochs carry the constraints (empty: none);
    ``sources``: the aiding sources, by index; ``tied``: the systems whose sync epochs carry
    the heading ties (empty: none); ``config``: the layout's ``fuser``; ``navigating``: every
    navigation system; ``output_interval_s``: the spacing of output epochs, at multiples of it
    within the span of the navigation systems' data (None: none); ``on_sync``: told
    (system, its new sync times) as each slice decides them, for those who follow a system's
    gait (the limits)."""

    def __init__(self, constrained: Sequence[SensorSystem], sources: Sequence[AidingSource],
                 tied: Sequence[SensorSystem], config: FuserConfig, navigating: Sequence[SensorSystem] = (),
                 output_interval_s: float | None = None,
                 on_sync: Callable[[int, np.ndarray], None] | None = None) -> None:
        self.constrained = list(constrained)
        self.navigating = list(navigating)
        self.sources = list(sources)
        self.tied = list(tied)
        self.config = config
        self.output_interval_s = output_interval_s
        self.on_sync = on_sync
        self.horizon = -math.inf
        """Every event at or before this time (s) has been given."""
        self._next_measurement = [0] * len(self.sources)
        """Per source, the run's number of its next measurement to give (its first held is its
        :attr:`~bodyfusion.core.system.AidingSource.measurements_forgotten`)."""
        self._events_config = FuserConfig(epochs="events")

    def until(self, horizon: float) -> list[Event]:
        """The events in (previous horizon, ``horizon``], sorted; ``horizon`` becomes the
        schedule's."""
        after = self.horizon
        if horizon <= after:
            return []
        events: list[Event] = []
        if self.constrained:
            if self.on_sync is not None:
                for i, s in enumerate(self.constrained):
                    times = s.sync_times()
                    self.on_sync(i, times[(times > after) & (times <= horizon)])
            events += [(float(t), CONSTRAINT, 0, 0) for t in epoch_times(self.constrained, self.config, after, horizon)]
        for i, src in enumerate(self.sources):
            times = src.measurement_times()
            forgotten = src.measurements_forgotten  # measurement k held is the run's k + forgotten
            k0 = self._next_measurement[i] - forgotten
            late = int(np.searchsorted(times, after, side="right"))  # at or before the last horizon, not given:
            for k in range(k0, late):  # a live source's rows that arrived after the fuser passed their time
                src.record_late(k)
            k0 = max(k0, late)
            k1 = int(np.searchsorted(times, horizon, side="right"))
            events += [(float(times[k]), MEASUREMENT, i, k) for k in range(k0, k1)]
            self._next_measurement[i] = forgotten + max(k0, k1)
        if self.tied:
            events += [(float(t), TIE, 0, 0) for t in epoch_times(self.tied, self._events_config, after, horizon)]
        if self.output_interval_s is not None and self.navigating:
            events += [(float(t), OUTPUT, 0, 0) for t in self._output_times(after, horizon)]
        self.horizon = horizon
        return sorted(events)

    def _output_times(self, after: float, until: float) -> np.ndarray:
        """Output epochs k·Δ (s) in (after, until] within the span of the navigation systems' data."""
        step = self.output_interval_s
        lo = max(after, max(s.t_start for s in self.navigating))
        hi = min(until, min(s.t_end for s in self.navigating))
        if not hi > lo:
            return np.empty(0)
        k0, k1 = int(math.floor(lo / step)), int(math.floor(hi / step)) + 1  # a step to spare each side
        times = np.round(np.arange(k0, k1 + 1) * step, 9)  # 0.6, not 0.6000000000000001
        return times[(times > lo) & (times <= hi)]  # by the rounded times: every slicing gives each once
