"""Time stamps of every reader: strictly increasing by an explicit policy, corrupt stamps
dropped and counted, the time source of a table (a column, or a fixed rate).

Timestamps are never silently integrated with a zero or negative step: see
:func:`apply_timestamp_policy`. Every problem raises :class:`bodyfusion.base.errors.InputError`
naming the file (and line).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from bodyfusion.base.errors import InputError
from bodyfusion.base.types import InputReport

TIMESTAMP_POLICIES = ("drop", "sort", "error", "unwrap")
RESET_STEPS = 20.0
"""A backward step longer than this many median steps is a clock reset (a counter that wrapped
or restarted, a second recording appended), not a sample out of order (a few steps)."""
RESET_RUN = 10
"""Samples after a reset that must go on forward for it to be a reset (not a corrupt stamp)."""


def clock_resets(t: np.ndarray) -> np.ndarray:
    """Indices i where the clock restarts: t[i] lies more than :data:`RESET_STEPS` median steps
    before t[i − 1] and the :data:`RESET_RUN` samples from i on go forward."""
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    positive = dt[dt > 0]
    if positive.size == 0 or t.size < RESET_RUN + 2:
        return np.empty(0, dtype=np.int64)
    back = np.flatnonzero(dt < -RESET_STEPS * float(np.median(positive))) + 1
    return np.array([i for i in back if i + RESET_RUN <= t.size and np.all(np.diff(t[i:i + RESET_RUN]) > 0)],
                    dtype=np.int64)


def _unwrapped(t: np.ndarray, resets: np.ndarray, before: np.ndarray) -> np.ndarray:
    """``t`` with the samples from each reset on moved to continue one median step after the
    sample ``before`` it (the last valid one)."""
    t = np.array(t, dtype=float)
    dt = np.diff(t)
    step = float(np.median(dt[dt > 0]))
    for i, j in zip(resets, before):
        t[i:] += t[j] + step - t[i]
    return t


class PolicyResult(NamedTuple):
    """What :func:`apply_timestamp_policy` keeps: indices ``kept`` into the input, in output
    order, what it did (``report``) and the kept samples' times ``t`` (s, strictly increasing)."""

    kept: np.ndarray
    report: InputReport
    t: np.ndarray


