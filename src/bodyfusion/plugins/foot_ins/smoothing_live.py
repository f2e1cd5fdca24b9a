"""The fixed-lag smoother of a live foot INS (``smoother.kind: fixed-lag`` in a live run).

The batch fixed-lag smoother (:mod:`bodyfusion.plugins.foot_ins.smoothing`) smooths each segment
(stance midpoint to stance midpoint) by the RTS of the window from its start to the first segment
bound at least ``lag_s`` after its end (:func:`~bodyfusion.plugins.foot_ins.smoothing.lag_windows`),
swept back from zero adjoints there. Every such window needs only the data up to its end, so a live
run can emit it then: :meth:`LiveFixedLag.advance`, after each pass of the fuser, finds the bounds
the final part of the record fixes (the midpoints of the stance runs that ended, long gaps cut as
the batch run cuts them), and for every segment whose window those bounds close it replays the
filter over the window from the filter's covariance at the segment's start
(:func:`~bodyfusion.plugins.foot_ins.smoothing.window_rts`), sweeps it back, and hands on the
segment's smoothed samples; the filter's covariance at the segment's end, from the same replay,
starts the next. The record read is the filter's own
(:meth:`~bodyfusion.plugins.foot_ins.system.FootIns.smoothing_record` from the segment's start
on), so that a pass costs the windows it closes, not the run so far.

A sample's smoothed state leaves about ``lag_s`` plus the rest of its segment and of the window's
last segment after it: a stride or two beyond the lag at walking pace (the achieved delays are
in :attr:`LiveFixedLag.delay_s`). The last sample of the filter's record is not final (the fuser
may correct it again at the next pass), nor is a stance run that has not ended (its midpoint may
move): neither is used before the close, where :meth:`LiveFixedLag.advance` with ``final`` takes
the record to its end as the batch run's last bound.

The smoothed samples are the batch fixed-lag smoother's, as far as the filter's record is
(the live filter's is the batch run's bit for bit on a layout of feet; ``tests/live``).
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np

from bodyfusion.core.epoch_state import SmoothedSamples
from bodyfusion.core.layout import SmootherConfig
from bodyfusion.plugins.foot_ins.records import SmoothedOutput
from bodyfusion.plugins.foot_ins.smoothing import (sweep_store, cut_long_segments, max_segment_samples,
                                                   stance_midpoints, window_rts)
from bodyfusion.plugins.foot_ins.smoothing_record import BlockBuffers, RunRecord

LATENCIES_KEPT = 1 << 14
"""Windows whose compute time a live smoother keeps (the last ones)."""


def _record_up_to(rec: dict, last: int, P0: np.ndarray) -> RunRecord:
    """The record ``rec`` (:meth:`~bodyfusion.plugins.foot_ins.system.FootIns.smoothing_record`) up
    to its sample ``last``, its covariance at its first sample ``P0``, replayed (no forward record)."""
    rec = dict(rec, P0=P0, forward_record=None)
    for key in ("t", "acc", "gyro", "stance", "hist_x"):
        rec[key] = rec[key][:last + 1]
    for idx, rows in (("override_idx", "override_P"), ("kept_idx", "kept_x"), ("gap_idx", "gap_dP")):
        within = rec[idx] <= last
        rec[idx], rec[rows] = rec[idx][within], rec[rows][within]
    return RunRecord(rec)


class LiveFixedLag:
    """``system``'s fixed-lag smoother as its live run goes (module docstring); ``cfg``: the
    layout's ``smoother`` (``lag_s``, ``min_stance_s``, ``max_segment_s``). Results: ``windows``
    smoothed, ``gain_failures``, ``latency_ms`` (compute time of each pass that closed windows,
    ms), ``delay_s`` (for every window: the data (s) from its segment's last sample to the end of
    the record it waited for)."""

    def __init__(self, system, cfg: SmootherConfig) -> None:
        self.system, self.cfg = system, cfg
        self.start = 0
        """The held sample where the next segment starts (the filter's covariance there: :attr:`P_start`)."""
        self.P_start = np.array(system.smoothing_record()["P0"])
        self.passed: deque[tuple[int, np.ndarray]] = deque([(0, self.P_start)])
        """(sample, the filter's covariance there) of the segment starts passed since the last forgetting."""
        self.windows = 0
        self.gain_failures = 0
        self.latency_ms: deque[float] = deque(maxlen=LATENCIES_KEPT)
        self.delay_s: deque[float] = deque(maxlen=LATENCIES_KEPT)

    def advance(self, final: bool = False) -> SmoothedSamples | None:
        """The segments the record now closes, smoothed (None: none yet); ``final``: the record is
        complete, every segment to its last sample."""
        system, cfg = self.system, self.cfg
        t0 = time.perf_counter_ns()
        last = system._i if final else system._i - 1  # the fuser may correct the last sample again
        s = self.start
        if last - s < (1 if final else 2):  # at the close, the last stretch however short
            return None
        lo = max(s - 1, 0)  # the replay from s takes the mechanisation memory of sample s − 1
        rec = system.smoothing_record(lo)
        rate_hz = float(system._rate_hz)
        stance = rec["stance"][s - lo:last - lo + 1]
        mids = stance_midpoints(stance, rate_hz, cfg.min_stance_s, ended=not final, skip_first=s > 0) + s
        bounds = np.unique(np.concatenate([[s], mids, [last] if final else []])).astype(np.int64)
        bounds = cut_long_segments(bounds, max_segment_samples(cfg.max_segment_s, rate_hz))
        if bounds.size < 2:
            return None
        t_nav = rec["t"]
        t_bounds = t_nav[bounds - lo]
        ends = np.maximum(np.searchsorted(t_bounds, t_bounds[1:] + cfg.lag_s - 1e-9, side="left"),
                          np.arange(1, bounds.size))
        if final:
            ends = np.minimum(ends, bounds.size - 1)
        ready = int(np.count_nonzero(ends < bounds.size))  # ends increase: the windows closed come first
        if ready == 0:
            return None
        hi = int(bounds[ends[ready - 1]])
        r = _record_up_to(rec, hi - lo, self.P_start)
        general = r.general_updates()
        local = bounds[:ends[ready - 1] + 1] - lo
        store = sweep_store(r, local, general, ends[:ready])
        out_x, out_var = r.hist_x.copy(), np.zeros((r.n, 4))
        buf = BlockBuffers(1)
        P = self.P_start
        for k in range(ready):
            if k:
                self.passed.append((int(bounds[k]), P))
            P, failed = window_rts(r, general, (int(local[k]), int(local[k + 1]), int(local[ends[k]])), P, store, buf,
                                   SmoothedOutput(out_x, out_var))
            self.gain_failures += failed
            self.delay_s.append(float(t_nav[local[ends[k]]] - t_nav[local[k + 1]]))
        self.windows += ready
        a, b = int(local[0]), int(local[ready]) + (1 if final and ready == bounds.size - 1 else 0)
        self.start, self.P_start = int(bounds[ready]), P
        self.passed.append((self.start, P))
        self.latency_ms.append((time.perf_counter_ns() - t0) / 1e6)
        return SmoothedSamples(system.stream.t[lo + a:lo + b].copy(), out_x[a:b, 0:3].copy(),
                               np.sqrt(np.maximum(out_var[a:b, 0:3], 0.0)))

    def covariance_at(self, d: int) -> np.ndarray:
        """The filter's covariance at held sample ``d`` (no later than :attr:`start`): replayed from
        the last segment start at or before it."""
        if d == self.start:
            return self.P_start.copy()
        j, P_j = next((j, P) for j, P in reversed(self.passed) if j <= d)
        if j == d:
            return P_j.copy()
        lo = max(j - 1, 0)
        r = _record_up_to(self.system.smoothing_record(lo), d - lo, P_j)
        return r.forward(j - lo, d - lo, P_j, False, BlockBuffers(1))

    def forget(self, d: int, P_d: np.ndarray) -> None:
        """The system forgot its first ``d`` samples (no later than :attr:`start`); ``P_d``: its
        covariance at sample ``d`` (:meth:`covariance_at`), now its first."""
        self.start -= d
        self.passed = deque([(0, P_d), *((j - d, P) for j, P in self.passed if j > d)])

    def diagnostics(self) -> dict:
        """``windows``, ``gain_failures``, ``latency_ms`` (mean, p99, max over the passes that
        closed windows) and ``delay_s`` (least, median, largest over the windows)."""
        out: dict = {"kind": "fixed-lag", "lag_s": self.cfg.lag_s, "windows": self.windows,
                     "gain_failures": self.gain_failures}
        if self.latency_ms:
            ms = np.asarray(self.latency_ms)
            out["latency_ms"] = {"mean": float(ms.mean()), "p99": float(np.percentile(ms, 99)), "max": float(ms.max())}
        if self.delay_s:
            d = np.asarray(self.delay_s)
            out["delay_s"] = {"min": float(d.min()), "median": float(np.median(d)), "max": float(d.max())}
        return out
