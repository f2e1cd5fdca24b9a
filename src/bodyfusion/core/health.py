"""Covariance checks while the fuser runs: each system seen through a :class:`CovarianceMonitor`.

The fuser drives a system with ``advance`` and ``apply_correction`` at its sync epochs; the
monitor passes every call on and checks the covariance the system holds (symmetric, positive
semi-definite: :class:`bodyfusion.nav.filter_health.CovarianceHealth`, kept in the
system's ``covariance_health`` for :meth:`~bodyfusion.core.system.SensorSystem.health`) after
every correction — the fuser's updates are where a covariance can lose its definiteness from
outside the system — and, while it propagates, at its own sync times at most one per
:data:`STRIDE_S` and at its end: every system is checked at least about once a second. An
advance is split at those times; splitting there changes nothing (the plugin contract asks that
advancing in chunks at sync times gives the same bits, and the fuser itself syncs there).
Checks are buffered and made in batches (:meth:`~bodyfusion.nav.filter_health.CovarianceHealth.add_many`:
compiled elementwise tests, and eigenvalue decompositions only of the covariances a Cholesky
factorisation cannot certify above the smallest eigenvalue seen).
"""

from __future__ import annotations

import inspect
import math

import numpy as np

from bodyfusion.core.system import SensorSystem

STRIDE_S = 1.0
"""Least time (s) between the extra checks inside one long advance."""
BATCH = 256
"""Covariances buffered before they are checked together."""


def stride_times(sync_times: np.ndarray, stride_s: float) -> np.ndarray:
    """The sync times (s) kept for the checks: the first, then each first one at least
    ``stride_s`` after the last kept."""
    kept: list[float] = []
    for t in np.unique(np.asarray(sync_times, dtype=float)):
        if not kept or t >= kept[-1] + stride_s:
            kept.append(float(t))
    return np.asarray(kept)


class CovarianceMonitor:
    """``system`` as the fuser sees it: every attribute is the system's own, and after each
    ``advance`` and ``apply_correction`` its covariance is checked. Call :meth:`flush` once
    the fuser is done."""

    def __init__(self, system: SensorSystem, stride_s: float = STRIDE_S) -> None:
        self.monitored = system
        self._stride_s = stride_s
        self._stride_t: list[float] = []
        self._known = -math.inf  # the stride times up to here are known (s)
        self._t_end = math.inf  # s, once the system's data are all decided; the fuser asks at every epoch
        self._next = 0  # index of the first stride time after the system's time
        self._learn()
        self._t = np.empty(BATCH)  # the buffered checks' times (s) ...
        self._covs: np.ndarray | None = None  # ... and covariances (BATCH, n, n), from the first check
        self._n = 0  # checks buffered

    def __getattr__(self, name: str):
        value = getattr(self.monitored, name)
        if inspect.ismethod(value):  # the system's bound method: looked up once (the fuser calls them per epoch)
            self.__dict__[name] = value
        return value

    def _learn(self) -> None:
        """The stride times among the sync times the system decided since the last call (all of
        them at once for a system whose data are in hand), and its end once known."""
        decided = self.monitored.decided_until()
        if decided <= self._known:
            return
        times = np.asarray(self.monitored.sync_times(), dtype=float)
        new = times[(times > self._known) & (times <= decided)]
        if self._stride_t:
            new = new[new >= self._stride_t[-1] + self._stride_s]
        self._stride_t += stride_times(new, self._stride_s).tolist()
        self._known = decided
        if not math.isfinite(decided):
            self._t_end = self.monitored.t_end

    def forget_passed(self) -> None:
        """Drop the stride times the system has passed (a live run that keeps a bounded history,
        as its system forgets: :meth:`~bodyfusion.core.capabilities.Streaming.forget_before`)."""
        del self._stride_t[:self._next]
        self._next = 0

    def advance(self, t: float) -> None:
        """The system's ``advance(t)``, split and checked at the stride times up to t, and checked
        at t when t is one of them or the system's end."""
        if t > self._known:
            self._learn()
        s, stride = self.monitored, self._stride_t
        at_stride = False
        while self._next < len(stride) and stride[self._next] <= t:
            ts = stride[self._next]
            self._next += 1
            if ts <= s.t_now:  # passed before (the system advanced on its own)
                continue
            if ts < t:
                s.advance(ts)
                self._check()
            else:
                at_stride = True
        s.advance(t)
        if at_stride or t >= self._t_end:
            self._check()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """The system's ``apply_correction(dx, P)``, then a check."""
        self.monitored.apply_correction(dx, P)
        self._check()

    def apply_relative_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        """The system's ``apply_relative_correction(dx, P)``, then a check."""
        self.monitored.apply_relative_correction(dx, P)
        self._check()

    def _check(self) -> None:
        P = self.monitored.covariance()
        if self._covs is None:
            self._covs = np.empty((BATCH, *P.shape))
        k = self._n
        self._t[k] = self.monitored.t_now
        self._covs[k] = P
        self._n = k + 1
        if self._n == BATCH:
            self.flush()

    def flush(self) -> None:
        """Check the buffered covariances into the system's ``covariance_health``."""
        if self._n:
            self.monitored.covariance_health.add_many(self._covs[:self._n], self._t[:self._n])
        self._n = 0
