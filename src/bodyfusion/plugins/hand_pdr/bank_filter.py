"""The phone's error-state Kalman filter, run over the bank of heading hypotheses.

Every hypothesis (:mod:`bodyfusion.plugins.hand_pdr.hypotheses`) runs the same linear
error-state filter; the plugin gives the model (the transition F and noise Q of a time step
or a PDR step; H, R and the residual of a measurement) and the bank applies it to each one:

    P ← F P Fᵀ + Q;
    K = P Hᵀ S⁻¹, S = H P Hᵀ + R;  x ← x + K y (nominal entries: closed-loop reset);
    P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ (Joseph form).

An update is rejected when its innovation fails the chi-square gate of every hypothesis.
One that weighs the hypotheses adds log N(y; 0, S) to each log-weight; the weights are then
normalised and pruned, and the bank collapses into one filter once its heading σ is small.

The fuser. While the bank is open the fuser sees the mixture's moments, a correction maps
every hypothesis through the affine map that takes the mixture to the corrected Gaussian,
and the transition Φ is 0 (the fuser's cross-covariances with this system are dropped);
with one filter Φ collects the filter's F and I − K H since the fuser's last sync.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from bodyfusion.core.heading import wrap_angle
from bodyfusion.plugins.hand_pdr.hypotheses import (Hypothesis, affine_map, collapse_if_resolved, mixture_moments,
                                                    normalise, spread_headings)


class BankFilter:
    """The ``hypotheses`` (iterate them; ``len``: 1 for one filter) with ``nominal`` and
    ``angles`` as in :func:`~bodyfusion.plugins.hand_pdr.hypotheses.mixture_moments`,
    ``heading`` the heading's nominal entry (its error-state index ``nominal[heading]``) and
    ``resolved_sd`` (rad) the heading σ at which an open bank collapses; ``phi``: the fuser's
    transition Φ since its last sync (None: not tracked)."""

    def __init__(self, hypotheses: list[Hypothesis], nominal: list[int], angles: list[int], heading: int,
                 resolved_sd: float) -> None:
        self.hypotheses = hypotheses
        self.nominal = nominal
        self.angles = angles
        self.heading = heading
        self.resolved_sd = resolved_sd
        self.n_err = hypotheses[0].P.shape[0]
        self.phi: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.hypotheses)

    def __iter__(self) -> Iterator[Hypothesis]:
        return iter(self.hypotheses)

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Nominal state and error-state covariance (the mixture's, moment-matched, while open)."""
        return mixture_moments(self.hypotheses, self.nominal, self.angles)

    def spread(self, x: np.ndarray, P: np.ndarray, count: int) -> None:
        """Open the bank: ``count`` hypotheses round the circle from (x, P)
        (:func:`~bodyfusion.plugins.hand_pdr.hypotheses.spread_headings`); Φ = 0."""
        self.hypotheses = spread_headings(x, P, count, self.heading, self.nominal[self.heading])
        self.chain(np.zeros((self.n_err, self.n_err)))

    def transition(self, F: np.ndarray | list[np.ndarray], Q: np.ndarray | list[np.ndarray]) -> None:
        """P ← F P Fᵀ + Q for every hypothesis (F, Q one for all or one each; Q a full matrix
        or its diagonal); the fuser's Φ ← F Φ (one filter) or 0 (a bank)."""
        count = len(self.hypotheses)
        Fs = F if isinstance(F, list) else [F] * count
        Qs = Q if isinstance(Q, list) else [Q] * count
        for h, Fi, Qi in zip(self.hypotheses, Fs, Qs):
            h.P = Fi @ h.P @ Fi.T + (np.diag(Qi) if Qi.ndim == 1 else Qi)
            h.P = 0.5 * (h.P + h.P.T)
        self.chain(Fs[0])

    def chain(self, A: np.ndarray) -> None:
        """Φ ← A Φ when tracked; a bank has no linear transition: Φ = 0 (see the module docstring)."""
        if self.phi is not None:
            self.phi = A @ self.phi if len(self.hypotheses) == 1 else np.zeros_like(self.phi)

    def update(self, H: np.ndarray, residual: Callable[[np.ndarray], np.ndarray], R: np.ndarray, gate: float,
               weigh: bool) -> bool:
        """Gated Kalman update (Joseph form) of every hypothesis, closed-loop reset; y = residual(x).
        Rejected (False) when the innovation fails the chi-square gate of every hypothesis. With
        ``weigh`` the log-weights gain log N(y; 0, S) (see :mod:`~bodyfusion.plugins.hand_pdr.hypotheses`)."""
        ys = [residual(h.x) for h in self.hypotheses]
        Ss = [H @ h.P @ H.T + R for h in self.hypotheses]
        nis = [float(y @ np.linalg.solve(S_, y)) for y, S_ in zip(ys, Ss)]
        if min(nis) > gate:
            return False
        IKH = None
        for h, y, S_, q in zip(self.hypotheses, ys, Ss, nis):
            K = h.P @ H.T @ np.linalg.inv(S_)
            h.x += (K @ y)[self.nominal]  # white error states (δS) have no nominal entry to feed
            IKH = np.eye(self.n_err) - K @ H
            h.P = IKH @ h.P @ IKH.T + K @ R @ K.T
            h.P = 0.5 * (h.P + h.P.T)
            if weigh:
                h.log_w -= 0.5 * (q + np.linalg.slogdet(S_)[1])
        self.chain(IKH)
        if len(self.hypotheses) > 1:
            self._settle()
        return True

    def _settle(self) -> None:
        """Normalise and prune the weights; collapse the bank once its heading is resolved."""
        self.hypotheses = collapse_if_resolved(normalise(self.hypotheses), self.nominal, self.angles,
                                               self.nominal[self.heading], self.resolved_sd)
        if len(self.hypotheses) == 1:
            self.chain(np.zeros((self.n_err, self.n_err)))

    def correct(self, dx: np.ndarray, P: np.ndarray) -> bool:
        """The fuser's correction (dx, P) of the moments, closed-loop; True if it changed them.
        A bank: every hypothesis i goes through the affine map that takes the mixture
        N(x̄, P̄) to N(x̄ + dx, P): x_i ← x̄ + dx + T d_i, P_i ← T P_i Tᵀ, with T P̄ Tᵀ = P
        (:func:`~bodyfusion.plugins.hand_pdr.hypotheses.affine_map`), d_i = x_i − x̄."""
        x_bar, P_bar = self.moments()
        changed = bool(np.any(dx)) or not np.array_equal(P, P_bar)
        if len(self.hypotheses) == 1:
            self.hypotheses[0].x += dx[self.nominal]
            self.hypotheses[0].P = 0.5 * (P + P.T)
        elif changed:
            T = affine_map(P_bar, P)
            for h in self.hypotheses:
                d = np.zeros(self.n_err)
                d[self.nominal] = h.x - x_bar
                for a in self.angles:
                    d[self.nominal[a]] = wrap_angle(d[self.nominal[a]])
                h.x = x_bar + (dx + T @ d)[self.nominal]
                TPT = T @ h.P @ T.T
                h.P = 0.5 * (TPT + TPT.T)
        return changed
