"""Every constraint at every epoch the fuser solved, in preallocated arrays: when, which pair, its
separation before and after the solve, its multiplier and whether it was active, and how long the
solve took."""

from __future__ import annotations

import numpy as np

from bodyfusion.core.constraints import ConstraintSolution
from bodyfusion.core.layout import ConstraintConfig


class ConstraintLog:
    """Rows for ``epochs`` sync epochs of the layout's ``constraints`` over the stacked systems
    ``order`` (the fuser's). The separation of constraint k is ‖E (p_i + l_i − p_j − l_j)‖ (m; E
    keeps east and north for a horizontal constraint, :mod:`bodyfusion.core.constraints.model`),
    ``before`` at the estimates p̂, ``after`` at the corrected estimates (the solution p* when
    the correction projects, ``fuser.inequality: projection``; inside the limit by the truncated
    density's mean with ``truncation``, also where the constraint held but the estimate's density
    crossed its limit: ``tail_truncated``); the multiplier λ follows the solvers' sign
    convention (0 when inactive); ``limit`` the limit at the epoch (m: a body limit follows the
    gait, a fighting one is relaxed, :mod:`bodyfusion.core.limits`). The stacked positions before and after (``p_before``,
    ``p_after``, (epochs, 3n), ENU m) are kept; the separations are computed from them when
    asked (``before_m``, ``after_m``). ``solve_us`` (epochs,): the solver's wall time (µs);
    :attr:`active_multipliers`: the multipliers of the active constraints, epoch by epoch in the
    order the solver made them active. Rows for more epochs are added by :meth:`reserve` (a live
    run learns its epochs as it goes)."""

    def __init__(self, constraints: list[ConstraintConfig], order: list[str], epochs: int = 0) -> None:
        self.constraints = constraints
        k = len(constraints)
        self._i = np.array([order.index(c.between[0]) for c in constraints], dtype=np.int64)
        self._j = np.array([order.index(c.between[1]) for c in constraints], dtype=np.int64)
        self._lever = np.array([[c.lever_arms_m.get(c.between[0], (0.0, 0.0, 0.0)) for c in constraints],
                                [c.lever_arms_m.get(c.between[1], (0.0, 0.0, 0.0)) for c in constraints]],
                               dtype=float).reshape(2, k, 3)
        self._axes = np.array([[1.0, 1.0, 0.0 if c.horizontal else 1.0] for c in constraints]).reshape(k, 3)
        self.t = np.empty(epochs)
        self.p_before = np.empty((epochs, 3 * len(order)))
        self.p_after = np.empty((epochs, 3 * len(order)))
        self.multiplier = np.empty((epochs, k))
        self.limit = np.empty((epochs, k))
        self.active = np.zeros((epochs, k), dtype=bool)
        self.tail_truncated = np.zeros((epochs, k), dtype=bool)
        self.solve_us = np.empty(epochs)
        self._lam_active = np.empty(epochs * k)
        self._n_active = 0
        self.n = 0

    _ROWS = ("t", "p_before", "p_after", "multiplier", "limit", "active", "tail_truncated", "solve_us")

    def reserve(self, epochs: int) -> None:
        """Room for ``epochs`` more epochs beyond those recorded (the arrays at least double when
        they grow, so that a live run's many small slices cost as one)."""
        need = self.n + epochs
        have = self.t.shape[0]
        if need <= have:
            return
        size = max(need, 2 * have)
        for name in self._ROWS:
            old = getattr(self, name)
            new = np.zeros((size, *old.shape[1:]), dtype=old.dtype)
            new[:self.n] = old[:self.n]
            setattr(self, name, new)
        lam = np.empty(size * len(self.constraints))
        lam[:self._n_active] = self._lam_active[:self._n_active]
        self._lam_active = lam

    def forget_before(self, t: float) -> None:
        """Drop the epochs before ``t`` (s): the later ones move to the front, the room stays (a
        live run that keeps a bounded history)."""
        d = int(np.searchsorted(self.t[:self.n], t))
        if d == 0:
            return
        gone = int(np.count_nonzero(self.active[:d]))
        for name in self._ROWS:
            rows = getattr(self, name)
            rows[:self.n - d] = rows[d:self.n]
        self.active[self.n - d:self.n] = self.tail_truncated[self.n - d:self.n] = False  # rows a record fills in part
        self._lam_active[:self._n_active - gone] = self._lam_active[gone:self._n_active]
        self._n_active -= gone
        self.n -= d

    def separations(self, p: np.ndarray) -> np.ndarray:
        """(..., K) separation (m) of every constraint at stacked positions p (..., 3n)."""
        pos = p.reshape(*p.shape[:-1], -1, 3)
        r = (pos[..., self._i, :] + self._lever[0] - pos[..., self._j, :] - self._lever[1]) * self._axes
        return np.sqrt(np.einsum("...ki,...ki->...k", r, r))

    @property
    def active_multipliers(self) -> np.ndarray:
        """λ of every activation (the solvers' sign convention), in the order they were made."""
        return self._lam_active[:self._n_active]

    @property
    def before_m(self) -> np.ndarray:
        """(epochs, K) separations (m) at the estimates."""
        return self.separations(self.p_before[:self.n])

    @property
    def after_m(self) -> np.ndarray:
        """(epochs, K) separations (m) at the corrected estimates."""
        return self.separations(self.p_after[:self.n])

    def record(self, t: float, p_hat: np.ndarray, p_after: np.ndarray, solution: ConstraintSolution,
               solve_us: float, limits: np.ndarray, tail_truncated: np.ndarray | None = None) -> None:
        """One epoch at time t (s): the estimates p̂ and the corrected estimates (3n,), the solution
        and its solve time (µs), the limits that held (K,, m), the constraints truncated in their
        tails (K,) bool."""
        e = self.n
        self.t[e] = t
        self.limit[e] = limits
        self.p_before[e] = p_hat
        self.p_after[e] = p_after
        self.multiplier[e] = solution.multipliers
        self.solve_us[e] = solve_us
        for k in solution.active:  # a few: scalar stores cost less than a fancy index
            self.active[e, k] = True
            self._lam_active[self._n_active] = solution.multipliers[k]
            self._n_active += 1
        if tail_truncated is not None:
            self.tail_truncated[e] = tail_truncated
        self.n += 1

    def columns(self) -> dict[str, np.ndarray]:
        """Long form, one row per epoch and constraint: ``t`` (s), ``pair`` (``a-b``), ``system_a``,
        ``system_b``, ``kind``, ``limit_m``, ``distance_before_m``, ``distance_after_m``,
        ``multiplier``, ``active``, ``tail_truncated``."""
        n, k = self.n, len(self.constraints)
        pick = np.tile(np.arange(k), n)
        labels = np.array([f"{c.between[0]}-{c.between[1]}" for c in self.constraints], dtype=object)
        a = np.array([c.between[0] for c in self.constraints], dtype=object)
        b = np.array([c.between[1] for c in self.constraints], dtype=object)
        return {"t": np.repeat(self.t[:n], k), "pair": labels[pick], "system_a": a[pick], "system_b": b[pick],
                "kind": np.array([c.kind for c in self.constraints], dtype=object)[pick],
                "limit_m": self.limit[:n].ravel(),
                "distance_before_m": self.before_m.ravel(), "distance_after_m": self.after_m.ravel(),
                "multiplier": self.multiplier[:n].ravel(), "active": self.active[:n].ravel(),
                "tail_truncated": self.tail_truncated[:n].ravel()}
