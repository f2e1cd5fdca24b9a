"""The hand-held phone live (:class:`~bodyfusion.core.capabilities.Streaming`): its IMU recording
and its GNSS fixes grow while it runs.

Two streamed sections: ``imu`` paces the run; ``gnss`` (a CSV's columns) is taken as it comes.
Each pass (:meth:`StreamingHandPdr.extend`) reads the IMU recording's last :data:`CONTEXT_S` before
its first undecided sample and derives from it what the batch run derives from the whole
recording (:meth:`~bodyfusion.plugins.hand_pdr.system.HandPdr._derive`: steps and their lengths,
the azimuth increments, where the phone is held steadily). The samples up to the look-ahead L
behind the newest become final: their steps, azimuth increments (continued from the last final
sample's) and steadiness are kept from then on, and the events they hold (steps, fixes, a heading
re-opened) join the filter's queue in time order. The fixes are read whole at every pass (one a
second) and flagged as the batch run flags them (:class:`~bodyfusion.plugins.hand_pdr.fixes.PhoneFixes`),
in the frame of the start fix. What is not local: the zero-phase low-passes and the step period
reach a few seconds past a sample (the look-ahead covers most of it); a fix arriving after its
time was decided is not taken (``late_fixes``). :meth:`StreamingHandPdr.close_stream` derives the
whole recording once more and counts the final steps the batch run would have placed otherwise
(``revised_steps``).

Not live: a GetSensorData phone log (one file of every sensor; give ``imu`` and ``gnss``), NMEA and
UBX fix logs (give the fixes' columns) and the magnetometer.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from pydantic import BaseModel

from bodyfusion.base.errors import ConfigError, FusionError, NotReady
from bodyfusion.base.findings import Finding
from bodyfusion.base.types import ImuStream, log_silenced
from bodyfusion.core.capabilities import Streaming, forgotten_history_finding
from bodyfusion.io.gnss import GnssFixes
from bodyfusion.io.imu import read_imu
from bodyfusion.plugins.hand_pdr.model import GNSS, STEADY, STEP

CONTEXT_S = 30.0
"""Recording (s) before the first undecided sample that each pass derives again: the step
period's 8 s windows, the missed-step search's neighbours and the low-passes' reach."""


