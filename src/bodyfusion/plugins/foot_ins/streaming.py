"""The foot INS live (:class:`~bodyfusion.core.capabilities.Streaming`): its recording grows while
it runs.

Each time the data section's table grows, the whole recording so far is read and checked again
(:func:`~bodyfusion.io.imu.read_imu`) and everything the filter derives from the stream whole is
derived again (:meth:`FootIns._prepare`: saturation repair, stance detection and its watchdog,
the gap policy's increments, the navigation clock). What was decided before is kept: the
samples up to the look-ahead L behind the newest are final, and a later pass that would decide
one of them otherwise is counted (``revised_decisions``), not applied. The filter's state and
history carry on; its arrays grow. A stance decision about a sample needs at most
about 1 s of data beyond it on every shared foot recording (``benchmarks/stance_lookahead.py``),
so that with L = 2 s (the live engine's default) a live run makes the batch run's decisions there.

Cost: each pass is linear in the recording so far (the detector's stride period and its
watchdog look at the whole of it), so a pass every second costs O(N²) over a run: fine for
minutes to an hour, not for a day.
"""

from __future__ import annotations

import math

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.core.capabilities import Streaming
from bodyfusion.io.imu import read_imu
from bodyfusion.nav import detectors
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.kernels import NO_STANCE
from bodyfusion.plugins.foot_ins.records import RECORDED_COVARIANCE


class StreamingFootIns(Streaming):
    """What :class:`~bodyfusion.plugins.foot_ins.system.FootIns` adds to run live (module docstring)."""

    _lookahead_s: float | None = None
    _decided = 0
    revised_decisions = 0
    """Stance decisions about final samples that a later pass would have made otherwise."""

    def start_streaming(self, lookahead_s: float) -> None:
        if self.config.position_fixes is not None:
            raise FusionError(f"systems.{self.name}.position_fixes: a live foot INS takes no position-fix file")
        self._lookahead_s = lookahead_s
        self._decide(float(self.stream.t[-1]) - lookahead_s)

    def decided_until(self) -> float:
        """The last final sample's time (s); ∞ when not live, or once the recording is complete."""
        if self._lookahead_s is None:
            return math.inf
        return float(self.stream.t[self._decided - 1]) if self._decided else -math.inf

    def extend(self) -> None:
        self._grow(read_imu(self.config.data))
        self._decide(float(self.stream.t[-1]) - self._lookahead_s)

    def close_stream(self) -> None:
        self._grow(read_imu(self.config.data))
        self._decided = len(self.stream)
        self._lookahead_s = None

    def _decide(self, until_t: float) -> None:
        self._decided = max(self._decided, int(np.searchsorted(self.stream.t, until_t, side="right")))

    def _grow(self, stream) -> None:
        """Take the longer ``stream``: derive again, keep what was final, grow the filter's arrays."""
        n0 = self._decided
        t0 = self.stream.t[:n0]
        old = (self.stance.copy(), self._t_nav[:n0].copy(), self.stream.acc_b[:n0].copy(),
               self.stream.gyro_b[:n0].copy(), self._input_increments)
        if len(stream) < n0 or not np.array_equal(stream.t[:n0], t0):
            raise FusionError(f"systems.{self.name}: the live recording changed samples already decided "
                              "(a timestamp policy that reorders, or rows replaced): live runs need rows in time order")
        self._prepare(stream)
        stance, t_nav, acc, gyro, (gap_idx, gap_P) = old
        self.revised_decisions += int(np.count_nonzero(self.stance[:n0] != stance[:n0]))
        self.stance = self.stance_detection.stance = np.concatenate([stance[:n0], self.stance[n0:]])
        self._t_nav = np.concatenate([t_nav, self._t_nav[n0:]])
        self.stream.acc_b = np.concatenate([acc, self.stream.acc_b[n0:]])
        self.stream.gyro_b = np.concatenate([gyro, self.stream.gyro_b[n0:]])
        self._stance_runs = detectors.stance_events(self.stance)
        new_idx, new_P = self._input_increments
        later = new_idx >= n0
        kept = gap_idx < n0
        self._input_increments = (np.concatenate([gap_idx[kept], new_idx[later]]),
                                  np.concatenate([gap_P[kept], new_P[later]]))
        running = self._gap_index < n0  # the filter's own list: the lockout recoveries it added stay
        self._gap_index = np.concatenate([self._gap_index[running], new_idx[later]])
        self._gap_P = np.concatenate([self._gap_P[running], new_P[later]])
        self._grow_history()

    def _grow_history(self) -> None:
        """The filter's inputs are the new arrays; its history rows grow to the recording's length."""
        data, n = self.run_data, len(self.stream)
        data.t, data.acc_b, data.gyro_b, data.stance = self._t_nav, self.stream.acc_b, self.stream.gyro_b, self.stance
        m = data.hist_x.shape[0]
        if n > m:
            for name, shape, fill in (("hist_x", (NOMINAL_SIZE,), np.nan), ("hist_cov", (RECORDED_COVARIANCE,), np.nan),
                                      ("hist_nis", (), NO_STANCE)):
                grown = np.full((n, *shape), fill)
                grown[:m] = getattr(data, name)
                setattr(data, name, grown)
