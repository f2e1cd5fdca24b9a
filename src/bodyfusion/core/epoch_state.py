"""What a live run emits at each output epoch: every navigation system's state with its
uncertainty, and what the fuser did since the epoch before.

The fuser (:class:`~bodyfusion.core.fuser.Fuser`) takes an output epoch after every other
event of its time: each navigation system is advanced to the epoch (its state then refers to
its last sample at or before it), read, and the :class:`EpochState` handed to every sink
(:class:`EpochSink`: :mod:`bodyfusion.live.sinks` writes JSON lines, CSV, Parquet and MCAP).
Advancing a system to an output epoch changes none of its bits: a system advanced in any
chunks gives the run it gives in one (the plugin contract), and the fuser's cross-covariances
are carried only at its own events.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from bodyfusion.core.system import SensorSystem


HEALTH_COUNTS = ("constraint_epochs", "constraint_active", "measurements_rejected", "ties_rejected", "fights")
"""What an epoch's ``health`` counts since the epoch before."""


@dataclass(frozen=True)
class SystemState:
    """One navigation system at an output epoch: ``t`` (s) its state's time (its last sample at
    or before the epoch), ``position_n`` (3,) ENU m, ``position_sd_m`` (3,) one-sigma east,
    north, up (m) from its error-state covariance."""

    t: float
    position_n: np.ndarray
    position_sd_m: np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready: ``t``, ``east_m``, ``north_m``, ``up_m``, ``sd_east_m``, ``sd_north_m``, ``sd_up_m``."""
        e, n, u = (float(v) for v in self.position_n)
        se, sn, su = (float(v) for v in self.position_sd_m)
        return {"t": self.t, "east_m": e, "north_m": n, "up_m": u, "sd_east_m": se, "sd_north_m": sn, "sd_up_m": su}


@dataclass(frozen=True)
class EpochState:
    """The fused state at output epoch ``t`` (s): ``systems`` (name → :class:`SystemState`),
    ``health``: what the fuser did since the epoch before (``constraint_epochs``,
    ``constraint_active``, ``measurements_rejected``, ``ties_rejected``, ``fights``: counts), and
    ``wall_time``: when it was made (s, :func:`time.perf_counter`; for latency figures)."""

    t: float
    systems: Mapping[str, SystemState]
    health: Mapping[str, int]
    wall_time: float
    smoothed_lag_s: float | None = None
    """None: the filtered state, emitted as the fuser takes the epoch; else the fixed-lag
    smoothed state of the systems that smooth live, emitted once the data reach this lag (s) and
    the window's segment bounds beyond the epoch (:class:`SmoothedSamples`; no ``health``)."""

    def to_dict(self) -> dict:
        """JSON-ready: ``t``, ``systems`` (name → :meth:`SystemState.to_dict`), ``health``; a
        smoothed state also ``smoothed_lag_s``."""
        out = {"t": self.t, "systems": {name: s.to_dict() for name, s in self.systems.items()},
               "health": dict(self.health)}
        if self.smoothed_lag_s is not None:
            out["smoothed_lag_s"] = self.smoothed_lag_s
        return out


@dataclass(frozen=True)
class SmoothedSamples:
    """Smoothed samples of one system as a live smoother hands them on, in time order: ``t`` (k,)
    s (the samples' times), ``position_n`` (k, 3) ENU m, ``position_sd_m`` (k, 3) one-sigma east,
    north, up (m)."""

    t: np.ndarray
    position_n: np.ndarray
    position_sd_m: np.ndarray


class EpochSink(Protocol):
    """Where output epochs go: ``write`` each, ``close`` once at the end (a file complete)."""

    def write(self, state: EpochState) -> None: ...

    def close(self) -> None: ...


@dataclass
class EpochOutput:
    """Output epochs every ``interval_s`` (s) of data (at its multiples), written to ``sinks``;
    ``emitted``: epochs emitted so far."""

    interval_s: float
    sinks: Sequence[EpochSink] = ()
    emitted: int = 0
    smoothed_emitted: int = 0
    """Smoothed epochs emitted so far (:meth:`emit_smoothed`)."""
    totals: dict[str, int] = field(default_factory=lambda: dict.fromkeys(HEALTH_COUNTS, 0))
    """The fuser's counts (:data:`HEALTH_COUNTS`) at the last epoch emitted."""
    _closed: bool = False

    def emit(self, t: float, systems: Mapping[str, SensorSystem], report) -> EpochState:
        """Advance every system to ``t``, read it, and write the state to every sink. ``report``:
        the fuser's :class:`~bodyfusion.core.fuser.FuserReport` (its counts since the last epoch
        become the state's ``health``)."""
        states = {}
        for name, s in systems.items():
            s.advance(t)
            P = s.covariance()
            rows = s.position_indices
            sd = np.sqrt(np.maximum(np.diagonal(P)[rows], 0.0))
            states[name] = SystemState(float(s.t_now), s.position_n(), sd)
        state = EpochState(float(t), states, self._health(report), time.perf_counter())
        for sink in self.sinks:
            sink.write(state)
        self.emitted += 1
        return state

    def emit_smoothed(self, t: float, systems: Mapping[str, SystemState], lag_s: float) -> EpochState:
        """Write the smoothed state at epoch ``t`` (s) of ``systems`` (name → its smoothed
        :class:`SystemState`), smoothed with ``lag_s`` (s), to every sink."""
        state = EpochState(float(t), dict(systems), {}, time.perf_counter(), lag_s)
        for sink in self.sinks:
            sink.write(state)
        self.smoothed_emitted += 1
        return state

    def _health(self, report) -> dict[str, int]:
        """The fuser's counts since the epoch before."""
        now = {"constraint_epochs": report.epochs, "constraint_active": report.activations,
               "measurements_rejected": report.measurements_rejected, "ties_rejected": report.ties_rejected,
               "fights": len(report.limits.fights) if report.limits is not None else 0}
        out = {key: value - self.totals[key] for key, value in now.items()}
        self.totals = now
        return out

    def close(self) -> None:
        """Close every sink (once; later calls do nothing)."""
        if not self._closed:
            self._closed = True
            for sink in self.sinks:
                sink.close()
