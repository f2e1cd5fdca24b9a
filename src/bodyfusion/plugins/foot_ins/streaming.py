"""The foot INS live (:class:`~bodyfusion.core.capabilities.Streaming`): its recording grows while
it runs.

Each pass (:meth:`StreamingFootIns.extend`) reads the recording's last :data:`CONTEXT_S` before
its first undecided sample (the bound table's rows; the live engine keeps them in time order, so
that row k is sample k) and derives from it what the batch run derives from the whole recording
(:meth:`~bodyfusion.plugins.foot_ins.system.FootIns._derive`: saturation repair, stance detection
and its watchdog, the gap policy's increments, the navigation clock's steps). The samples up to
the look-ahead L behind the newest become final and are appended to the filter's inputs; the
filter's state and history carry on. Every derivation is local in time — the SHOE statistic and
its threshold over a stride, the stride period over 8 s windows every 1 s (the context starts on
that grid) — so a pass makes the batch run's decisions about the samples it finalises wherever
those depend on less than the context before them and the look-ahead after; a stance decision
needs at most about 1 s after it on every shared foot recording
(``benchmarks/stance_lookahead.py``). What is not local: a stretch of missed stances longer than
the context, the stride period filled in where no gait repeats (the recording's median), the
gap policy's RMS motion, a sensor's rails found from the whole recording.
:meth:`StreamingFootIns.close_stream` derives the whole recording once more and counts every
final input the batch run would have taken otherwise (``revised_inputs``): the places a live
run departs from the batch run, and the only ones.

Cost: a pass is linear in the context, not the recording (the stance runs are recounted over the
whole, a vectorised pass); the filter's history grows with the recording.
"""

from __future__ import annotations

import math

import numpy as np

from bodyfusion.base.errors import FusionError, NotReady
from bodyfusion.base.findings import Finding
from bodyfusion.base.records import GrowingArray
from bodyfusion.base.types import ImuStream, log_silenced
from bodyfusion.core.capabilities import Streaming, forgotten_history_finding
from bodyfusion.core.layout import SmootherConfig
from bodyfusion.io.imu import read_imu
from bodyfusion.nav import detectors
from bodyfusion.nav.gait import PERIOD_HOP_S
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.input_policy import DerivedInputs, clock_lag, navigation_clock
from bodyfusion.plugins.foot_ins.kernels import NO_STANCE
from bodyfusion.plugins.foot_ins.records import RECORDED_COVARIANCE
from bodyfusion.plugins.foot_ins.smoothing_live import LiveFixedLag

CONTEXT_S = 30.0
"""Recording (s) before the first undecided sample that each pass derives again: several stride
periods' windows, a stretch of missed stances."""
LEVELLING_WAIT_S = 60.0
"""Longest a live foot INS waits for its first rest to end (s); then it levels on the quietest
window so far, as a batch run does on a recording without rest."""


class LiveInputs:
    """The filter's inputs so far, in growing arrays: sample times (s), repaired specific force
    (m/s^2) and rate (rad/s), stance, the navigation clock's accumulated lag (s) and the clock
    itself (s: the sample time less the lag)."""

    def __init__(self, stream: ImuStream, stance: np.ndarray, lag: np.ndarray) -> None:
        n = len(stream)
        self.t = GrowingArray((), capacity=2 * n)
        self.acc = GrowingArray((3,), capacity=2 * n)
        self.gyro = GrowingArray((3,), capacity=2 * n)
        self.stance = GrowingArray((), np.bool_, capacity=2 * n)
        self.lag = GrowingArray((), capacity=2 * n)
        self.t_nav = GrowingArray((), capacity=2 * n)
        self.arrays = (self.t, self.acc, self.gyro, self.stance, self.lag, self.t_nav)
        self.append(stream.t, stream.acc_b, stream.gyro_b, stance, lag)

    def append(self, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, stance: np.ndarray, lag: np.ndarray) -> None:
        """Rows after the last, ``lag`` the clock's steps there (s): accumulated from the last row's
        as :func:`numpy.cumsum` accumulates them over the whole recording."""
        before = self.lag.view()[-1:] if len(self.lag) else np.zeros(1)
        total = np.cumsum(np.concatenate([before, lag]))[1:]
        for array, rows in zip(self.arrays, (t, acc, gyro, stance, total, t - total)):
            array.extend(rows)

    def keep(self, n: int) -> None:
        """Drop every row from n on."""
        for array in self.arrays:
            array.keep(n)

    def drop_first(self, d: int) -> None:
        """Drop the first d rows."""
        for array in self.arrays:
            array.drop_first(d)

    def __len__(self) -> int:
        return len(self.t)


