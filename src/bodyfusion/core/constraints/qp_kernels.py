"""Compiled (numba) kernels of the SQP's quadratic programs (:mod:`bodyfusion.core.constraints.sqp`,
:mod:`bodyfusion.core.constraints.qp`): the constraints linearised at a point with the
Hessian of their curvature, OSQP's start at a KKT point, the step back to positions, and the
one-constraint QP that certifies the projection on either side of OSQP. Arguments as in
:mod:`bodyfusion.core.constraints.kernels`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from bodyfusion.base.linalg_kernels import cholesky
from bodyfusion.core.constraints.kernels import (_DEGENERATE_M, _FAILED, _SOLVED, PairSolution, StackedLimits,
                                                 _certify_pair, _kernel, _pair_direction, _project_pair, _separation)

_CURVATURE_FLOOR = 1e-2  # least eigenvalue of the SQP's whitened Hessian I + H (see _curvature_scale)


class QpArrays(NamedTuple):
    """One SQP step's QP in OSQP's form on the whitened variable: constraint rows ``A`` (m, 3n),
    bounds ``lo``, ``hi`` (m,), Hessian ``P`` (3n, 3n) and linear term ``q`` (3n,)."""

    A: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    P: np.ndarray
    q: np.ndarray


class PairStart(NamedTuple):
    """A one-constraint QP's start (:func:`_qp_start_pair`): Σ's Cholesky factor ``L``
    (3n, 3n), the projection ``p0`` (3n,), the multipliers ``duals`` (m,) and the whitened
    point ``y0`` (3n,)."""

    L: np.ndarray
    p0: np.ndarray
    duals: np.ndarray
    y0: np.ndarray


@_kernel
def _curvature_scale(H: np.ndarray, neg: np.ndarray) -> float:
    """The largest t in [0, 1] with I + H + t·neg ⪰ _CURVATURE_FLOOR·I (a Cholesky
    factorisation of (1 − floor) I + H + t·neg succeeds; H ⪰ 0), by bisection to 2⁻²⁰.

    t = 1 while the whole negative curvature leaves that margin: Newton steps near
    a ``min`` solution unless its Hessian is weaker than the floor (at the edge of
    the degenerate case). Where it does not (a concave stretch of the constraint),
    the model's least curvature is the floor: a large step out of it. Halving t to
    keep ⪰ 0.1 I instead made the SQP from p̂ converge linearly or creep along the
    constraint (up to 20 QPs, then the fallback) on 0.2–5 % of random ``min`` problems."""
    n = H.shape[0]
    work = np.empty((n, n))
    fac = np.empty((n, n))
    lo, hi, t = 0.0, 1.0, 1.0  # t = 1 first, then bisection of [lo, hi]
    for _ in range(21):
        for a in range(n):
            for b in range(n):
                work[a, b] = H[a, b] + t * neg[a, b]
            work[a, a] += 1.0 - _CURVATURE_FLOOR
        if cholesky(work, fac):
            if t == hi:
                return t
            lo = t
        else:
            hi = t
        t = 0.5 * (lo + hi)
    return lo


@_kernel
def _linearise(
    p_hat: np.ndarray, L: np.ndarray, limits: StackedLimits, p: np.ndarray, duals: np.ndarray, qp: QpArrays,
) -> None:
    """The constraints of one SQP step (:func:`~bodyfusion.core.constraints.sqp._sqp`)
    linearised at p, and its Hessian.

    Row k of A: a_k = u_kᵀ BL_k, BL_k = E B_k L, u_k the direction at p
    (:func:`_pair_direction`); bound lin_k = d_k − u_k·r̂_k into lo/hi on the side(s)
    of its kind (±1e30, OSQP's infinity, on the other). P = I + H with the curvature
    H = Σ_k duals_k (BL_kᵀBL_k − a_k a_kᵀ)/‖r_k‖ = Σ_k duals_k Lᵀ∇²‖r_k‖L; its
    negative part (duals < 0: active ``min``) scaled by :func:`_curvature_scale`; written into
    ``qp``'s A, lo, hi and P.
    """
    idx, geo, hints = limits
    A, lo, hi, P, _ = qp
    n3 = p.shape[0]
    neg = np.zeros((n3, n3))
    has_neg = False
    BL = np.empty((3, n3))
    u = np.empty(3)
    rhat = np.empty(3)
    for a in range(n3):
        for b in range(n3):
            P[a, b] = 0.0
    for k in range(idx.shape[0]):
        i3, j3, D, code = idx[k, 0], idx[k, 1], idx[k, 2], idx[k, 3]
        rho = _pair_direction(p, idx, geo, hints, k, u)
        _separation(p_hat, idx, geo, k, rhat)
        lin = geo[k, 0]
        for t in range(D):
            lin -= u[t] * rhat[t]
        lo[k] = -1e30 if code == 0 else lin
        hi[k] = 1e30 if code == 1 else lin
        for c in range(n3):
            acc = 0.0
            for t in range(D):
                BL[t, c] = L[i3 + t, c] - L[j3 + t, c]
                acc += u[t] * BL[t, c]
            A[k, c] = acc
        if duals[k] == 0.0 or not rho > _DEGENERATE_M:
            continue
        wk = duals[k] / rho
        H = P if wk > 0.0 else neg
        has_neg = has_neg or wk < 0.0
        for a in range(n3):
            for b in range(n3):
                btb = 0.0
                for t in range(D):
                    btb += BL[t, a] * BL[t, b]
                H[a, b] += wk * (btb - A[k, a] * A[k, b])
    if has_neg:
        t = _curvature_scale(P, neg)
        for a in range(n3):
            for b in range(n3):
                P[a, b] += t * neg[a, b]
    for a in range(n3):
        P[a, a] += 1.0


@_kernel
def _stationary_point(A: np.ndarray, duals: np.ndarray, y: np.ndarray) -> None:
    """y = −Aᵀ duals: the whitened point at which multipliers ``duals`` (OSQP's sign)
    satisfy stationarity, y + Σ_k duals_k a_k = 0 (its KKT point, for the projection's)."""
    for c in range(A.shape[1]):
        acc = 0.0
        for k in range(A.shape[0]):
            acc -= duals[k] * A[k, c]
        y[c] = acc


@_kernel
def _linear_term(P: np.ndarray, y: np.ndarray, q: np.ndarray) -> None:
    """q = −H y = y − P y (P = I + H): the QP's linear term, its minimiser the Newton step from y."""
    for a in range(y.shape[0]):
        acc = y[a]
        for b in range(y.shape[0]):
            acc -= P[a, b] * y[b]
        q[a] = acc


@_kernel
def _advance(
    p_hat: np.ndarray, L: np.ndarray, y: np.ndarray, p: np.ndarray, idx: np.ndarray, geo: np.ndarray,
    p_new: np.ndarray, g: np.ndarray,
) -> float:
    """p_new = p̂ + L y and g_k(p_new) for every constraint (:mod:`bodyfusion.core.constraints.model`);
    returns the step max |p_new − p|, inf when p_new is not finite."""
    n3 = p.shape[0]
    step = 0.0
    for a in range(n3):
        acc = p_hat[a]
        for b in range(n3):
            acc += L[a, b] * y[b]
        p_new[a] = acc
        if not math.isfinite(acc):
            return math.inf
        step = max(step, abs(acc - p[a]))
    r = np.empty(3)
    for k in range(idx.shape[0]):
        rho = _separation(p_new, idx, geo, k, r)
        g[k] = geo[k, 0] - rho if idx[k, 3] == 1 else rho - geo[k, 0]
    return step


# the usual case, one constraint: the projection certified by one QP


@_kernel
def _qp_start_pair(
    p_hat: np.ndarray, sigma: np.ndarray, limits: StackedLimits, k: int, tol: float, max_iter: int, start: PairStart,
    qp: QpArrays,
) -> tuple[int, float]:
    """The QP that certifies the projection onto constraint k, the only one: the
    projection p0 (:func:`_project_pair`), its multiplier in OSQP's sign to duals[k],
    Σ = L Lᵀ (:func:`~bodyfusion.base.linalg_kernels.cholesky`) and the SQP's QP at p0, started from that KKT point
    (:func:`_linearise`, :func:`_stationary_point` to y0, :func:`_linear_term`).
    Returns (status, violation at p̂); _FAILED also when Σ is not positive definite."""
    L, p0, duals, y0 = start
    A, _, _, P, q = qp
    idx = limits.idx
    n3 = p_hat.shape[0]
    status, v0, _, lam, _, _, _, _ = _project_pair(p_hat, sigma, limits, k, tol, max_iter,
                                                   PairSolution(p0, np.empty((n3, n3)), np.empty((1, n3))))
    if status != _SOLVED:
        return status, v0
    if not cholesky(sigma, L):
        return _FAILED, v0
    duals[k] = -lam if idx[k, 3] == 1 else lam
    _linearise(p_hat, L, limits, p0, duals, qp)
    _stationary_point(A, duals, y0)
    _linear_term(P, y0, q)
    return _SOLVED, v0


@_kernel
def _qp_finish_pair(
    p_hat: np.ndarray, sigma: np.ndarray, L: np.ndarray, y: np.ndarray, p0: np.ndarray, limits: StackedLimits, k: int,
    out: PairSolution,
) -> tuple[float, float, bool, float, float, float, float]:
    """OSQP's point p = p̂ + L y of the QP of :func:`_qp_start_pair` (:func:`_advance`)
    and eqs. 58–60 there for constraint k (:func:`_certify_pair`; ``out``'s p, gain, jac
    written). Returns (step from p0, g_k(p), M > 0, λ, u0, u1, u2)."""
    idx, geo, hints = limits
    p, gain, jac = out
    g = np.empty(idx.shape[0])
    step = _advance(p_hat, L, y, p0, idx, geo, p, g)
    ok, lam, u0, u1, u2 = _certify_pair(p_hat, sigma, idx, geo, k, hints, p, gain, jac)
    return step, g[k], ok, lam, u0, u1, u2
