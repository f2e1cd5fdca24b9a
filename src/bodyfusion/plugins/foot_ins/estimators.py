"""The foot INS's estimators, one class per ``filter.kind``, chosen once when the system is built.

Each holds the nominal state ``x`` (16,) and the error-state covariance ``P`` and knows how to
process a chunk of samples, take a closed-loop correction from the fuser and apply a position
fix; :class:`~bodyfusion.plugins.foot_ins.system.FootIns` owns the data, the history, the gap
policy and the record the smoothers rebuild from, and never asks which kind it runs.

* :class:`ErrorStateEkf` (``ekf``): the 15-state error-state EKF, compiled per-sample loop
  (:func:`~bodyfusion.plugins.foot_ins.kernels.run_foot_ins`) with the gated ZUPT.
* :class:`ColouredEkf` (``ckf``): the same with the zero-velocity update under coloured noise
  ([Xu2024] eqs. 5–18); the smoothers rebuild ordinary ZUPTs with σ_ξ, so it keeps its
  covariance after every stance update for them.
* :class:`EnsembleEkf` (``enekf``, ``cenekf``): M members carrying the attitude quaternion
  ([Deng2026] eqs. 1–19); ``x`` is their mean, ``P`` the sample covariance of their error-state
  deviations (15, or 18 with the coloured noise δV). Not smoothable, no error-state transition
  for the fuser's cross-covariances.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from bodyfusion.nav.error_state import FilterParams
from bodyfusion.base.forking import Forked, fork_is_safe
from bodyfusion.base.records import GrowingArray
from bodyfusion.nav.kalman import inv3_sym
from bodyfusion.nav.measurements import GateCounts, position_fix_update
from bodyfusion.nav.strapdown import NOMINAL_SIZE
from bodyfusion.plugins.foot_ins.config import COLOURED_KINDS, FootFilterConfig
from bodyfusion.plugins.foot_ins.ensemble import Ensemble
from bodyfusion.plugins.foot_ins.kernels import C_CALL_RECORDS, NO_RESET, run_foot_ins, run_foot_ins_coloured, set_state
from bodyfusion.plugins.foot_ins.records import FilterHistory, FilterState, ImuSamples, RtsRecord, no_record


@dataclass
class RunData:
    """What every estimator reads and writes: the samples (t s, specific force m/s^2, rate
    rad/s, stance flags), the filter parameters, the per-sample history rows it fills
    (nominal state; position covariance: variances east, north, up and the east–north
    covariance, m²; the stance update's NIS, :data:`~bodyfusion.plugins.foot_ins.kernels.NO_STANCE`
    where there is none: at swing samples, and at every sample of the ensemble kinds, which keep
    no NIS), the counters, the covariances it leaves
    outside the plain EKF recursion (sample index, covariance) for the smoothers, and the
    kept corrections (sample index, nominal state before the correction): those derived from
    other systems' estimates, which the smoothers keep as the filter made them; ``record``: the
    arrays the ekf records the whole-run RTS's sweep into as it runs
    (:func:`~bodyfusion.plugins.foot_ins.kernels.run_foot_ins`;
    :func:`~bodyfusion.plugins.foot_ins.kernels.no_record`: none)."""

    t: np.ndarray
    acc_b: np.ndarray
    gyro_b: np.ndarray
    stance: np.ndarray
    params: FilterParams
    hist_x: np.ndarray
    hist_cov: np.ndarray
    hist_nis: np.ndarray
    counters: np.ndarray
    override_idx: list[np.ndarray] = field(default_factory=list)
    override_P: list[np.ndarray] = field(default_factory=list)
    kept_idx: GrowingArray = field(default_factory=lambda: GrowingArray((), np.int64))
    kept_x: GrowingArray = field(default_factory=lambda: GrowingArray((NOMINAL_SIZE,)))
    record: RtsRecord = field(default_factory=no_record)

    def samples(self) -> ImuSamples:
        """The samples the kernels step through."""
        return ImuSamples(self.t, self.acc_b, self.gyro_b, self.stance)

    def history(self) -> FilterHistory:
        """The rows the kernels fill."""
        return FilterHistory(self.hist_x, self.hist_cov, self.hist_nis, self.counters)


class Estimator:
    """A foot INS estimator: state ``x`` (16,), covariance ``P`` (n, n)."""

    smoothable: ClassVar[bool] = True
    """The smoothers can rebuild its covariances (the 15-state EKF recursion)."""
    tracks_transition: ClassVar[bool] = True
    """It can accumulate the error-state transition Φ for the fuser's cross-covariances."""

    def __init__(self, x0: np.ndarray, P0: np.ndarray, cfg: FootFilterConfig, seed: int, name: str) -> None:
        self.x = x0.copy()
        self.P = P0.copy()
        self.cfg = cfg
        self.mech_memory = np.zeros(6)

    def run(self, data: RunData, i0: int, i1: int, phi: np.ndarray) -> None:
        """Process samples i0 ≤ i < i1; ``phi`` accumulates the transition ((0, 0): off)."""
        run_foot_ins(FilterState(self.x, self.P, self.mech_memory, phi), data.samples(), i0, i1, data.params,
                     data.history(), data.record)

    def reset_and_record(self, dx: np.ndarray, P: np.ndarray, data: RunData, i: int, packed: np.ndarray) -> bool:
        """Closed-loop reset: inject dx (n,) into the nominal state, take ½ (P + Pᵀ) (n, n); then
        record the state as sample i's and pack the covariance into ``packed`` unless it is empty
        (:func:`~bodyfusion.plugins.foot_ins.kernels.set_state`, one compiled call; dx, P as
        :data:`~bodyfusion.plugins.foot_ins.kernels.NO_RESET`: record the state as it is). Returns
        whether the covariance is exactly symmetric."""
        return set_state(self.x, self.P, np.ascontiguousarray(dx, dtype=np.float64),
                         np.ascontiguousarray(P, dtype=np.float64), i, data.hist_x, data.hist_cov, packed)

    def position_fix(self, z_n: np.ndarray, sigma_m: float, gate: float, counts: GateCounts,
                     phi: np.ndarray) -> None:
        """Gated absolute position fix (ENU, m; σ per axis; chi-square ``gate``, 3 dof)."""
        position_fix_update(self.x, self.P, z_n, sigma_m, gate, counts, phi)