class StreamingFootIns(Streaming):
    """What :class:`~bodyfusion.plugins.foot_ins.system.FootIns` adds to run live (module docstring)."""

    _lookahead_s: float | None = None
    _decided = 0
    _live: LiveInputs | None = None
    _levelled_on: tuple[int, int] | None = None
    """Where the whole recording would have levelled (first sample, end), once the stream closed."""
    revised_inputs = 0
    """Final samples whose inputs (stance, repaired IMU sample, navigation clock, a covariance
    increment) the whole recording would have given otherwise (counted when the stream closes)."""
    forgotten = 0
    """Samples dropped from the front so far (:meth:`forget_before`); sample k now is the
    recording's sample k + ``forgotten``."""
    _t_first: float | None = None
    """The recording's first sample (s), once live."""
    P_first_held: np.ndarray | None = None
    """The filter's covariance at the first sample held, once samples before it were forgotten by a
    run that smooths (None: the initial one): where a smoother of what is held starts."""
    _live_smoother: LiveFixedLag | None = None
    """The live fixed-lag smoother, once asked for (:meth:`live_smoother`)."""

    def _check_ready(self) -> None:
        """On a live run's first part (:attr:`~bodyfusion.core.system.LayoutContext.growing`), refuse
        to start (:class:`~bodyfusion.base.errors.NotReady`) before the first rest has ended, for up
        to :data:`LEVELLING_WAIT_S`: the levelling takes the rest whole, as the batch run does."""
        if not self.context.growing or self.stream.t[-1] - self.stream.t[0] >= LEVELLING_WAIT_S:
            return
        if not self.still.still or self.still.stop >= len(self.stream):
            raise NotReady(f"systems.{self.name}: no rest of {self.config.initial.stationary_s:g} s has ended in the "
                           f"first {self.stream.t[-1] - self.stream.t[0]:.1f} s yet")

    def live_findings(self) -> list[Finding]:
        """Where this live run departed from the batch run on the same recording: a levelling on
        another rest, inputs the whole recording would have made otherwise, a history forgotten."""
        if self._t_first is None or self._lookahead_s is not None:  # not live, or not closed yet
            return []
        t = self.stream.t
        out = []
        a, b = self.still.start, self.still.stop
        if self._levelled_on is not None and self._levelled_on != (a, b):  # None: forgotten, not compared
            c, d = self._levelled_on
            out.append(Finding(
                "live_levelling", "info", self.name, float(t[a]), float(t[b - 1]),
                f"the live run levelled on t = {t[a]:.2f}–{t[b - 1]:.2f} s; the whole recording would have "
                f"levelled on t = {t[c]:.2f}–{t[d - 1]:.2f} s (its stillest rest), so the track departs from a batch "
                "run's from the start.",
                "a live run levels on its first rest; a batch run on the first rest as still as the recording's "
                "stillest.", "stand still for a second or two before walking, as still as at any rest later."))
        if self.forgotten:
            out.append(forgotten_history_finding(self.name, self._t_first, float(t[0]), float(t[-1]), self.forgotten))
        if self.revised_inputs:
            out.append(Finding(
                "live_revisions", "info", self.name, float(t[0]), float(t[-1]),
                f"{self.revised_inputs} samples were navigated with inputs (stance, a repaired sample, the clock, a "
                "covariance increment) the whole recording would have made otherwise, so the track departs from a "
                "batch run's there.",
                f"those decisions needed more than the {CONTEXT_S:g} s before or the look-ahead after them (a long "
                "stretch of missed stances, a gap, a rail seen only later).",
                "raise the look-ahead (fusion live --lookahead) if the delay allows."))
        return out

    def live_smoother(self, cfg: SmootherConfig) -> LiveFixedLag:
        """The fixed-lag smoother as this live run goes (:mod:`bodyfusion.plugins.foot_ins.smoothing_live`)."""
        if cfg.kind != "fixed-lag":
            raise FusionError(f"smoother.kind {cfg.kind} does not smooth live: use fixed-lag")
        self._live_smoother = LiveFixedLag(self, cfg)
        return self._live_smoother

    def start_streaming(self, lookahead_s: float) -> None:
        if self.config.position_fixes is not None:
            raise FusionError(f"systems.{self.name}.position_fixes: a live foot INS takes no position-fix file")
        self._lookahead_s = lookahead_s
        self._t_first = float(self.stream.t[0])
        self._live = LiveInputs(self.stream, self.stance, clock_lag(self.stream))
        self._decide(float(self.stream.t[-1]) - lookahead_s)

    @property
    def t_start(self) -> float:
        """The recording's first sample (s), also once it is forgotten (the fuser's epoch grid starts there)."""
        return self._t_first if self._t_first is not None else float(self.stream.t[0])

    def forget_before(self, t: float) -> dict[str, int]:
        """Drop the samples before ``t`` (s) with their inputs and history rows, as far as the next
        pass allows: it derives again from :data:`CONTEXT_S` before the first undecided sample, on
        the stride period's grid (so the number dropped is a multiple of its hop), and the lockout
        watch reads the stance the filter is in whole. Indices kept (the filter's sample, the gaps'
        and corrections') lose the number dropped; the covariances kept for a smoother before it
        are dropped with them. A live fixed-lag smoother (:meth:`live_smoother`) keeps every sample from its next
        segment's start, and the covariance at the new first sample is kept (:attr:`P_first_held`: a smoother at the
        close starts there)."""
        if self._lookahead_s is None:
            return {}
        hop = max(1, int(round(PERIOD_HOP_S * self._rate_hz)))
        d = min(int(np.searchsorted(self.stream.t, t)), self._decided - int(CONTEXT_S * self._rate_hz) - hop, self._i)
        starts, ends = self._stance_runs
        r = int(np.searchsorted(starts, self._i, side="right")) - 1
        if r >= 0 and ends[r] > self._i:
            d = min(d, int(starts[r]))
        if self._live_smoother is not None:  # it smooths from its next segment's start on
            d = min(d, self._live_smoother.start)
        d -= d % hop
        if d <= 0:
            return {}
        if self._live_smoother is not None:  # the covariance at the new first sample: a smoother's start
            self.P_first_held = self._live_smoother.covariance_at(d)
            self._live_smoother.forget(d, self.P_first_held)
        self._live.drop_first(d)
        data, n = self.run_data, self._i + 1
        for name in ("hist_x", "hist_cov", "hist_nis"):
            rows = getattr(data, name)
            rows[:n - d] = rows[d:n]  # the rows written so far
        self._i -= d
        self._decided -= d
        self._input_increments = self._shifted(self._input_increments, d)
        self._gap_index, self._gap_P = self._shifted((self._gap_index, self._gap_P), d)
        gone = int(np.searchsorted(data.kept_idx.view(), d))  # the kept corrections, in time order
        data.kept_idx.drop_first(gone)
        data.kept_x.drop_first(gone)
        data.kept_idx.view()[:] -= d
        overrides = [self._shifted(pair, d) for pair in zip(data.override_idx, data.override_P)]
        data.override_idx, data.override_P = [i for i, _ in overrides], [P for _, P in overrides]
        self.corrections = self.corrections.forgotten(d)
        self.forgotten += d
        self._take_live()
        return {self.data_section: d}

    @staticmethod
    def _shifted(indexed: tuple[np.ndarray, np.ndarray], d: int) -> tuple[np.ndarray, np.ndarray]:
        """(sample indices, rows) of the samples ``d`` and later, each index less d."""
        later = indexed[0] >= d
        return indexed[0][later] - d, indexed[1][later]

    def decided_until(self) -> float:
        """The last final sample's time (s); ∞ when not live, or once the recording is complete."""
        if self._lookahead_s is None:
            return math.inf
        return float(self.stream.t[self._decided - 1]) if self._decided else -math.inf

    def extend(self) -> None:
        n0 = self._decided
        hop = max(1, int(round(PERIOD_HOP_S * self._rate_hz)))
        a = max(0, n0 - int(CONTEXT_S * self._rate_hz))
        a -= a % hop  # the stride period's windows on the whole recording's grid
        with log_silenced():  # what the reader finds in the context it said on an earlier pass
            # the gaps and clipping only: the units, rate and rest checks report, and the close checks the whole
            derived = self._derive(read_imu(self.config.data.rows_from(a), checks="inputs"))
        self._splice(derived, a)
        self._decide(float(self.stream.t[-1]) - self._lookahead_s)

    def _splice(self, derived: DerivedInputs, a: int) -> None:
        """Keep the final samples (those before the first undecided one) and take every later one
        from ``derived``, the derivation of the recording from sample ``a`` on; a row read before
        that changed is refused."""
        live, n0 = self._live, self._decided
        tail = derived.stream
        known = len(live) - a  # rows read before, and kept: they must not have changed
        if len(tail) < known or not np.array_equal(tail.t[:known], live.t.view()[a:]):
            raise FusionError(f"systems.{self.name}: the live recording changed samples already read "
                              "(live rows must come in time order)")
        k = n0 - a
        live.keep(n0)
        live.append(tail.t[k:], tail.acc_b[k:], tail.gyro_b[k:], derived.detection.stance[k:], clock_lag(tail)[k:])
        index, increments = derived.increments
        later = index >= k
        self._input_increments = self._merge_increments(self._input_increments, index[later] + a, increments[later], n0)
        self._gap_index, self._gap_P = self._merge_increments((self._gap_index, self._gap_P), index[later] + a,
                                                              increments[later], n0)
        self._take_live()

    @staticmethod
    def _merge_increments(old: tuple[np.ndarray, np.ndarray], index: np.ndarray, increments: np.ndarray,
                          n0: int) -> tuple[np.ndarray, np.ndarray]:
        """The increments before sample n0 kept, the new ones from n0 on."""
        kept = old[0] < n0
        return np.concatenate([old[0][kept], index]), np.concatenate([old[1][kept], increments])

    def _take_live(self) -> None:
        """The filter reads the growing inputs; its history rows reach the recording's length."""
        live, data = self._live, self.run_data
        t = live.t.view()
        self.stream = ImuStream(t, live.acc.view(), live.gyro.view(), None, self.stream.source, self.stream.report,
                                self.stream.checks)
        self.stance = self.stance_detection.stance = live.stance.view()
        self._t_nav = live.t_nav.view()
        self._stance_runs = detectors.stance_events(self.stance)
        data.t, data.acc_b, data.gyro_b, data.stance = self._t_nav, self.stream.acc_b, self.stream.gyro_b, self.stance
        n, m = len(t), data.hist_x.shape[0]
        if n > m:
            size = max(n, 2 * m)
            for name, shape, fill in (("hist_x", (NOMINAL_SIZE,), np.nan), ("hist_cov", (RECORDED_COVARIANCE,), np.nan),
                                      ("hist_nis", (), NO_STANCE)):
                grown = np.full((size, *shape), fill)
                grown[:m] = getattr(data, name)
                setattr(data, name, grown)

    def close_stream(self) -> None:
        """Derive the whole recording once more (what the batch run derives), keep what was final
        (counting where it differs: ``revised_inputs``) and decide every sample. After
        :meth:`forget_before` the recording is what is left of it: its first :data:`CONTEXT_S` lack
        the samples before them and are not counted, and the levelling is not compared."""
        live, n0 = self._live, self._decided
        whole = self._derive(read_imu(self.config.data))
        s = whole.stream
        if len(s) < n0:
            raise FusionError(f"systems.{self.name}: the live recording changed samples already read "
                              "(live rows must come in time order)")
        differ = ((whole.detection.stance[:n0] != live.stance.view()[:n0])
                  | np.any(s.acc_b[:n0] != live.acc.view()[:n0], axis=1)
                  | np.any(s.gyro_b[:n0] != live.gyro.view()[:n0], axis=1)
                  | (navigation_clock(s)[:n0] != live.t_nav.view()[:n0]))
        theirs = {int(i): P for i, P in zip(*whole.increments) if i < n0}
        mine = {int(i): P for i, P in zip(*self._input_increments) if i < n0}
        for i in set(theirs) | set(mine):
            if i not in theirs or i not in mine or not np.array_equal(theirs[i], mine[i]):
                differ[i] = True
        if self.forgotten:
            differ[:int(CONTEXT_S * self._rate_hz)] = False
        self.revised_inputs = int(np.count_nonzero(differ))
        self._splice(whole, 0)
        self.clipping, self.stance_detection = whole.clipping, whole.detection  # the findings of the whole recording
        self.stance_detection.stance = self.stance
        self.stream.report, self.stream.checks = s.report, s.checks
        if not self.forgotten:
            whole_still = self._find_still_interval()  # the whole recording's: the findings compare the live one
            self._levelled_on = (whole_still.start, whole_still.stop)
        self._decided = len(self.stream)
        self._lookahead_s = None

    def _decide(self, until_t: float) -> None:
        self._decided = max(self._decided, int(np.searchsorted(self.stream.t, until_t, side="right")))
