"""The ensemble estimator of the foot INS (``filter.kind: enekf | cenekf``; [Deng2026]).

The members (M, n_s) are propagated and analysed together by the compiled loop of
:mod:`bodyfusion.plugins.foot_ins.ensemble_kernels`. This module owns their set-up, their
random numbers and what the fuser sees of them:

* Estimate: the ensemble mean (paper eq. 18), a 16-value nominal state like the EKF's.
* Covariance: the sample covariance of the members' error-state deviations about the mean,
  [δp, δv, δθ, δb_a, δb_g] (15; δθ the rotation vector of q_j ⊗ q̄⁻¹ in the navigation
  frame, as the EKF's attitude error), and for the cenekf the coloured noise δV (18). So
  position is states 0:3 for the fuser, as for the EKF.
* Correction (the fuser's constraint): the mean moves by dx (closed-loop injection, as the
  EKF's) and the deviations D (M, n) are mapped by the linear transform
  A = Σ^{-1/2} (Σ^{1/2} P Σ^{1/2})^{1/2} Σ^{-1/2} (Σ the current sample covariance, P the
  fuser's): the symmetric map that takes Σ to A Σ Aᵀ = P with the least change of the
  members (a square-root ensemble update; computed in correlation coordinates). Every
  member moves consistently: member_j = (mean ⊕ dx) ⊕ (c + A d_j), d_j the centred
  deviations and c their mean (of second order, from the attitude). Exact when the members span
  the error space (M > n); with fewer members P is matched on their span only.

Random numbers: ``bodyfusion.base.seeding.system_seed(context.seed, name)`` spawns one stream for
the initial members (drawn from N(x₀, P₀) in error coordinates; cenekf: V from its
stationary N(0, σ_v²/(1 − α²))) and one for the process noise and the perturbed
observations, drawn per sample in time order, so the same seed gives the same bits
however the run is chunked.
"""

from __future__ import annotations

import numpy as np

from bodyfusion.nav.error_state import FilterParams, inject
from bodyfusion.plugins.foot_ins.records import FilterHistory, ImuSamples
from bodyfusion.base.seeding import system_seed
from bodyfusion.plugins.foot_ins.ensemble_kernels import (NOISE_WIDTH, NOMINAL, ensemble_covariance, ensemble_deviations,
                                                      ensemble_mean, place_members, run_ensemble)

NOISE_BLOCK = 1024
"""Samples of noise drawn at a time (bounds memory: 1024 × M × 21 floats)."""


def _sym_sqrt(S: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Symmetric square root (or pseudo-inverse square root) of a symmetric PSD matrix."""
    w, U = np.linalg.eigh(0.5 * (S + S.T))
    floor = 1e-13 * max(float(w.max()), 0.0)
    w = np.where(w > floor, w, 0.0)
    if inverse:
        w = np.where(w > 0, 1.0 / np.sqrt(np.where(w > 0, w, 1.0)), 0.0)
    else:
        w = np.sqrt(w)
    return (U * w) @ U.T


def covariance_transform(S: np.ndarray, P: np.ndarray) -> np.ndarray:
    """A (n, n) with A S Aᵀ = P, the symmetric (least-change) map, computed in the correlation
    coordinates of S (scales the error states' units away)."""
    sd = np.sqrt(np.maximum(np.diag(S), 0.0))
    sd = np.where(sd > 0, sd, 1.0)
    Sn = S / np.outer(sd, sd)
    Pn = P / np.outer(sd, sd)
    root = _sym_sqrt(Sn)
    inv_root = _sym_sqrt(Sn, inverse=True)
    An = inv_root @ _sym_sqrt(root @ Pn @ root) @ inv_root
    return (sd[:, None] * An) / sd[None, :]


class Ensemble:
    """M members of the foot INS with the seeded random streams (see the module docstring).

    ``x0`` (16,) and ``P0`` (15, 15): initial nominal state and covariance; ``alpha``: colour
    factor (None: enekf); ``sigma_v``: the ZUPT σ (m/s).
    """

    def __init__(self, members: int, x0: np.ndarray, P0: np.ndarray, alpha: float | None, sigma_v: float,
                 seed: int, name: str) -> None:
        self.members = members
        self.alpha = alpha
        self.size = NOMINAL + (3 if alpha is not None else 0)
        self.error_size = 15 + (3 if alpha is not None else 0)
        init_ss, self._noise_ss = system_seed(seed, name).spawn(2)
        rng = np.random.Generator(np.random.PCG64(init_ss))
        z = rng.standard_normal((members, self.error_size))
        sd = np.sqrt(np.diag(P0))
        if alpha is not None:
            sd = np.concatenate([sd, np.full(3, sigma_v / np.sqrt(1.0 - alpha**2))])
        mean = np.concatenate([x0, np.zeros(self.size - NOMINAL)])
        self.ens = np.empty((members, self.size))
        place_members(mean, np.ascontiguousarray(z * sd), self.ens)
        self.memory = np.zeros((members, 6))
        self._rng = np.random.Generator(np.random.PCG64(self._noise_ss))
        self.mean = np.empty(self.size)
        ensemble_mean(self.ens, self.mean)

    def run(self, samples: ImuSamples, i0: int, i1: int, params: FilterParams, history: FilterHistory) -> None:
        """Process samples i0 ≤ i < i1 (see :func:`run_ensemble`), noise drawn block by block."""
        alpha = -1.0 if self.alpha is None else float(self.alpha)
        for a in range(i0, i1, NOISE_BLOCK):
            b = min(a + NOISE_BLOCK, i1)
            noise = self._rng.standard_normal((b - a, self.members, NOISE_WIDTH))
            run_ensemble(self.ens, self.memory, samples, a, b, params, alpha, noise, self.mean, history)

    def covariance(self) -> np.ndarray:
        """Sample covariance (n, n) of the error-state deviations about the mean."""
        P = np.empty((self.error_size, self.error_size))
        ensemble_covariance(self.ens, self.mean, P)
        return P

    def correct(self, dx: np.ndarray, P: np.ndarray) -> None:
        """Move the mean by dx (n,) and map the deviations so the sample covariance is P."""
        D = np.empty((self.members, self.error_size))
        ensemble_deviations(self.ens, self.mean, D, False)
        c = D.mean(axis=0)
        D -= c
        S = D.T @ D / (self.members - 1)
        A = covariance_transform(S, P)
        mean = self.mean.copy()
        inject(mean, np.ascontiguousarray(dx[:15], dtype=np.float64))
        mean[NOMINAL:] += dx[15:]
        place_members(mean, np.ascontiguousarray(c + D @ A.T), self.ens)
        self.mean = mean