class StreamingHandPdr(Streaming):
    """What :class:`~bodyfusion.plugins.hand_pdr.system.HandPdr` adds to run live (module docstring)."""

    _lookahead_s: float | None = None
    _decided = 0
    """IMU samples final so far (the first undecided one's index)."""
    _fixes_read = 0
    """GNSS fixes read by the last pass."""
    _t_first: float | None = None
    """The recording's first sample (s), once live."""
    _rate_hz = math.nan
    """The IMU's rate (Hz) on the live run's first part: the context's length in samples."""
    late_fixes = 0
    """Fixes that arrived after their time was decided (not taken)."""
    revised_steps = 0
    """Final steps the whole recording would have placed otherwise (counted when the stream closes)."""
    forgotten = 0
    """IMU samples dropped from the front so far (:meth:`forget_before`)."""

    @classmethod
    def streamed_sections(cls, config: BaseModel) -> tuple[str, ...]:
        """``imu``, and ``gnss`` when the phone has fixes (module docstring: what does not run live)."""
        if config.phone_log is not None:
            raise ConfigError("phone_log", "a phone log does not run live: give the phone's imu and gnss sections")
        if config.magnetometer.enabled:
            raise ConfigError("magnetometer.enabled", "the magnetometer does not run live yet; set it false")
        if config.gnss is None:
            return ("imu",)
        if config.gnss.format != "csv":
            raise ConfigError("gnss.format", f"{config.gnss.format} fixes do not run live: give the fixes' columns "
                                             "(format csv)")
        return ("imu", "gnss")

    def _check_fixes_arrived(self) -> None:
        """On a live run's first part: no fix yet, while the layout has a GNSS section, is
        :class:`~bodyfusion.base.errors.NotReady` (the frame and the heading come from the fixes)."""
        table = self.config.gnss.table if self.config.gnss is not None else None
        if self.context.growing and table is not None and not len(next(iter(table.values()))):
            raise NotReady(f"systems.{self.name}.gnss: no fix has arrived yet")

    def _check_start_fix(self) -> None:
        """On a live run's first part, a start from GNSS waits until a fix is confirmed by its
        successor (:func:`~bodyfusion.plugins.hand_pdr.fixes.first_confirmed`), as the whole
        recording's start fix is."""
        fx = self._fixes
        if not self.context.growing or fx is None or fx.confirmed < 0:
            return
        usable = np.flatnonzero(~fx.masked & ~fx.held & ~fx.fast)
        if fx.confirmed == usable[-1]:
            raise NotReady(f"systems.{self.name}.initial.position_m: no GNSS fix confirmed by the next yet")

    @property
    def t_start(self) -> float:
        """The recording's first sample (s), also once it is forgotten."""
        return self._t_first if self._t_first is not None else float(self.t[0])

    def start_streaming(self, lookahead_s: float) -> None:
        self._lookahead_s = lookahead_s
        self._t_first = float(self.t[0])
        self._rate_hz = 1.0 / float(np.median(np.diff(self.t)))
        self._fixes_read = len(self._fixes.t) if self._fixes is not None else 0
        self._decided = int(np.searchsorted(self.t, float(self.t[-1]) - lookahead_s, side="right"))
        until = self.decided_until()
        self._events = [e for e in self._events if e[0] <= until]

    def decided_until(self) -> float:
        """The last final IMU sample's time (s); ∞ when not live, or once the recording is complete."""
        if self._lookahead_s is None:
            return math.inf
        return float(self.t[self._decided - 1]) if self._decided else -math.inf

    def extend(self) -> None:
        a, stream, fixes = self._read_context()
        self._splice(stream.t, stream.acc_b, stream.gyro_b, a)
        self._decide(float(self.t[-1]) - self._lookahead_s, fixes)

    def _open_fix(self) -> int:
        """The first fix after the decided time: its flags (walking, held steadily) wait for the
        steps around it; the fixes before it are final."""
        fixes = self._fixes
        return int(np.searchsorted(fixes.t, self.decided_until(), side="right")) if fixes is not None else 0

    def _read_context(self) -> tuple[int, ImuStream, tuple[int, GnssFixes] | None]:
        """The IMU recording from :data:`CONTEXT_S` before the first undecided sample (its first
        sample's index, the samples) and the fixes from the one before the first open fix on (the
        first one read, the fixes: a fix is flagged against its predecessor)."""
        a = max(0, self._decided - int(CONTEXT_S * self._rate_hz))
        first = max(self._open_fix() - 1, 0)
        with log_silenced():  # what the readers find in the context they said on an earlier pass
            fixes = (first, self._read_fixes(first)) if self.config.gnss is not None else None
            # no checks: its derivation reads none, and the close checks the whole recording
            return a, read_imu(self.config.imu.rows_from(a), checks="none"), fixes

    def _splice(self, t: np.ndarray, acc: np.ndarray, gyro: np.ndarray, a: int) -> None:
        """Keep the final samples' derivations and take every later sample's from the derivation
        of the recording from sample ``a`` on (``t``, ``acc``, ``gyro``); a sample read before
        that changed is refused."""
        n0 = self._decided
        known = len(self.t) - a
        if len(t) < known or not np.array_equal(t[:known], self.t[a:]):
            raise FusionError(f"systems.{self.name}: the live recording changed samples already read "
                              "(live rows must come in time order)")
        d = self._derive(t, acc, gyro)
        k = n0 - a
        azimuth = d.azimuth[k:] - d.azimuth[k - 1] + self._azimuth[n0 - 1] if k > 0 else d.azimuth
        kept = int(np.searchsorted(self.step_index, n0))
        new = d.step_index >= k
        if kept and new.any():  # a step the context places within the debounce of the last final one is that one
            distance = max(1, int(round(self.config.step.min_interval_s * self._rate_hz)))
            new &= d.step_index + a - self.step_index[kept - 1] >= distance
        self.t = np.concatenate([self.t[:n0], t[k:]])
        self._azimuth = np.concatenate([self._azimuth[:n0], azimuth])
        self._steady = np.concatenate([self._steady[:n0], d.steady[k:]])
        self.step_index = np.concatenate([self.step_index[:kept], d.step_index[new] + a])
        self.step_length_m = np.concatenate([self.step_length_m[:kept], d.step_length_m[new]])

    def _decide(self, until_t: float, fixes: tuple[int, GnssFixes] | None) -> None:
        """Make the samples up to ``until_t`` (s) final and queue their events, with ``fixes`` (the
        GNSS section's rows from a first one on, :meth:`_read_context`; None: none): the open ones
        flagged as the batch run flags them, the final ones kept."""
        before = self.decided_until()
        if fixes is not None and len(fixes[1]) and fixes[0] + len(fixes[1]) > self._open_fix():
            first, rows = fixes
            held, u = self._fixes, self._open_fix()
            read = self._fixes_read
            tail = self._phone_fixes(rows)
            # a fix's position is kept from the pass that read it: converted in an array that starts
            # where it does whatever was forgotten before (a vectorised sine may round by where a
            # value falls in its array)
            fresh = tail.pos[read - first:]
            joined = {f.name: np.concatenate([getattr(held, f.name)[:u], getattr(tail, f.name)[u - first:]])
                      if held is not None else getattr(tail, f.name) for f in dataclasses.fields(tail)
                      if isinstance(getattr(tail, f.name), np.ndarray)}
            joined["pos"] = np.concatenate([held.pos[:read], fresh]) if held is not None else fresh
            self._fixes = dataclasses.replace(tail, **joined, confirmed=held.confirmed if held is not None else -1)
            self.late_fixes += int(np.count_nonzero(self._fixes.t[read:] <= before))
            self._fixes_read = len(self._fixes.t)
        self._decided = max(self._decided, int(np.searchsorted(self.t, until_t, side="right")))
        self._events = self._events[self._next:] + self._event_list(before, self.decided_until())
        self._next = 0

    def close_stream(self) -> None:
        """Derive the whole recording once more (what the batch run derives), keep what was final
        (counting the steps placed otherwise: ``revised_steps``) and decide every sample."""
        stream = read_imu(self.config.imu)
        n0 = self._decided
        whole = self._derive(stream.t, stream.acc_b, stream.gyro_b).step_index
        mine = self.step_index[self.step_index < n0]
        theirs = whole[whole < n0]
        if self.forgotten:  # the first context lacks the samples before it: not compared
            edge = int(CONTEXT_S * self._rate_hz)
            mine, theirs = mine[mine >= edge], theirs[theirs >= edge]
        self.revised_steps = int(np.setxor1d(mine, theirs).size)
        a, context, fixes = self._read_context()  # the last part as a pass reads it: the same sums
        self._splice(context.t, context.acc_b, context.gyro_b, a)
        self._report = stream.report if fixes is None else stream.report.merge(self._read_fixes().report)
        self._decide(math.inf, fixes)
        self._decided = len(self.t)
        self._lookahead_s = None

    def forget_before(self, t: float) -> dict[str, int]:
        """Drop the IMU samples before ``t`` (s), the steps, fixes and history rows before them, as
        far as the next pass allows (it derives again from :data:`CONTEXT_S` before the first
        undecided sample) and the filter has passed; the indices kept lose the numbers dropped."""
        if self._lookahead_s is None:
            return {}
        d = min(int(np.searchsorted(self.t, t)), self._decided - int(CONTEXT_S * self._rate_hz), self._i_tc)
        if d <= 0:
            return {}
        steps = int(np.searchsorted(self.step_index, d))
        fixes = int(np.searchsorted(self._fixes.t, self.t[d])) if self._fixes is not None else 0
        shift = {STEP: steps, GNSS: fixes, STEADY: d}
        self._events = [(te, kind, k - shift.get(kind, 0), i - d) for te, kind, k, i in self._events[self._next:]]
        self._next = 0
        self.t, self._azimuth, self._steady = self.t[d:].copy(), self._azimuth[d:].copy(), self._steady[d:].copy()
        self.step_index, self.step_length_m = self.step_index[steps:] - d, self.step_length_m[steps:].copy()
        if self._fixes is not None:
            fx = self._fixes
            self._fixes = dataclasses.replace(fx, confirmed=fx.confirmed - fixes, **{
                f.name: getattr(fx, f.name)[fixes:].copy() for f in dataclasses.fields(fx)
                if isinstance(getattr(fx, f.name), np.ndarray)})
        self._start_fix -= fixes
        self._fixes_read -= fixes
        self._i_tc -= d
        self._decided -= d
        rows = int(np.searchsorted(self._hist_x.view()[:, 0], self.t[0]))
        self._hist_x.drop_first(rows)
        self._hist_P.drop_first(rows)
        for record in self.nis_records.values():
            record.forget_before(float(self.t[0]))
        self.forgotten += d
        return {"imu": d, **({"gnss": fixes} if fixes else {})}

    def live_findings(self) -> list[Finding]:
        """Where this live run departed from the batch run on the same recording: steps placed
        otherwise, fixes that came too late, a history forgotten."""
        if self._t_first is None or self._lookahead_s is not None:  # not live, or not closed yet
            return []
        t0, t1 = float(self.t[0]), float(self.t[-1])
        out = []
        if self.forgotten:
            out.append(forgotten_history_finding(self.name, self._t_first, t0, t1, self.forgotten))
        if self.revised_steps:
            out.append(Finding(
                "live_revisions", "info", self.name, t0, t1,
                f"{self.revised_steps} steps were placed where the whole recording would not have placed them (or "
                "missed where it would), so the track departs from a batch run's there.",
                f"a step decision needed more than the {CONTEXT_S:g} s before or the look-ahead after it.",
                "raise the look-ahead (fusion live --lookahead) if the delay allows."))
        if self.late_fixes:
            out.append(Finding(
                "late_fixes", "warning", self.name, t0, t1,
                f"{self.late_fixes} GNSS fixes arrived after the phone's data had been decided past their time and "
                "were not used.",
                "the fixes reach the run later than the look-ahead behind the phone's IMU samples.",
                "raise the look-ahead (fusion live --lookahead) above the fixes' delay."))
        return out

