"""A synthetic dead-reckoning system: [KFSC2015]'s §7.1 Monte-Carlo model.

The carrier moves at a constant velocity v_n (ENU, m/s) from ``start_m``. At each of
``rate_hz`` steps the system measures its position increment v_n dt plus white noise
of variance q (m² per axis), and integrates it; so its position error is a random
walk, P_{k+1} = P_k + q I. Its truth is known exactly (``truth_trajectory``), which
makes it a test bed for the fuser's constraints: two such systems held within d of
each other.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from bodyfusion.base.sections import StrictModel
from bodyfusion.base.seeding import system_seed
from bodyfusion.core.capabilities import TransitionTracking
from bodyfusion.core.system import CovarianceHistory, LayoutContext, SensorSystem
from bodyfusion.base.types import InputReport, Trajectory
from bodyfusion.nav.filter_health import CovarianceHealth


class RandomWalkConfig(StrictModel):
    """Velocity (ENU, m/s), start (ENU, m), step rate (Hz), duration (s), increment noise
    variance (m² per axis per step), initial position variance (m² per axis)."""

    plugin: Literal["random_walk"] = "random_walk"
    velocity_mps: tuple[float, float, float] = (1.0, 0.0, 0.0)
    start_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_hz: float = Field(default=100.0, gt=0)
    duration_s: float = Field(default=60.0, gt=0)
    increment_variance_m2: float = Field(default=0.05, ge=0)
    """Noise variance of each step's position increment, m² per axis."""
    initial_variance_m2: float = Field(default=0.0, ge=0)
    """Initial position variance, m² per axis."""


class RandomWalk(SensorSystem, TransitionTracking):
    """Position-only dead reckoning with white increment noise (error state: δp, 3)."""

    plugin_name = "random_walk"
    Config = RandomWalkConfig

    def __init__(self, name: str, config: RandomWalkConfig, context: LayoutContext) -> None:
        super().__init__(name, config, context)
        n = int(round(config.duration_s * config.rate_hz)) + 1
        self.t = np.arange(n) / config.rate_hz
        v = np.asarray(config.velocity_mps)
        self.truth_pos_n = np.asarray(config.start_m) + self.t[:, None] * v
        rng = np.random.default_rng(system_seed(context.seed, name))
        noise = rng.normal(0.0, np.sqrt(config.increment_variance_m2), (n - 1, 3))
        self.increments = np.diff(self.truth_pos_n, axis=0) + noise
        self.restart()

    def restart(self) -> None:
        n = len(self.t)
        self.x = np.asarray(self.config.start_m, dtype=float).copy()
        self.P = np.eye(3) * self.config.initial_variance_m2
        self.hist_pos = np.empty((n, 3))
        self.hist_cov = np.empty((n, 3, 3))
        self.hist_pos[0] = self.x
        self.hist_cov[0] = self.P
        self._i = 0

    @property
    def t_now(self) -> float:
        return float(self.t[self._i])

    def advance(self, t: float) -> None:
        i1 = int(np.searchsorted(self.t, t, side="right"))
        if i1 <= self._i + 1:
            return
        q = self.config.increment_variance_m2
        if i1 == self._i + 2:  # one step: the fuser's per-sample epochs
            self.x = self.x + self.increments[self._i]
            self.P = self.P + q * np.eye(3)
            self._i += 1
            self.hist_pos[self._i] = self.x
            self.hist_cov[self._i] = self.P
            return
        steps = np.arange(self._i + 1, i1)
        # accumulate in sample order from the current state, as the one-step path does
        self.hist_pos[steps] = np.cumsum(np.concatenate([self.x[None], self.increments[steps - 1]]), axis=0)[1:]
        self.hist_cov[steps] = np.cumsum(np.concatenate([self.P[None], np.broadcast_to(q * np.eye(3), (len(steps), 3, 3))]),
                                         axis=0)[1:]
        self.x = self.hist_pos[i1 - 1].copy()
        self.P = self.hist_cov[i1 - 1].copy()
        self._i = i1 - 1

    def position_n(self) -> np.ndarray:
        return self.x.copy()

    def covariance(self) -> np.ndarray:
        return self.P.copy()

    def apply_correction(self, dx: np.ndarray, P: np.ndarray) -> None:
        self.x = self.x + dx
        self.P = 0.5 * (P + P.T)
        self.hist_pos[self._i] = self.x
        self.hist_cov[self._i] = self.P

    def track_transition(self) -> None:
        """Nothing to accumulate: the error state (δp) carries over unchanged, Φ = I."""

    def transition_since_sync(self) -> np.ndarray:
        return np.eye(3)

    def sync_times(self) -> np.ndarray:
        return self.t[1:]

    def sample_times(self) -> np.ndarray:
        return self.t

    def trajectory(self) -> Trajectory:
        n = self._i + 1
        var = np.diagonal(self.hist_cov[:n], axis1=1, axis2=2)
        return Trajectory(self.t[:n], self.hist_pos[:n], np.sqrt(np.maximum(var, 0.0)))

    def covariance_history(self) -> CovarianceHistory:
        """The whole error-state (position) covariance at every sample."""
        n = self._i + 1
        return CovarianceHistory(self.t[:n], ("east_m", "north_m", "up_m"), self.hist_cov[:n].copy(),
                                 "the whole error-state (position) covariance at every sample (m^2)")

    def horizontal_nees(self) -> np.ndarray:
        """(N,) normalised estimation error squared of the horizontal position against the
        truth, eᵀ P_hh⁻¹ e; a consistent filter averages 2 (undefined where P_hh = 0: NaN)."""
        n = self._i + 1
        e = (self.hist_pos[:n] - self.truth_pos_n[:n])[:, :2]
        P = self.hist_cov[:n, :2, :2]
        det = P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            nees = (P[:, 1, 1] * e[:, 0] ** 2 - 2 * P[:, 0, 1] * e[:, 0] * e[:, 1] + P[:, 0, 0] * e[:, 1] ** 2) / det
        return np.where(det > 0, nees, np.nan)

    def truth_trajectory(self) -> Trajectory:
        return Trajectory(self.t, self.truth_pos_n, np.zeros_like(self.truth_pos_n))

    @property
    def samples(self) -> int:
        return len(self.t)

    @property
    def input_report(self) -> InputReport:
        return InputReport()

    def health(self) -> dict:
        """As :meth:`SensorSystem.health`, plus ``covariance_history``: the checks of the full
        position covariance recorded at every sample."""
        n = self._i + 1
        return {**super().health(),
                "covariance_history": {"block": "position, every sample",
                                       **CovarianceHealth.of(self.hist_cov[:n], self.t[:n]).to_dict()}}