class ErrorStateEkf(Estimator):
    """``ekf``: the 15-state error-state EKF."""


class ColouredEkf(Estimator):
    """``ckf``: the EKF with the zero-velocity update under coloured noise of colour factor
    ``filter.colour_factor``; records the covariance after each stance update."""

    def run(self, data: RunData, i0: int, i1: int, phi: np.ndarray) -> None:
        bound = int(np.count_nonzero(data.stance[i0:i1]))
        post_idx, post_P = np.empty(bound, dtype=np.int64), np.empty((bound, 15, 15))
        run_foot_ins_coloured(FilterState(self.x, self.P, self.mech_memory, phi), data.samples(), i0, i1, data.params,
                              self.cfg.colour_factor, data.history(), post_idx, post_P)
        k = int(data.counters[C_CALL_RECORDS])
        if k:  # the smoother rebuilds ZUPTs with σ_ξ: it takes the ckf's covariances here
            data.override_idx.append(post_idx[:k])
            data.override_P.append(post_P[:k])


class EnsembleEkf(Estimator):
    """``enekf``, ``cenekf``: the ensemble filter (:class:`~bodyfusion.plugins.foot_ins.ensemble.Ensemble`),
    its members drawn from the run's seed; corrections move the mean and map the deviations
    so that their sample covariance is the one given."""

    smoothable = False
    tracks_transition = False

    def __init__(self, x0: np.ndarray, P0: np.ndarray, cfg: FootFilterConfig, seed: int, name: str) -> None:
        super().__init__(x0, P0, cfg, seed, name)
        alpha = cfg.colour_factor if cfg.kind in COLOURED_KINDS else None
        self.ensemble = Ensemble(cfg.members, x0, P0, alpha, cfg.zupt_sigma_mps, seed, name)
        self._sync()

    def _sync(self) -> None:
        self.x = self.ensemble.mean[:NOMINAL_SIZE].copy()
        self.P = self.ensemble.covariance()

    def run(self, data: RunData, i0: int, i1: int, phi: np.ndarray) -> None:
        self.ensemble.run(data.samples(), i0, i1, data.params, data.history())
        self._sync()

    def reset_and_record(self, dx: np.ndarray, P: np.ndarray, data: RunData, i: int, packed: np.ndarray) -> bool:
        if dx.shape[0] > 0:
            self._correct(dx, P)
        return super().reset_and_record(*NO_RESET, data, i, packed)

    def _correct(self, dx: np.ndarray, P: np.ndarray) -> None:
        """Move the mean by dx (n,) and map the deviations to the covariance ½ (P + Pᵀ) (n, n)."""
        P = 0.5 * (P + P.T)
        self.ensemble.correct(np.asarray(dx, dtype=np.float64), P)
        self.x = self.ensemble.mean[:NOMINAL_SIZE].copy()
        self.P = P

    def position_fix(self, z_n: np.ndarray, sigma_m: float, gate: float, counts: GateCounts,
                     phi: np.ndarray) -> None:
        """The Kalman update of the mean and the sample covariance (H selects δp), gated,
        carried to the members by :meth:`_correct`."""
        y = z_n - self.x[0:3]
        r_var = sigma_m**2
        P = self.P
        S = P[0:3, 0:3] + r_var * np.eye(3)
        if float(y @ inv3_sym(np.ascontiguousarray(S)) @ y) > gate:
            counts.rejected += 1
            return
        K = np.linalg.solve(S, P[0:3, :]).T
        IKH = np.eye(P.shape[0])
        IKH[:, 0:3] -= K
        self._correct(K @ y, IKH @ P @ IKH.T + r_var * K @ K.T)
        counts.accepted += 1


ESTIMATORS: dict[str, type[Estimator]] = {"ekf": ErrorStateEkf, "ckf": ColouredEkf, "enekf": EnsembleEkf,
                                          "cenekf": EnsembleEkf}
"""``filter.kind`` → its estimator class."""


def compile_step(estimator: Estimator, data: RunData, phi: np.ndarray) -> None:
    """Compile ``estimator``'s step for these arguments' types: :meth:`Estimator.run` over at
    most one sample (it moves the state: for a copy, or a system that restarts afterwards)."""
    estimator.run(data, 1, min(2, len(data.t)), phi)


def compile_step_ahead(estimator: Estimator, data: RunData, phi: np.ndarray,
                       compiling_ahead: dict[str, Forked] | None) -> None:
    """On a first run (``compiling_ahead``: the run's
    :attr:`~bodyfusion.core.system.LayoutContext.compiling_ahead`), fork the process compiling
    ``estimator``'s step (:func:`compile_step`, on the copy's memory): the run's first foot of
    its class does, before compiling its reset (``set_state``, ~3 s of an ~12 s first run); the
    run waits for it before anything advances. Nothing on any other run, or where forking is not
    safe (the step is never taken here: it moves the state)."""
    key = f"foot_ins.{type(estimator).__name__}.run"
    if compiling_ahead is not None and key not in compiling_ahead and fork_is_safe():
        compiling_ahead[key] = Forked(lambda: compile_step(estimator, data, phi))
