"""A bank of heading hypotheses (Gaussian-sum filter) for a phone whose walking heading is unknown.

Why a bank. The PDR error model (eqs. 38–40) is linear in the heading error δψ only while
δψ is small: a step moves the position by S (sin ψ, cos ψ), and the linearisation
δE ≈ S cos ψ δψ is 3 % wrong at 15° but meaningless at 90°. A single extended Kalman
filter started with "heading unknown" (σ = 180°) therefore is not a filter at all: its
first position fixes rotate the track by an amount the linearisation invents. Instead the
circle is split into M sectors: hypothesis i starts at ψ_i = ψ_c + 2π i / M with
σ_ψ = π / M (half the spacing, where the linearisation holds), every other state equal.
Each runs the ordinary error-state filter; its weight is its likelihood of the evidence,

    w_i ← w_i · N(y_i; 0, S_i)       (y_i, S_i: that hypothesis' innovation and its covariance),

normalised over the bank. Together they are a Gaussian sum: mean and covariance by moment
matching (:func:`mixture_moments`; angles about the circular mean). Once the mixture's own
heading σ is below ``resolved_sd`` the sum is unimodal and narrow enough for one linearised
filter: the bank collapses into its moment-matched Gaussian (:func:`collapse_if_resolved`).

Why not fit the heading once. Rotating the PDR track onto the GNSS track over its first
metres (the former ``gnss_track``) needs the GNSS to move far compared with its error before
the filter may start: a log whose fixes never wander 15 m from the first could not run, and
one that starts standing took its heading from GNSS jitter. The bank starts at once, keeps
every heading the fixes allow, and resolves as soon as the walk makes one likely.

The same idea in PX4's EKF-GSF yaw estimator (a bank of yaw hypotheses weighted by GNSS
velocity); here the evidence is GNSS position and course, and the magnetometer's azimuth
when a holding offset prior makes it absolute, while the phone walks held steadily (the
plugin decides which updates weigh).

States are the plugin's nominal vector ``x`` and its error-state covariance ``P``; ``nominal``
maps nominal entries to error-state indices and ``angles`` lists nominal entries that are
angles (wrapped to (−π, π] when differenced).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from bodyfusion.core.heading import wrap_angle

PRUNE_WEIGHT = 1e-9
"""Hypotheses whose normalised weight falls below this are dropped."""


@dataclass
class Hypothesis:
    """One member of the bank: nominal state ``x``, error covariance ``P``, log-weight."""

    x: np.ndarray
    P: np.ndarray
    log_w: float = 0.0


def spread_headings(x: np.ndarray, P: np.ndarray, count: int, psi: int, dpsi: int) -> list[Hypothesis]:
    """``count`` hypotheses at headings x[psi] + 2π i / count (rad), each with heading variance
    (π / count)² at error index ``dpsi`` and everything else as (x, P); equal weights."""
    bank = []
    for i in range(count):
        xi, Pi = x.copy(), P.copy()
        xi[psi] = wrap_angle(x[psi] + 2.0 * np.pi * i / count)
        Pi[dpsi, :] = Pi[:, dpsi] = 0.0
        Pi[dpsi, dpsi] = (np.pi / count) ** 2
        bank.append(Hypothesis(xi, Pi, -np.log(count)))
    return bank


def normalise(bank: list[Hypothesis]) -> list[Hypothesis]:
    """Log-weights normalised to Σ w = 1, hypotheses below :data:`PRUNE_WEIGHT` dropped."""
    log_w = np.array([h.log_w for h in bank])
    log_w -= logsumexp(log_w)
    keep = np.flatnonzero(log_w >= np.log(PRUNE_WEIGHT))
    log_w = log_w[keep] - logsumexp(log_w[keep])
    return [Hypothesis(bank[k].x, bank[k].P, float(lw)) for k, lw in zip(keep, log_w)]


def mixture_moments(bank: list[Hypothesis], nominal: list[int], angles: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Mean x̄ (nominal; angles: circular weighted mean) and covariance
    P̄ = Σ w_i (P_i + d_i d_iᵀ), d_i the error-state offset of x_i from x̄ (angles wrapped)."""
    if len(bank) == 1:
        return bank[0].x.copy(), bank[0].P.copy()
    w = np.exp([h.log_w for h in bank])
    w /= w.sum()
    X = np.array([h.x for h in bank])
    mean = w @ X
    for a in angles:
        mean[a] = np.arctan2(w @ np.sin(X[:, a]), w @ np.cos(X[:, a]))
    P = np.zeros_like(bank[0].P)
    for wi, h in zip(w, bank):
        d = np.zeros(P.shape[0])
        diff = h.x - mean
        for a in angles:
            diff[a] = wrap_angle(diff[a])
        d[nominal] = diff
        P += wi * (h.P + np.outer(d, d))
    return mean, 0.5 * (P + P.T)


def collapse_if_resolved(bank: list[Hypothesis], nominal: list[int], angles: list[int], dpsi: int,
                         resolved_sd: float) -> list[Hypothesis]:
    """The bank, or its moment-matched single Gaussian once the mixture's heading σ (rad,
    error index ``dpsi``) is at most ``resolved_sd``."""
    if len(bank) == 1:
        return bank
    x, P = mixture_moments(bank, nominal, angles)
    if P[dpsi, dpsi] > resolved_sd**2:
        return bank
    return [Hypothesis(x, P, 0.0)]


def affine_map(P_from: np.ndarray, P_to: np.ndarray) -> np.ndarray:
    """T with T P_from Tᵀ = P_to for symmetric positive semi-definite P_from, P_to whose null
    spaces agree: T = P_to^{1/2} (P_from^{1/2})⁺ (symmetric square roots)."""
    def sqrt_and_pinv(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        val, vec = np.linalg.eigh(0.5 * (A + A.T))
        root = np.sqrt(np.clip(val, 0.0, None))
        inv = np.divide(1.0, root, out=np.zeros_like(root), where=root > 1e-12 * max(root.max(), 1e-300))
        return (vec * root) @ vec.T, (vec * inv) @ vec.T
    root_to, _ = sqrt_and_pinv(P_to)
    _, inv_from = sqrt_and_pinv(P_from)
    return root_to @ inv_from
