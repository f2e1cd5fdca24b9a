"""Sensor saturation: readings clipped at the end of an inertial sensor's range, found and repaired.

A foot's swing turns it faster than many gyroscopes measure (a walking swing peaks at
5–10 rad/s, a running swing at 10–20 rad/s; full scales of ±300 to ±1000 °/s are common),
and a heel strike can exceed a small accelerometer range. A clipped sample under-reads the
rotation or the acceleration, and strapdown integrates the shortfall into an attitude error
at every stride.

Detection (:func:`find_clipping`), per axis and sign, from the recording alone. Samples within
:data:`RAIL_TOLERANCE` of the axis's extreme reading form candidate runs. A run is *clipped*
when the signal's flanks say it went beyond the level it was read at: the cubic through the
:data:`FIT_SAMPLES` unclipped samples on each side of the run (least squares) rises above the
level by more than :data:`MIN_EXCESS` of it inside the run. A natural peak is reproduced by
its flanks (its top sample is the peak); a rail is not (the flanks are still steep where the
readings go flat). The side of the axis is saturated when at least :data:`MIN_CLIPPED_RUNS`
runs are clipped: one excursion could be a fluke, a rail is met again and again.

Repair (:meth:`Clipping.repaired`): each clipped run is replaced by that cubic (never below the
rail: the sensor read its end of range, so the truth is beyond it). The reconstruction is a
guess; :attr:`ClippedRun.excess_integral` (the repaired area beyond the rail, signal unit × s)
lets a filter add its uncertainty: for a gyroscope, an attitude error of a fraction of that
angle (:data:`REPAIR_UNCERTAINTY`).

Units: whatever the signal's (m/s^2 or rad/s); times in seconds.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

RAIL_TOLERANCE = 0.005
"""Readings within this fraction of an axis's extreme value are candidates for its rail."""
FITS_KEPT = 4096
"""Flank fits :func:`_cubic_through` keeps."""
FIT_SAMPLES = 4
"""Unclipped samples on each side of a run that its cubic is fitted to."""
MIN_EXCESS = 0.02
"""A run is clipped when its flanks' cubic exceeds the level by this fraction of it."""
MIN_CLIPPED_RUNS = 3
"""Clipped runs on one side of an axis that make it saturated there."""
REPAIR_UNCERTAINTY = 0.5
"""One-sigma error of a repair, as a fraction of the repaired area beyond the rail."""


@dataclass(frozen=True)
class ClippedRun:
    """Samples [start, stop) of one axis read at its rail; ``values``: their repair (the flanks'
    cubic, never inside the rail); ``excess_integral``: its area beyond the rail (signal unit × s)."""

    axis: int
    start: int
    stop: int
    excess_integral: float
    values: np.ndarray = field(repr=False, compare=False)


@dataclass
class Clipping:
    """What was found in an (N, 3) signal: the rail of each axis and side (signal units; NaN
    where none) and the clipped runs, in time order."""

    rail: np.ndarray = field(default_factory=lambda: np.full((3, 2), np.nan))
    """(3, 2): the level of each axis's negative and positive rail; NaN: no rail."""
    runs: list[ClippedRun] = field(default_factory=list)

    @property
    def samples(self) -> int:
        """Samples with at least one clipped axis."""
        mask = np.zeros(max((r.stop for r in self.runs), default=0), dtype=bool)
        for r in self.runs:
            mask[r.start:r.stop] = True
        return int(mask.sum())

    def describe(self, name: str, unit: str) -> str:
        """One line: which axes were clipped where, on how many samples, and what their flanks say
        was lost."""
        rails = [f"{'xyz'[a]} at {'−+'[s]}{self.rail[a, s]:.4g} {unit}"
                 for a in range(3) for s in range(2) if np.isfinite(self.rail[a, s])]
        worst = max((r.excess_integral for r in self.runs), default=0.0)
        return (f"{name} saturated ({', '.join(rails)}): {len(self.runs)} clipped runs, {self.samples} samples; "
                f"their flanks say up to {worst:.3g} {unit}·s was lost beyond the range in one run")

    def repaired(self, signal: np.ndarray) -> np.ndarray:
        """A copy of ``signal`` (N, 3), the signal this was found in, with every clipped run
        replaced by its repair."""
        out = np.array(signal, dtype=float)
        for run in self.runs:
            out[run.start:run.stop, run.axis] = run.values
        return out

    def to_dict(self) -> dict:
        """Plain-JSON summary for metrics.json."""
        return {"rail": [[None if not np.isfinite(v) else float(v) for v in side] for side in self.rail],
                "clipped_runs": len(self.runs), "clipped_samples": self.samples,
                "repaired_excess_max": max((r.excess_integral for r in self.runs), default=0.0)}


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and exclusive end indices of the True runs of a 1-D bool array."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