def apply_timestamp_policy(
    t: np.ndarray,
    policy: str,
    path: str | Path,
    *,
    lines: np.ndarray | None = None,
) -> PolicyResult:
    """Make time strictly increasing by an explicit policy.

    Returns :class:`PolicyResult` ``(kept, report, t)``: ``kept`` are indices into ``t`` of the
    samples to keep, in output order; ``t`` their times, strictly increasing (``t[kept]`` of the
    input but under ``"unwrap"``, whose restarted clock goes on).

    Except under ``"error"``, samples whose stamp leaps far from both neighbours
    (:func:`timestamp_spikes`: a corrupt stamp such as 1e30) are dropped first, counted and
    warned about.

    - ``"drop"``: keep a sample only if its time is strictly greater than that of
      the last kept sample; the others count as ``dropped_samples``.
    - ``"sort"``: stable sort by time; ``reordered_samples`` counts the samples
      whose position changed; then exact duplicate times are dropped (the first
      in file order is kept) and counted as ``dropped_samples``.
    - ``"error"``: raise :class:`InputError` at the first sample whose time is not
      strictly greater than the previous one.
    - ``"unwrap"``: a clock that restarts (:func:`clock_resets`: a counter that wrapped or was
      reset) goes on from where it was, one median step after the last sample before each
      restart; warned about and counted; then as ``"drop"``.

    Under ``"drop"`` and ``"sort"`` a clock reset is refused naming its line: dropping what
    follows it (half a recording) or sorting two clocks into one would be silently wrong.

    ``lines`` (optional): the file line number of each sample, for messages.
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    if policy not in TIMESTAMP_POLICIES:
        raise InputError(
            path, f"unknown timestamp policy {policy!r}; allowed: " + ", ".join(TIMESTAMP_POLICIES)
        )

    def where(i: int) -> int | None:
        return None if lines is None else int(lines[i])

    nonfinite = np.flatnonzero(~np.isfinite(t))
    if nonfinite.size:
        i = int(nonfinite[0])
        raise InputError(path, f"non-finite time {float(t[i])!r}" + ("" if lines is not None else f" at sample {i}"), where(i))

    report = InputReport()
    if n == 0:
        return PolicyResult(np.arange(0, dtype=np.int64), report, t)

    if policy == "error":
        bad = np.flatnonzero(np.diff(t) <= 0.0)
        if bad.size:
            i = int(bad[0]) + 1
            kind = "duplicate timestamp" if t[i] == t[i - 1] else "backward timestamp"
            at = "" if lines is not None else f" at sample {i}"
            raise InputError(
                path, f"{kind}{at}: t = {float(t[i])!r} s after t = {float(t[i - 1])!r} s (timestamp policy 'error')", where(i)
            )
        return PolicyResult(np.arange(n, dtype=np.int64), report, t)

    spikes = timestamp_spikes(t)
    if spikes.size:
        first = int(spikes[0])
        at = f"line {where(first)}" if lines is not None else f"sample {first}"
        report.warn(f"{Path(path).name}: dropped {spikes.size} sample(s) whose time leaps far from both "
                    f"neighbours (the first at {at}, t = {float(t[first]):.6g} s)")
        report.dropped_samples += int(spikes.size)
    valid = np.ones(n, dtype=bool)
    valid[spikes] = False

    ok = np.flatnonzero(valid)
    at_reset = clock_resets(t[ok])  # among the valid samples: a corrupt stamp is no restart
    resets, before = ok[at_reset], ok[at_reset - 1]
    if resets.size and policy == "unwrap":
        first, last = int(resets[0]), int(before[0])
        at = f"line {where(first)}" if lines is not None else f"sample {first}"
        report.warn(f"{Path(path).name}: the clock restarts {resets.size} time(s) (the first at {at}, t = "
                    f"{float(t[last]):.6g} → {float(t[first]):.6g} s); joined on one clock (timestamp policy "
                    "'unwrap')")
        report.notes.append(f"unwrapped {resets.size} clock reset(s) (timestamp policy 'unwrap')")
        t = _unwrapped(t, resets, before)
        policy = "drop"
    elif resets.size:
        first, last = int(resets[0]), int(before[0])
        at = "" if lines is not None else f" at sample {first}"
        raise InputError(path, f"the clock restarts{at}: t = {float(t[first]):.6g} s after t = {float(t[last]):.6g} s, "
                               f"and {t.size - first} samples follow (a counter that wrapped or was reset, or a second "
                               f"recording appended); timestamp policy {policy!r} would "
                               f"{'drop them' if policy == 'drop' else 'mix the two clocks'}: set timestamp_policy: "
                               "unwrap to join them, or split the file there", where(first))

    if policy == "drop":
        # The max over kept samples before i equals the max over all samples before i.
        tv = np.where(valid, t, -np.inf)
        prev_max = np.empty(n)
        prev_max[0] = -np.inf
        np.maximum.accumulate(tv[:-1], out=prev_max[1:])
        kept = np.flatnonzero(valid & (t > prev_max)).astype(np.int64)
        dropped = int(valid.sum()) - kept.size
        report.dropped_samples += dropped
        if dropped:
            report.notes.append(f"dropped {dropped} samples with non-increasing time (timestamp policy 'drop')")
        return PolicyResult(kept, report, t if kept.size == n else t[kept])  # nothing dropped: no copy

    # sort
    order = np.flatnonzero(valid)[np.argsort(t[valid], kind="stable")].astype(np.int64)
    moved = int(np.count_nonzero(order != np.flatnonzero(valid)))
    ts = t[order]
    keep = np.ones(order.size, dtype=bool)
    keep[1:] = ts[1:] > ts[:-1]
    kept = order[keep]
    dropped = order.size - kept.size
    report.reordered_samples = moved
    report.dropped_samples += dropped
    if moved:
        report.notes.append(f"reordered {moved} samples to restore time order (timestamp policy 'sort')")
    if dropped:
        report.notes.append(f"dropped {dropped} samples with duplicate time (timestamp policy 'sort')")
    return PolicyResult(kept, report, t[kept])


SPIKE_FACTOR = 1000.0
"""A time step this many median steps long, undone by the next one, is a spike (a corrupt stamp)."""


def timestamp_spikes(t: np.ndarray) -> np.ndarray:
    """Indices of samples whose time leaps far from both neighbours — more than
    :data:`SPIKE_FACTOR` median steps after the previous sample and before the next one,
    or the reverse — a corrupt stamp (such as 1e30) that a policy would otherwise take for
    the new time base, dropping everything after it. The first and last samples are judged
    by their one neighbour only when the leap is also far beyond the record's time values."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return np.empty(0, dtype=np.int64)
    dt = np.diff(t)
    positive = dt[dt > 0]
    if positive.size == 0:
        return np.empty(0, dtype=np.int64)
    leap = SPIKE_FACTOR * float(np.median(positive))
    before = np.concatenate([[0.0], dt])  # t[i] − t[i−1]
    after = np.concatenate([dt, [0.0]])   # t[i+1] − t[i]
    spike = ((before > leap) & (after < -leap)) | ((before < -leap) & (after > leap))
    far = max(leap, 1e3 * (abs(float(np.median(t))) + leap))
    spike[0] = abs(after[0]) > far
    spike[-1] = abs(before[-1]) > far
    return np.flatnonzero(spike).astype(np.int64)


def check_time_source(path: str | Path, time_column: str | None, time_scale: float, rate_hz: float | None) -> None:
    if (time_column is None) == (rate_hz is None):
        raise InputError(path, "give exactly one of time_column and rate_hz")
    if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0):
        raise InputError(path, f"rate_hz must be a positive finite number, got {rate_hz!r}")
    if not (math.isfinite(time_scale) and time_scale > 0):
        raise InputError(path, f"time_scale must be a positive finite number, got {time_scale!r}")


def sample_times(
    arrays: dict[str, np.ndarray], n: int, time_column: str | None, time_scale: float, rate_hz: float | None
) -> np.ndarray:
    if time_column is not None:
        return arrays[time_column] if time_scale == 1.0 else arrays[time_column] * time_scale
    assert rate_hz is not None
    return np.arange(n, dtype=np.float64) / rate_hz
