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

The covariance steps are compiled (:mod:`bodyfusion.plugins.hand_pdr.kernels`), in place on
each hypothesis' P.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from bodyfusion.core.heading import wrap_angle
from bodyfusion.plugins.hand_pdr.hypotheses import (Hypothesis, affine_map, collapse_if_resolved, mixture_moments,
                                                    normalise, spread_headings)
from bodyfusion.nav.kalman import kalman_update
from bodyfusion.plugins.hand_pdr.kernels import transition

NOT_TRACKED = np.zeros((0, 0))
"""The kernels' ``phi`` when Φ is not chained (not tracked, or the bank is open)."""


class BankFilter:
    """The ``hypotheses`` (iterate them; ``len``: 1 for one filter) with ``nominal`` and
    ``angles`` as in :func:`~bodyfusion.plugins.hand_pdr.hypotheses.mixture_moments`,
    ``heading`` the heading's nominal entry (its error-state index ``nominal[heading]``) and
    ``resolved_sd`` (rad) the heading σ at which an open bank collapses; ``phi``: the fuser's
    transition Φ since its last sync (None: not tracked); ``nis``: the NIS of the last
    :meth:`update`, one per hypothesis."""

    def __init__(self, hypotheses: list[Hypothesis], nominal: list[int], angles: list[int], heading: int,
                 resolved_sd: float) -> None:
        self.hypotheses = hypotheses
        self.nominal = nominal
        self.angles = angles
        self.heading = heading
        self.resolved_sd = resolved_sd
        self.n_err = hypotheses[0].P.shape[0]
        self.phi: np.ndarray | None = None
        self.nis: list[float] = []
        self._nominal = np.array(nominal)
        self._dx = np.zeros(self.n_err)

    def __len__(self) -> int:
        return len(self.hypotheses)

    def __iter__(self) -> Iterator[Hypothesis]:
        return iter(self.hypotheses)

    def moments(self, copy: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Nominal state and error-state covariance (the mixture's, moment-matched, while open).
        ``copy`` False: one filter's own arrays, to be read before the filter moves on."""
        if not copy and len(self.hypotheses) == 1:
            return self.hypotheses[0].x, self.hypotheses[0].P
        return mixture_moments(self.hypotheses, self.nominal, self.angles)

    def spread(self, x: np.ndarray, P: np.ndarray, count: int) -> None:
        """Open the bank: ``count`` hypotheses round the circle from (x, P)
        (:func:`~bodyfusion.plugins.hand_pdr.hypotheses.spread_headings`); Φ = 0."""
        self.hypotheses = spread_headings(x, P, count, self.heading, self.nominal[self.heading])
        self._forget_phi()

    def transition(self, F: np.ndarray, Q: np.ndarray) -> None:
        """P ← F P Fᵀ + Q for every hypothesis (F, Q (n, n), one for all, or (count, n, n), one
        each); the fuser's Φ ← F Φ (one filter) or 0 (a bank)."""
        phi = self._chained()
        for i, h in enumerate(self.hypotheses):
            transition(h.P, F[i] if F.ndim == 3 else F, Q[i] if Q.ndim == 3 else Q, phi)
        if len(self.hypotheses) > 1:
            self._forget_phi()

    def _chained(self) -> np.ndarray:
        """Φ for the kernels to chain in place: tracked with one filter; else :data:`NOT_TRACKED`."""
        return self.phi if self.phi is not None and len(self.hypotheses) == 1 else NOT_TRACKED

    def _forget_phi(self) -> None:
        """A bank has no linear transition: Φ = 0 when tracked (see the module docstring)."""
        if self.phi is not None:
            self.phi[:] = 0.0

    def update(self, H: np.ndarray, residual: Callable[[np.ndarray], np.ndarray], R: np.ndarray, gate: float,
               weigh: bool) -> bool:
        """Gated Kalman update (Joseph form) of every hypothesis, closed-loop reset; y = residual(x).
        Rejected (False) when the innovation fails the chi-square gate of every hypothesis
        (:func:`~bodyfusion.nav.kalman.kalman_update` with gate −∞ gives the NIS
        alone, with +∞ updates). With ``weigh`` the log-weights gain log N(y; 0, S) (see
        :mod:`~bodyfusion.plugins.hand_pdr.hypotheses`)."""
        ys = [residual(h.x) for h in self.hypotheses]
        self.nis = [kalman_update(h.P, H, R, y, -np.inf, self._dx, NOT_TRACKED)[0] for h, y in zip(self.hypotheses, ys)]
        if not any(q <= gate for q in self.nis):
            return False
        phi = self._chained()
        for h, y in zip(self.hypotheses, ys):
            self._dx[:] = 0.0  # a hypothesis whose S is not positive definite is left as it is
            q, logdet = kalman_update(h.P, H, R, y, np.inf, self._dx, phi)
            h.x += self._dx[self._nominal]  # white error states (δS) have no nominal entry to feed
            if weigh:
                h.log_w -= 0.5 * (q + logdet)
        if len(self.hypotheses) > 1:
            self._forget_phi()
            self._settle()
        return True

    def _settle(self) -> None:
        """Normalise and prune the weights; collapse the bank once its heading is resolved."""
        self.hypotheses = collapse_if_resolved(normalise(self.hypotheses), self.nominal, self.angles,
                                               self.nominal[self.heading], self.resolved_sd)

    def correct(self, dx: np.ndarray, P: np.ndarray) -> bool:
        """The fuser's correction (dx, P) of the moments, closed-loop; True if it changed them.
        One filter: x ← x + dx (nominal entries), P ← (P + Pᵀ) / 2 in place. A bank: every
        hypothesis i goes through the affine map that takes the mixture N(x̄, P̄) to
        N(x̄ + dx, P): x_i ← x̄ + dx + T d_i, P_i ← T P_i Tᵀ, with T P̄ Tᵀ = P
        (:func:`~bodyfusion.plugins.hand_pdr.hypotheses.affine_map`), d_i = x_i − x̄."""
        x_bar, P_bar = self.moments(copy=False)
        changed = bool(dx.any() or (P != P_bar).any())
        if len(self.hypotheses) == 1:
            h = self.hypotheses[0]
            h.x += dx[self._nominal]
            np.add(P, P.T, out=h.P)
            h.P *= 0.5
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