class _Flanks:
    """The flanks of every candidate run [starts[r], stops[r]) of ``x``: the unexcluded samples
    within :data:`FIT_SAMPLES` before and after each (in that order), found for all runs at once;
    :meth:`cubic` fits one run's."""

    def __init__(self, x: np.ndarray, starts: np.ndarray, stops: np.ndarray, excluded: np.ndarray) -> None:
        k = np.arange(FIT_SAMPLES)
        idx = np.concatenate([starts[:, None] - FIT_SAMPLES + k, stops[:, None] + k], axis=1)
        inside = np.clip(idx, 0, x.size - 1)
        self.usable = (idx >= 0) & (idx < x.size) & ~excluded[inside]
        self.count = self.usable.sum(axis=1)
        self.offsets = idx - 0.5 * (starts + stops - 1)[:, None]  # from each run's centre
        self.values = x[inside]
        self.lengths = stops - starts

    def cubic(self, r: int) -> np.ndarray | None:
        """The least-squares cubic through run r's flank samples, evaluated on the run; None
        without 4 of them."""
        if self.count[r] < 4:
            return None
        use = self.usable[r]
        return _cubic_through(self.offsets[r][use].tobytes(), self.values[r][use].tobytes(),
                              int(self.lengths[r])).copy()


@functools.lru_cache(maxsize=FITS_KEPT)
def _cubic_through(offsets: bytes, values: bytes, length: int) -> np.ndarray:
    """The least-squares cubic through the float64 points (``offsets``, ``values``), evaluated
    at the run's ``length`` samples centred on offset 0. Cached: a live run derives the same
    runs' flanks on every pass (:mod:`bodyfusion.plugins.foot_ins.streaming`), the same bits."""
    coef = np.polyfit(np.frombuffer(offsets), np.frombuffer(values), 3)
    return np.polyval(coef, np.arange(length) - 0.5 * (length - 1))


def find_clipping(signal: np.ndarray, dt: float) -> Clipping:
    """The rails and clipped runs of ``signal`` (N, 3) sampled every ``dt`` s, each run with its
    repair (module docstring)."""
    x = np.asarray(signal, dtype=float)
    found = Clipping()
    if not x.size:
        return found
    # every side of every axis at once, axis by row (contiguous): its level, its candidate samples
    # and the runs they make; a side's own pass below only where they could make a rail
    # (−x ≥ L ⇔ x ≤ −L, exactly)
    xt = np.ascontiguousarray(x.T)
    levels = np.concatenate([-xt.min(axis=1), xt.max(axis=1)])  # row 3·side + axis
    candidates = np.concatenate([xt <= -(levels[:3] * (1.0 - RAIL_TOLERANCE))[:, None],
                                 xt >= (levels[3:] * (1.0 - RAIL_TOLERANCE))[:, None]])
    run_counts = candidates[:, 0] + np.count_nonzero(candidates[:, 1:] & ~candidates[:, :-1], axis=1)
    for axis in range(3):
        for side, sign in ((0, -1.0), (1, 1.0)):
            row = 3 * side + axis
            level = float(levels[row])
            if not level > 0.0 or run_counts[row] < MIN_CLIPPED_RUNS:  # too few runs to make a rail
                continue
            col = sign * x[:, axis]
            candidate = candidates[row]
            starts, stops = _runs(candidate)
            flanks = _Flanks(col, starts, stops, candidate)
            clipped = []
            for k, (a, b) in enumerate(zip(starts, stops)):
                if len(clipped) + starts.size - k < MIN_CLIPPED_RUNS:  # too few runs left to make a rail
                    break
                fit = flanks.cubic(k)
                if fit is not None and fit.max() > level * (1.0 + MIN_EXCESS):
                    beyond = np.maximum(fit, level)
                    clipped.append(ClippedRun(axis, int(a), int(b), float(np.sum(beyond - level) * dt), sign * beyond))
            if len(clipped) >= MIN_CLIPPED_RUNS:
                found.rail[axis, side] = level
                found.runs += clipped
    found.runs.sort(key=lambda run: (run.start, run.axis))
    return found
