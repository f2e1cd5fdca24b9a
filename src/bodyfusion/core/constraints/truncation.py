"""Density truncation of a joint error state at the distance limits ([Simon2010]), compiled.

The fuser's ``inequality: truncation`` (:mod:`bodyfusion.core.fuser`). Each limit k taken,
linearised (row J_k (3n,) over the stacked positions), bounds X = J_k p above by b_k (an
equality: X = b_k). The estimate's X is N(m, s²), m = J_k p̂, s² = J_k Σ J_kᵀ; cut at b_k it
has mean m + s μ_t and variance s² v_t (:func:`truncated_moments` at β = (b_k − m)/s). The
joint state takes the Gaussian conditional on X averaged over the cut X: with PH = P hᵀ
(h: J_k placed at the positions of the joint state),

    δx += PH (m_t − m)/s²,   P* = P − c PH PHᵀ,  c = (s² − V)/s⁴,

written as the Joseph update of a scalar measurement of noise R = V s²/(s² − V) with gain
K = PH (s² − V)/s⁴, expanded to its rank-two form
P* = P − K PHᵀ − PH Kᵀ + (s² + R) K Kᵀ (O(n²), exact for any K): a ``positions_only``
correction (Schmidt consider states: their rows of K and of the mean's gain zero) keeps
P* the exact covariance of that sub-optimal update. An equality, or a bound far below the
estimate, gives V → 0: the projection of [KFSC2015]. The limits are taken one after the
other, each on the state the previous one left.

Which limits: the solver's active ones, linearised at its solution p* (b_k = J_k p*), then
every other inequality whose bound the estimate's density crosses within :data:`TAIL_BETA`
σ (β = −g_k(p̂)/s_k), linearised at p̂ (b_k = J_k p̂ − g_k(p̂)): the limit holds although the
estimate's tail says it might not, and the truncation takes that information too, as
[Simon2010] truncates wherever the density crosses a bound.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from bodyfusion.core.constraints.kernels import _DEGENERATE_M, StackedLimits, _kernel, _separation
from bodyfusion.core.constraints.model import ConstraintSolution, DistanceConstraint, _layout

TAIL_BETA = 4.0
"""An inactive inequality is truncated where its bound lies within this many σ of the
estimate (beyond, the tail it cuts holds less than 3e-5 of the density)."""

_SQRT_2PI = math.sqrt(2.0 * math.pi)


@_kernel
def truncated_moments(beta: float) -> tuple[float, float]:
    """Mean and variance of a standard normal truncated to X ≤ β: −φ(β)/Φ(β) and
    1 − β φ(β)/Φ(β) − (φ(β)/Φ(β))², Φ(β) = erfc(−β/√2)/2 (accurate in the lower tail, where
    both φ and Φ stay normal numbers down to β = −30); below β = −30 their asymptotic forms
    β + 1/β and 1/β² (Mills' ratio), free of cancellation."""
    if beta < -30.0:
        return beta + 1.0 / beta, 1.0 / (beta * beta)
    ratio = math.exp(-0.5 * beta * beta) / _SQRT_2PI / (0.5 * math.erfc(-beta / math.sqrt(2.0)))
    return -ratio, max(1.0 - beta * ratio - ratio * ratio, 0.0)


class SolvedLimits(NamedTuple):
    """The solve's active limits as the truncation takes them: their Jacobian ``rows`` (A, 3n),
    the solution ``p_star`` (3n,) m, and which constraints they are ``active`` (A,) int64."""

    rows: np.ndarray
    p_star: np.ndarray
    active: np.ndarray


@_kernel
def _truncate(P: np.ndarray, pos: np.ndarray, p_hat: np.ndarray, solved: SolvedLimits, limits: StackedLimits,
              tail_beta: float, others: np.ndarray, dx: np.ndarray, tail: np.ndarray) -> int:
    """Every limit the truncation takes at one epoch, into δx (n,) and P (n, n) in place
    (module docstring): the ``solved`` active constraints' (A,) ``rows`` (A, 3n), bounded at
    the solution ``p_star`` (3n,), then the inactive inequalities within ``tail_beta`` σ of p̂
    (flagged in ``tail`` (K,)). Geometry ``limits`` as in
    :mod:`bodyfusion.core.constraints.kernels` (its hints unused); ``others`` (n,): rows kept
    out of the correction. Returns the limits that cut (s² > 0, V < s²)."""
    rows, p_star, active = solved
    idx, geo, _ = limits
    n = P.shape[0]
    n3 = pos.shape[0]
    A = rows.shape[0]
    limits = np.zeros((A + idx.shape[0], n3))
    limit_bounds = np.zeros(A + idx.shape[0])
    limit_fixed = np.zeros(A + idx.shape[0], dtype=np.bool_)
    is_active = np.zeros(idx.shape[0], dtype=np.bool_)
    for q in range(A):  # scalar loops: a slice assignment compiles numba's shape checks (seconds)
        for c in range(n3):
            limits[q, c] = rows[q, c]
            limit_bounds[q] += rows[q, c] * p_star[c]
        limit_fixed[q] = idx[active[q], 3] == 2
        is_active[active[q]] = True
    L = A
    r = np.empty(3)
    for k in range(idx.shape[0]):  # the tails, tested on the estimate before any cut
        tail[k] = False
        code = idx[k, 3]
        if is_active[k] or code == 2:
            continue
        rho = _separation(p_hat, idx, geo, k, r)
        if not rho > _DEGENERATE_M:
            continue
        i3, j3, D = idx[k, 0], idx[k, 1], idx[k, 2]
        sign = -1.0 if code == 1 else 1.0
        g = sign * (rho - geo[k, 0])
        for t in range(D):
            limits[L, i3 + t] = sign * r[t] / rho
            limits[L, j3 + t] = -sign * r[t] / rho
        s2 = 0.0
        lin = 0.0
        for c in range(n3):
            lin += limits[L, c] * p_hat[c]
            for e in range(n3):
                s2 += limits[L, c] * P[pos[c], pos[e]] * limits[L, e]
        if s2 > 0.0 and -g < tail_beta * math.sqrt(s2):
            tail[k] = True
            limit_bounds[L] = lin - g
            L += 1
        else:
            for c in range(n3):
                limits[L, c] = 0.0
    PH = np.empty(n)
    K = np.empty(n)
    taken = 0
    for q in range(L):  # X = J_q p ≤ b_q (= when fixed), on the state the previous ones left
        s2 = 0.0
        m = 0.0
        for a in range(n):
            acc = 0.0
            for c in range(n3):
                if limits[q, c] != 0.0:
                    acc += P[a, pos[c]] * limits[q, c]
            PH[a] = acc
        for c in range(n3):
            s2 += limits[q, c] * PH[pos[c]]
            m += limits[q, c] * (p_hat[c] + dx[pos[c]])
        if not s2 > 0.0:
            continue
        s = math.sqrt(s2)
        if limit_fixed[q]:
            shift, var = limit_bounds[q] - m, 0.0
        else:
            mean_t, var_t = truncated_moments((limit_bounds[q] - m) / s)
            shift, var = s * mean_t, s2 * var_t
        if var >= s2:
            continue
        taken += 1
        scale = (s2 - var) / (s2 * s2)
        for a in range(n):
            if others[a]:
                K[a] = 0.0
            else:
                dx[a] += PH[a] / s2 * shift
                K[a] = PH[a] * scale
        w = s2 + var * s2 / (s2 - var)  # s² + R
        for a in range(n):
            for b in range(n):
                P[a, b] += -K[a] * PH[b] - PH[a] * K[b] + w * K[a] * K[b]
    for a in range(n):
        for b in range(a):
            P[a, b] = P[b, a] = 0.5 * (P[a, b] + P[b, a])
    return taken


class DensityTruncation:
    """The truncation of one constraint set over the stacked positions of ``n_systems``
    systems; ``positions_only`` keeps every state but the positions out of the correction.
    :meth:`correct` at each epoch."""

    def __init__(self, constraints: list[DistanceConstraint], n_systems: int, positions_only: bool = False) -> None:
        lay = _layout(n_systems, constraints)
        self._limits = StackedLimits(lay.idx, lay.geo, np.zeros((lay.idx.shape[0], 3)))
        self.positions_only = positions_only
        self._others: dict[tuple[int, bytes], np.ndarray] = {}  # the rows kept out, per state layout

    def correct(self, P: np.ndarray, pos: np.ndarray, p_hat: np.ndarray,
                solution: ConstraintSolution) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Joint error-state correction δx (n,) and covariance P* (n, n) at the solver's
        active limits and the inactive ones whose tails the estimate crosses (module
        docstring), and which constraints (K,) were taken in their tails.

        P: (n, n) joint error-state covariance (m², rad², ...); pos: (3n_sys,) int64 indices
        of the stacked positions in it, in the order of p̂ (ENU, m, float64) and of the
        solution's Jacobian rows."""
        n = P.shape[0]
        P_new = np.array(P, dtype=float, order="C")
        dx = np.zeros(n)
        tail = np.zeros(self._limits.idx.shape[0], dtype=bool)
        key = (n, pos.tobytes())
        others = self._others.get(key)
        if others is None:
            others = self._others[key] = np.full(n, self.positions_only)
            others[pos] = False
        solved = SolvedLimits(solution.jacobian.reshape(len(solution.active), p_hat.shape[0]), solution.p,
                              np.array(solution.active, dtype=np.int64))
        _truncate(P_new, pos, p_hat, solved, self._limits, TAIL_BETA, others, dx, tail)
        return dx, P_new, tail
