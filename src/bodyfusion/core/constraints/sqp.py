"""Whitening and the sequential QP (SQP) of the distance constraints.

In the whitened variable y = L⁻¹ (p − p̂), Σ = L Lᵀ (Cholesky; the symmetric square
root when Σ is only PSD), the objective ½ (p − p̂)ᵀ Σ⁻¹ (p − p̂) is ½‖y‖²: well
conditioned whatever the scale of Σ (p in ENU metres, y in units of Σ's square
root) and no Σ⁻¹ needed. Each QP linearises the constraints about the current
point: one row u_kᵀ (r̂_k + E B_k L y) {≤, ≥, =} d_k per constraint. Re-linearising
and projecting again converges only linearly (the fixed-point scheme of
:mod:`bodyfusion.core.constraints.projection`), so the QPs carry the constraints'
curvature, which makes each a Newton step: P = I + Σ_k y_k Lᵀ ∇²‖r_k‖ L, y_k the
previous QP's multipliers; the first QP's curvature is seeded with [KFSC2015]
eq. 58's multipliers at p̂, or comes with the start point (the projection's).
Negative curvature (active ``min``, ``fixed`` pushed apart) is kept whole while
P ⪰ 0.01 I, else cut to that floor: Newton steps close to the degenerate case too,
large steps out of concave stretches of the constraint. Iterated
until the nonlinear constraints hold to the tolerance and the step is below it
(or Newton's quadratic rate shows the next step would be).

The QP solver is a backend: OSQP (:mod:`bodyfusion.core.constraints.qp`) or the
projection's small dense dual active set. Multipliers to and from a backend
("duals") are in OSQP's sign: > 0 at an upper bound (``max``, ``fixed``), < 0 at
a lower one (``min``); λ_k = ``_Layout.dual_sign[k]`` · dual_k.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from bodyfusion.base.linalg_kernels import cholesky
from bodyfusion.core.constraints.kernels import _DEGENERATE_M, StackedLimits
from bodyfusion.core.constraints.qp_kernels import QpArrays, _advance, _linear_term, _linearise, _stationary_point
from bodyfusion.core.constraints.model import _Layout, _max_violation

# one QP: (P, q, A, lo, hi, y warm start, duals warm start) -> (ok, y, duals)
QpBackend = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                     tuple[bool, np.ndarray, np.ndarray]]


def _sqrt_cov(sigma: np.ndarray) -> np.ndarray | None:
    """L with Σ = L Lᵀ: Cholesky, or the symmetric square root for PSD Σ."""
    L = np.empty_like(sigma)
    if cholesky(sigma, L):
        return L
    s = 0.5 * (sigma + sigma.T)
    w, V = np.linalg.eigh(s)
    if not np.all(np.isfinite(w)) or w[0] < -1e-9 * max(1.0, abs(w[-1])):
        return None
    return V * np.sqrt(np.clip(w, 0.0, None))


def _sqp_work(n3: int, m: int) -> tuple[np.ndarray, ...]:
    """Buffers of :func:`_sqp`'s QPs: A (m, n3), lo, hi (m), P (n3, n3), q (n3), g (m)."""
    return np.empty((m, n3)), np.empty(m), np.empty(m), np.empty((n3, n3)), np.empty(n3), np.empty(m)


def _seed_duals(p_hat: np.ndarray, L: np.ndarray, lay: _Layout) -> np.ndarray:
    """Eq. 58's multiplier at p̂ of each violated (or fixed) constraint taken alone,
    (‖r̂‖ − d)/‖a‖² with a = (r̂/‖r̂‖)ᵀ E B L, in OSQP's sign: the first QP's curvature."""
    pl = p_hat.tolist()
    g0, rho0 = lay.g_all(pl)
    duals = np.zeros(lay.m)
    for k in range(lay.m):
        if (g0[k] > 0.0 or lay.code[k] == 2) and rho0[k] > _DEGENERATE_M:
            blk = L[lay.i3[k] : lay.i3[k] + lay.dims[k]] - L[lay.j3[k] : lay.j3[k] + lay.dims[k]]
            a = np.asarray([x / rho0[k] for x in lay.r(pl, k)]) @ blk
            duals[k] = (rho0[k] - lay.d[k]) / float(a @ a)
    return duals


