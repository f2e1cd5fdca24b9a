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

Memory: a bounded live run (``--keep``) makes the tag forget the ranges the fuser has taken
before the time forgotten (:meth:`StreamingUwbTag.forget_before`), their verdicts kept as counts
(:class:`RangeTally`), so that its diagnostics and health cover the whole run while it holds the
ranges of the part kept.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.base.findings import Finding
from bodyfusion.base.sections import TableSection
from bodyfusion.core.capabilities import Streaming
from bodyfusion.plugins.uwb.ranges import RangeLog, read_ranges

UNUSED, ACCEPTED, REJECTED, NOT_APPLIED, LATE = 0, 1, 2, 3, 4
"""Fate of each range, as the fuser recorded it (:data:`LATE`: arrived after the fuser passed its time)."""


@dataclass
class RangeTally:
    """What ranges came to, per end (anchor or peer, in the tag's id order): ``fates`` (ends, 5)
    counts by fate, ``nis_accepted`` and ``nis_applied`` (ends,) the NIS summed over the accepted
    and over the applied (accepted or refused by the gate), ``nlos`` (2, 2) the applied ranges by
    their truth NLOS flag (row) and the gate's refusal (column), ``dropped`` the reader's drops."""

    fates: np.ndarray
    nis_accepted: np.ndarray
    nis_applied: np.ndarray
    nlos: np.ndarray
    dropped: dict[str, int] = field(default_factory=dict)

    @classmethod
    def empty(cls, ends: int) -> RangeTally:
        return cls(np.zeros((ends, 5), dtype=np.int64), np.zeros(ends), np.zeros(ends), np.zeros((2, 2), np.int64))

    @classmethod
    def of(cls, log: RangeLog, fate: np.ndarray, nis: np.ndarray, ends: int) -> RangeTally:
        """The tally of ranges ``log`` with their ``fate`` and ``nis``."""
        out = cls.empty(ends)
        np.add.at(out.fates, (log.end, fate), 1)
        accepted, applied = fate == ACCEPTED, (fate == ACCEPTED) | (fate == REJECTED)
        np.add.at(out.nis_accepted, log.end[accepted], nis[accepted])
        np.add.at(out.nis_applied, log.end[applied], nis[applied])
        if log.nlos is not None:
            np.add.at(out.nlos, (log.nlos[applied].astype(np.int64), (fate[applied] == REJECTED).astype(np.int64)), 1)
        out.dropped = dict(log.dropped)
        return out

    def __add__(self, other: RangeTally) -> RangeTally:
        return self._with(other, 1)

    def __sub__(self, other: RangeTally) -> RangeTally:
        return self._with(other, -1)

    def _with(self, other: RangeTally, sign: int) -> RangeTally:
        """This tally with ``other``'s added (``sign`` 1) or taken away (−1)."""
        return RangeTally(self.fates + sign * other.fates, self.nis_accepted + sign * other.nis_accepted,
                          self.nis_applied + sign * other.nis_applied, self.nlos + sign * other.nlos,
                          {k: self.dropped.get(k, 0) + sign * other.dropped.get(k, 0)
                           for k in {*self.dropped, *other.dropped}})


class StreamingUwbTag(Streaming):
    """What :class:`~bodyfusion.plugins.uwb.system.UwbTag` adds to run live (module docstring)."""

    paces_live = False
    log: RangeLog
    fate: np.ndarray
    nis: np.ndarray

    def read_log(self, section: TableSection | None = None) -> RangeLog:
        """The ranges of the tag's ``ranges`` section (its file, or the table bound to it), or of
        ``section``, a copy of it bound to other rows."""
        rc = self.config.ranges
        return read_ranges(rc if section is None else section, self.ids, time_column=rc.time_column,
                           id_column=rc.id_column, range_column=rc.range_column, nlos_column=rc.nlos_column,
                           delimiter=rc.delimiter)

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

    forgotten_tally: RangeTally | None = None
    """What the ranges forgotten so far came to (None: none forgotten)."""

    def tally(self) -> RangeTally:
        """What every range of the run came to: those held and those forgotten."""
        held = RangeTally.of(self.log, self.fate, self.nis, len(self.ids))
        return held if self.forgotten_tally is None else held + self.forgotten_tally

    def forget_before(self, t: float) -> dict[str, int]:
        """Forget the ranges before ``t`` (s) the fuser has taken, and their rows; what they came to
        is kept (:attr:`forgotten_tally`). Returns the rows of the ``ranges`` table dropped."""
        section = self.config.ranges
        if section.table is None:
            return {}
        times = np.asarray(section.table[section.time_column], dtype=float)
        k = int(np.searchsorted(self.log.t, t))
        if k == 0 or np.any(self.fate[:k] == UNUSED):
            return {}
        rows = int(np.searchsorted(times, self.log.t[k - 1], side="right"))  # through the last range forgotten
        later = self.read_log(section.rows_from(rows))
        gone = len(self.log) - len(later)
        before = self.tally()
        self.log, self.fate, self.nis = later, self.fate[gone:], self.nis[gone:]
        self.measurements_forgotten += gone
        self.forgotten_tally = before - RangeTally.of(later, self.fate, self.nis, len(self.ids))
        return {self.data_section: rows}

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
