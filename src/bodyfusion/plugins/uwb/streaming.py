"""The UWB tag live (:class:`~bodyfusion.core.capabilities.Streaming`): its ranges arrive while the
run goes.

The tag is an aiding source: its ranges do not pace the run (``paces_live`` False) — the feet's
samples do — and are taken as they come. Each pass (:meth:`StreamingUwbTag.extend`) reads the
ranges received so far (the bound table, rows in time order; several may share a time) by the
batch reader's policies (:func:`~bodyfusion.plugins.uwb.ranges.read_ranges`: failed and
negative rangings dropped and counted) and keeps the fuser's verdicts on those it had. A range
whose time the fuser has passed when it arrives (the ranges came later than the look-ahead
behind the feet's data) is not applied: the fuser's schedule tells the tag
(:meth:`StreamingUwbTag.record_late`), which counts it (``late`` in the diagnostics, a
``late_ranges`` finding). Ranges that arrive in time are applied at the batch run's events, in
its order, so that a live run is the batch run wherever none is late.

Memory: the tag keeps every range received (about 40 bytes each: a day at 10 Hz is 35 MB); it
forgets none in a bounded live run (``--keep``).
"""

from __future__ import annotations

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.base.findings import Finding
from bodyfusion.core.capabilities import Streaming
from bodyfusion.plugins.uwb.ranges import RangeLog, read_ranges

UNUSED, ACCEPTED, REJECTED, NOT_APPLIED, LATE = 0, 1, 2, 3, 4
"""Fate of each range, as the fuser recorded it (:data:`LATE`: arrived after the fuser passed its time)."""


class StreamingUwbTag(Streaming):
    """What :class:`~bodyfusion.plugins.uwb.system.UwbTag` adds to run live (module docstring)."""

    paces_live = False
    log: RangeLog
    fate: np.ndarray
    nis: np.ndarray

    def read_log(self) -> RangeLog:
        """The ranges of the tag's ``ranges`` section (its file, or the table bound to it)."""
        rc = self.config.ranges
        return read_ranges(rc, self.ids, time_column=rc.time_column, id_column=rc.id_column,
                           range_column=rc.range_column, nlos_column=rc.nlos_column, delimiter=rc.delimiter)

    def start_streaming(self, lookahead_s: float) -> None:
        """Nothing to decide: the tag's ranges are taken as they come."""

    def extend(self) -> None:
        """Read the ranges received so far; those read before keep their verdicts."""
        log = self.read_log()
        n = len(self.log)
        if len(log) < n or not (np.array_equal(log.t[:n], self.log.t[:n]) and np.array_equal(log.end[:n],
                                                                                              self.log.end[:n])):
            raise FusionError(f"systems.{self.name}: the live ranges changed rows already read "
                              "(live rows must come in time order)")
        self.log = log
        self.fate = np.concatenate([self.fate, np.full(len(log) - n, UNUSED, dtype=np.int8)])
        self.nis = np.concatenate([self.nis, np.full(len(log) - n, np.nan)])

    def close_stream(self) -> None:
        self.extend()

    def record_late(self, k: int) -> None:
        self.fate[k] = LATE

    def findings(self) -> list[Finding]:
        """``late_ranges``: ranges that arrived after the fuser had passed their time."""
        late = np.flatnonzero(self.fate == LATE)
        if not late.size:
            return []
        t = self.log.t[late]
        return [Finding(
            "late_ranges", "warning", self.name, float(t[0]), float(t[-1]),
            f"{late.size} of {len(self.log)} ranges arrived after the fuser had passed their time and were not "
            "applied.",
            "the ranges reached the run later than the look-ahead behind the navigation systems' data.",
            "raise the look-ahead (fusion live --lookahead) above the ranges' delay.")]
