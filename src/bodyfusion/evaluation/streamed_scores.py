"""Scores of the states a live run emits, made as they are emitted.

A live run that keeps a bounded history (``fusion live --keep``) finishes with the last part of
each track only, so its scores (:func:`~bodyfusion.evaluation.metrics.score_systems`) cover that
part. :class:`StreamedScores` is a sink beside the others
(:class:`~bodyfusion.core.epoch_state.EpochSink`) that scores every state as it passes, by the
batch scoring's rule applied to the states' track: the errors at the truth epochs, the estimate
interpolated linearly to them between two consecutive states (errors at truth epochs outside the
states' span are not made), after the evaluation alignment (``none``: identity; ``first_3m``: the
planar fit of :func:`~bodyfusion.evaluation.metrics.fit_first_distance_alignment`, on the states
of the alignment's first metres). It holds each system's errors as sketches
(:class:`~bodyfusion.evaluation.metrics.ErrorSketch`), the states not yet scored (a block of
:data:`BLOCK_STATES`) and those of the first metres, nothing of the track.

The interpolation between output epochs (0.1 s apart by default) is part of the figure: on a
foot accurate to centimetres it dominates (the simulated foot + UWB walk: 0.0235 m streamed
against 0.0118 m scored at every sample by the batch run), so the figure compares live streams
with each other, and the batch run's scores only with states at the sample period.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from bodyfusion.base.types import Trajectory
from bodyfusion.core.epoch_state import EpochState
from bodyfusion.evaluation.metrics import ErrorSketch, PlanarTransform, fit_first_distance_alignment
from bodyfusion.io.truth import TruthWindow

FIT_WAIT_STATES = 6000
"""States (10 min at the default 0.1 s) the alignment waits for its distance at most: then it is
fitted on those, as the batch fit takes a whole track that never travels that far."""


BLOCK_STATES = 512
"""States a track collects before it scores them together (51 s at the default 0.1 s): the
errors are those of one state at a time, made by array operations instead of a call each."""


class _Track:
    """One system's scoring: its truth (a window this track reads as ``reader``), the index of
    the next truth epoch, the last state scored, the states not yet scored and the horizontal
    and vertical errors so far."""

    def __init__(self, truth: TruthWindow, reader: str) -> None:
        self.truth, self.reader = truth, reader
        truth.place(reader, 0)  # until the first state: the alignment may fit on any of it
        self.next = 0
        self.last: tuple[float, np.ndarray] | None = None
        self._t: list[float] = []
        self._p: list[np.ndarray] = []
        self.horizontal, self.vertical = ErrorSketch(), ErrorSketch()
        self.span = [math.inf, -math.inf]
        self.travelled_m = 0.0

    def take(self, t: float, p: np.ndarray, transform: PlanarTransform) -> None:
        """The state (``t`` s, ``p`` ENU m), scored with the states after it
        (:data:`BLOCK_STATES`; :meth:`score` scores those taken)."""
        if self.last is None:
            self.next = self.truth.index(t, side="left")  # epochs before the first state: unscored
            self.truth.place(self.reader, self.next)
            self.last = (t, p)
            return
        self._t.append(t)
        self._p.append(p)
        if len(self._t) >= BLOCK_STATES:
            self.score(transform)

    def score(self, transform: PlanarTransform) -> None:
        """Errors at the truth epochs through the states taken: each epoch t_k between two
        consecutive states t_0 < t_k ≤ t_1 (a state not after the one before it is passed over)
        gets the estimate p_0 + (t_k − t_0)/(t_1 − t_0) (p_1 − p_0)."""
        if self.last is None or not self._t:
            return
        t0, p0 = self.last
        t = np.array([t0, *self._t])
        p = np.array([p0, *self._p])
        self._t, self._p = [], []
        later = np.concatenate(([True], t[1:] > np.maximum.accumulate(t)[:-1]))
        t, p = t[later], p[later]
        self.last = (float(t[-1]), p[-1])
        if t.size < 2:
            return
        stop = self.truth.index(t[-1], side="right")
        if stop <= self.next:
            return
        tk, pos = self.truth.epochs_between(self.next, stop)
        j = np.maximum(np.searchsorted(t, tk, side="left"), 1)  # t[j − 1] < t_k ≤ t[j] (t_k = t[0]: j = 1)
        before = p[j - 1]
        est = before + ((tk - t[j - 1]) / (t[j] - t[j - 1]))[:, None] * (p[j] - before)
        d = transform.apply(est) - pos
        self.horizontal.add(np.hypot(d[:, 0], d[:, 1]))
        self.vertical.add(d[:, 2])
        self.span = [min(self.span[0], float(tk[0])), max(self.span[1], float(tk[-1]))]
        self.next = stop
        self.truth.place(self.reader, stop)


class StreamedScores:
    """The sink (module docstring): the truth ``windows`` by system, the layout's truth
    ``alignment`` (``none`` or ``first_3m``) and ``alignment_distance_m``. :meth:`scores` gives
    the figures."""

    def __init__(self, windows: Mapping[str, TruthWindow], alignment: str, alignment_distance_m: float,
                 smoothed: bool = False) -> None:
        self.smoothed = smoothed
        """Score the smoothed states (:attr:`~bodyfusion.core.epoch_state.EpochState.smoothed_lag_s`), else the filtered."""
        reader = "smoothed scores" if smoothed else "scores"
        self.tracks = {name: _Track(window, reader) for name, window in windows.items()}
        self.distance_m = alignment_distance_m
        self.transform: PlanarTransform | None = PlanarTransform.identity() if alignment == "none" else None
        self._first: list[EpochState] = []
        """The states before the alignment is fitted."""

    def write(self, state: EpochState) -> None:
        if (state.smoothed_lag_s is not None) != self.smoothed:
            return
        if self.transform is None:
            self._first.append(state)
            for name, track in self.tracks.items():
                s = state.systems.get(name)
                if s is not None and len(self._first) > 1:
                    before = self._first[-2].systems[name].position_n
                    track.travelled_m += float(np.hypot(*(s.position_n - before)[:2]))
            if len(self._first) >= FIT_WAIT_STATES or all(t.travelled_m >= self.distance_m
                                                          for t in self.tracks.values()):
                self._fit()
            return
        for name, track in self.tracks.items():
            s = state.systems.get(name)
            if s is not None:
                track.take(s.t, np.asarray(s.position_n, dtype=float), self.transform)

    def _fit(self) -> None:
        """Fit the alignment on the states so far and score them."""
        estimates = {}
        for name in self.tracks:
            rows = [(e.systems[name].t, *e.systems[name].position_n) for e in self._first if name in e.systems]
            a = np.unique(np.asarray(rows, dtype=float).reshape(-1, 4), axis=0)
            estimates[name] = Trajectory(a[:, 0], a[:, 1:], np.zeros_like(a[:, 1:]))
        last = max((e.systems[name].t for e in self._first for name in e.systems if name in self.tracks),
                   default=-math.inf)
        for track in self.tracks.values():  # the truth through the states' span (nothing read is released yet)
            track.truth.read_through(last)
        truths = {name: track.truth.held() for name, track in self.tracks.items()}
        usable = {n: e for n, e in estimates.items() if len(e.t) > 1}
        self.transform = fit_first_distance_alignment(usable, truths, self.distance_m) if usable else \
            PlanarTransform.identity()
        first, self._first = self._first, []
        for state in first:
            self.write(state)

    def close(self) -> None:
        """Score the states taken; a run that ended before its systems travelled the alignment's
        distance is fitted on what it has first."""
        if self.transform is None and self._first:
            self._fit()
        if self.transform is not None:
            for track in self.tracks.values():
                track.score(self.transform)

    def scores(self) -> dict[str, dict]:
        """Per system: ``horizontal_error_m`` and, where the truth has heights, ``vertical_error_m``
        (:func:`~bodyfusion.evaluation.metrics.error_stats`' figures), ``scored_epochs``, ``t_start`` and
        ``t_end`` (s) of the truth epochs scored, ``epochs`` saying how they were made, and
        ``truth_error`` where the truth's reader refused a later part of its file (the scores end
        there: :class:`~bodyfusion.io.truth.TruthWindow`)."""
        self.close()
        out = {}
        for name, track in self.tracks.items():
            n = track.horizontal.count
            vertical = {"vertical_error_m": track.vertical.stats()} if track.vertical.count else {}
            ended = {"truth_error": str(track.truth.error)} if track.truth.error is not None else {}
            out[name] = {"horizontal_error_m": track.horizontal.stats(), **vertical, "scored_epochs": n,
                         "t_start": track.span[0] if n else None, "t_end": track.span[1] if n else None,
                         "epochs": "truth epochs; the emitted states interpolated linearly to them", **ended}
        return out