def _sqp(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    hints: np.ndarray,
    tol: float,
    max_iter: int,
    backend: QpBackend,
    step_tol: float | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
    work: tuple[np.ndarray, ...] | None = None,
) -> tuple[np.ndarray, list[float], np.ndarray, int, bool] | None:
    """Sequential QP in y = L⁻¹(p − p̂) with the constraints' curvature.

    Each QP (:func:`_linearise`, :func:`_linear_term`):
    min ½ yᵀ(I + H)y − (H y_k)ᵀ y  s.t.  lo ≤ A y ≤ hi, with A the distance
    gradients at p_k (rows a_k = u_kᵀ E B_k L) and
    H = Σ_k y_k (BL_kᵀBL_k − a_k a_kᵀ)/‖r_k‖ = Σ_k y_k Lᵀ∇²‖r_k‖L, y_k the
    previous QP's multipliers in OSQP's sign (> 0 at an upper bound). Without
    ``start`` the SQP begins at p̂ and the first QP's curvature is seeded with
    eq. 58's multiplier of each violated constraint (:func:`_seed_duals`), so it
    is already a Newton step. ``start``: (p0, duals0), a KKT point and its
    multipliers in OSQP's sign (the projection's), whitened by
    :func:`_stationary_point`; the first QP is then the Newton step from there,
    its solution p0 itself. Negative curvature (active ``min`` constraints) is
    scaled down only as far as I + H ⪰ 0.01 I needs
    (:func:`~bodyfusion.core.constraints.kernels._curvature_scale`).

    ``backend(P, q, A, lo, hi, y_k, duals_k) -> (ok, y, duals)`` solves one QP,
    warm-started at the linearisation point. Converged: violations ≤ ``tol`` and
    the step ≤ ``step_tol`` (default ``tol``), or Newton's rate shows the next
    step would be. ``work``: :func:`_sqp_work` buffers to reuse. Returns (p, g(p),
    duals, iterations, converged), or None on QP failure; max_iter ≥ 1.
    """
    stol = tol if step_tol is None else step_tol
    n3, m = p_hat.shape[0], lay.m
    A, lo, hi, P, q, g_new = _sqp_work(n3, m) if work is None else work
    if start is None:
        p, duals, y = p_hat, _seed_duals(p_hat, L, lay), np.zeros(n3)
    else:
        (p, duals), y = start, np.empty(n3)
    prev_step = math.inf
    for it in range(1, max_iter + 1):
        _linearise(p_hat, L, StackedLimits(lay.idx, lay.geo, hints), p, duals, QpArrays(A, lo, hi, P, q))
        if it == 1 and start is not None:
            _stationary_point(A, duals, y)
        _linear_term(P, y, q)
        ok, y_new, duals_new = backend(P, q, A, lo, hi, y, duals)
        if not ok:
            return None
        p_new = np.empty(n3)
        step = _advance(p_hat, L, y_new, p, lay.idx, lay.geo, p_new, g_new)
        if not math.isfinite(step):
            return None
        y, duals, p, g = y_new, duals_new, p_new, g_new.tolist()
        if _settled(_max_violation(lay, g), step, prev_step, tol, stol):
            return p, g, duals, it, True
        prev_step = step
    return p, g, duals, max_iter, False


def _settled(viol: float, step: float, prev_step: float, tol: float, stol: float) -> bool:
    """SQP convergence: violations ≤ tol and the step ≤ stol, or Newton's (quadratic)
    rate shows the next step (≈ step³/prev²) would be; the bounds keep this safe
    even under linear convergence (rate ≤ 0.01)."""
    return viol <= tol and (step <= stol or (step <= 100.0 * stol and step**3 <= 1e-2 * stol * prev_step**2))
