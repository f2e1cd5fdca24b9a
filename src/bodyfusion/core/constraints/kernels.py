"""Compiled (numba) kernels of the distance-constraint solvers.

The per-epoch work of the usual case, one constraint — its projection ([KFSC2015]
eqs. 55–60 with the secular equation) and the certification of another solver's point
by eqs. 58–60 — compiled by numba once and cached on disk (``cache=True``); the SQP's QPs
are :mod:`bodyfusion.core.constraints.qp_kernels`'s.

Arguments shared by the kernels:

* p̂, p (3n,): stacked system positions, ENU metres; Σ (3n, 3n) in m², L (3n, 3n)
  with Σ = L Lᵀ;
* the constraint geometry of :class:`bodyfusion.core.constraints.model._Layout`:
  ``idx`` (m, 4) int rows (3i, 3j, dims, kind code: 0 ``max``, 1 ``min``,
  2 ``fixed``) and ``geo`` (m, 4) rows (d_k, b_k): the distance and the lever-arm
  offset b_k = E (l_i − l_j), metres, zero-padded to 3;
* ``hints`` (m, 3): each constraint's direction for a zero separation (its first
  dims entries);
* output buffers, written in place.

g_k, the multiplier sign and the hint directions are defined in
:mod:`bodyfusion.core.constraints.model`; OSQP's multiplier sign ("duals") in
:mod:`bodyfusion.core.constraints.sqp`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np


_DEGENERATE_M = 1e-12  # ‖r‖ below this (m) is "no direction"
_SOLVED, _INACTIVE, _FAILED = 0, 1, 2  # status of _project_pair and _qp_start_pair


# scalar loops only (array expressions cost numba compile time); the numpy error model
# gives IEEE inf/nan instead of exceptions, results carry a status instead
_kernel = numba.njit(cache=True, error_model="numpy")


class StackedLimits(NamedTuple):
    """The constraints as the kernels take them (:class:`~bodyfusion.core.constraints.model._Layout`):
    ``idx`` (m, 4) int64 per constraint its two systems' stacked offsets, dimensions (2 or 3)
    and kind (0 max, 1 min, 2 fixed); ``geo`` (m, ·) its limit (m) and lever arms; ``hints``
    (m, 3) the direction remembered for a zero separation."""

    idx: np.ndarray
    geo: np.ndarray
    hints: np.ndarray


class PairSolution(NamedTuple):
    """Where a one-constraint solve writes: the point ``p`` (3n,) m, the gain ``gain``
    (3n, 3n) of Σ* = (I − gain) Σ (I − gain)ᵀ, the constraint's Jacobian ``jac`` (1, 3n)."""

    p: np.ndarray
    gain: np.ndarray
    jac: np.ndarray


@_kernel
def _all_finite(p: np.ndarray, s: np.ndarray) -> bool:
    """True when every entry of p (n,) and s (n, n) is finite."""
    for a in range(p.shape[0]):
        if not math.isfinite(p[a]):
            return False
        for b in range(s.shape[1]):
            if not math.isfinite(s[a, b]):
                return False
    return True


# ---------------------------------------------------------------------------
# one constraint: geometry and eqs. 58–60
# ---------------------------------------------------------------------------


@_kernel
def _separation(p: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, r: np.ndarray) -> float:
    """r ← r_k(p) = E (p_i + l_i − p_j − l_j) (first dims entries); returns ‖r_k(p)‖."""
    i3, j3 = idx[k, 0], idx[k, 1]
    n2 = 0.0
    for t in range(idx[k, 2]):
        r[t] = p[i3 + t] - p[j3 + t] + geo[k, 1 + t]
        n2 += r[t] * r[t]
    return math.sqrt(n2)


@_kernel
def _pair_gain(
    sigma: np.ndarray, idx: np.ndarray, k: int, u: np.ndarray, sgt: np.ndarray, gain: np.ndarray, jac: np.ndarray
) -> float:
    """Eqs. 58–60's matrices for constraint k linearised with unit direction u (its
    first dims entries): the Jacobian row G = s·(uᵀE on block i, −uᵀE on block j),
    s = −1 for ``min`` else 1, to jac[0]; Σ Gᵀ to sgt; μ = Σ Gᵀ G / M to gain.
    Returns M = G Σ Gᵀ (gain is meaningless unless M > 0).
    """
    n3 = sigma.shape[0]
    i3, j3, D = idx[k, 0], idx[k, 1], idx[k, 2]
    sgn = -1.0 if idx[k, 3] == 1 else 1.0
    for c in range(n3):
        jac[0, c] = 0.0
    for b in range(D):
        jac[0, i3 + b] = sgn * u[b]
        jac[0, j3 + b] -= sgn * u[b]
    M = 0.0
    for r in range(n3):
        acc = 0.0
        for b in range(D):
            acc += (sigma[r, i3 + b] - sigma[r, j3 + b]) * u[b]
        sgt[r] = sgn * acc
        M += jac[0, r] * sgt[r]
    inv_m = 1.0 / M
    for r in range(n3):
        for c in range(n3):
            gain[r, c] = sgt[r] * (jac[0, c] * inv_m)
    return M


@_kernel
def _pair_direction(
    p: np.ndarray, idx: np.ndarray, geo: np.ndarray, hints: np.ndarray, k: int, u: np.ndarray
) -> float:
    """u ← r_k(p)/‖r_k(p)‖ (first dims entries), the hint when ‖r_k‖ ≤ _DEGENERATE_M;
    returns ‖r_k(p)‖."""
    rho = _separation(p, idx, geo, k, u)
    for t in range(idx[k, 2]):
        u[t] = u[t] / rho if rho > _DEGENERATE_M else hints[k, t]
    return rho


@_kernel
def _certify_pair(
    p_hat: np.ndarray, sigma: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, hints: np.ndarray,
    p: np.ndarray, gain: np.ndarray, jac: np.ndarray,
) -> tuple[bool, float, float, float, float]:
    """Eqs. 58–60 at another solver's point p with constraint k active: its direction
    u at p (:func:`_pair_direction`), :func:`_pair_gain` there (gain, jac written) and
    λ = −G (p − p̂)/M, the least-squares multiplier of Σ⁻¹(p − p̂) + λ Gᵀ = 0.
    Returns (M > 0, λ, u0, u1, u2)."""
    u = np.zeros(3)
    _pair_direction(p, idx, geo, hints, k, u)
    sgt = np.empty(p.shape[0])
    M = _pair_gain(sigma, idx, k, u, sgt, gain, jac)
    acc = 0.0
    for c in range(p.shape[0]):
        acc += jac[0, c] * (p[c] - p_hat[c])
    return M > 0.0, -acc / M, u[0], u[1], u[2]


# ---------------------------------------------------------------------------
# projection onto one constraint (scalar secular equation)
# ---------------------------------------------------------------------------


@_kernel
def _sym_eig(S: np.ndarray, D: int, w: np.ndarray, Q: np.ndarray) -> None:
    """Eigen-pairs of the symmetric D×D (D ≤ 3) matrix with upper triangle S: w (D,)
    descending, row a of Q the unit eigenvector of w[a].

    Cyclic Jacobi: the rotation of the (p, q) plane by θ = ½ atan2(2 A_pq, A_pp − A_qq)
    diagonalises that 2x2 block, A_pp, A_qq ← mean ± hypot(½(A_pp − A_qq), A_pq), and
    turns rows p, q of Q by θ. A 2x2 takes one rotation, a 3x3 converges quadratically.
    """
    A = np.empty((3, 3))
    for a in range(D):
        for b in range(D):
            A[a, b] = S[a, b] if a <= b else S[b, a]
            Q[a, b] = 1.0 if a == b else 0.0
    for _sweep in range(50):
        off = 0.0
        scale = 0.0
        for a in range(D):
            scale += abs(A[a, a])
            for b in range(a + 1, D):
                off += abs(A[a, b])
        if not off > 1e-30 * scale:
            break
        for p in range(D - 1):
            for q in range(p + 1, D):
                apq = A[p, q]
                if apq == 0.0:
                    continue
                app, aqq = A[p, p], A[q, q]
                mean = 0.5 * (app + aqq)
                rad = math.hypot(0.5 * (app - aqq), apq)
                th = 0.5 * math.atan2(2.0 * apq, app - aqq)
                c, s = math.cos(th), math.sin(th)
                A[p, p] = mean + rad
                A[q, q] = mean - rad
                A[p, q] = 0.0
                A[q, p] = 0.0
                for t in range(D):
                    if t != p and t != q:
                        atp, atq = A[t, p], A[t, q]
                        A[t, p] = c * atp + s * atq
                        A[p, t] = A[t, p]
                        A[t, q] = c * atq - s * atp
                        A[q, t] = A[t, q]
                    qp, qq = Q[p, t], Q[q, t]
                    Q[p, t] = c * qp + s * qq
                    Q[q, t] = c * qq - s * qp
    for a in range(D):
        w[a] = A[a, a]
    for a in range(D - 1):  # selection sort, descending; ties keep their order
        best = a
        for b in range(a + 1, D):
            if w[b] > w[best]:
                best = b
        if best != a:
            w[a], w[best] = w[best], w[a]
            for t in range(D):
                Q[a, t], Q[best, t] = Q[best, t], Q[a, t]


@_kernel
def _secular(
    S: np.ndarray, rhat: np.ndarray, D: int, d: float, hint: np.ndarray, tol: float, max_iter: int,
    u: np.ndarray,
) -> int:
    """Direction of the exact solution of min ½(r − r̂)ᵀS⁻¹(r − r̂) s.t. ‖r‖ = d, global
    for ‖r̂‖ ≠ d. Writes the unit r*/d to u; returns the iterations, −1 on failure.

    With S = Σ_a s_a q_a q_aᵀ (s descending) and c_a = q_a·r̂, r(ν) = Σ_a c_a/(1 + ν s_a) q_a
    (ν = λ/‖r‖). ‖r̂‖ > d: ν ∈ (0, ∞), the convex ``max`` case; ‖r̂‖ < d: ν ∈ (−1/s_1, 0),
    the global minimiser of the non-convex ``min`` case. Safeguarded Newton on
    F(ν) = 1/d − 1/‖r(ν)‖ (bisection when a step leaves the bracket) until
    |‖r(ν)‖ − d| ≤ tol. Hard case (‖r̂‖ < d, c ≈ 0 on the top eigenspace T): if
    ρ = ‖Σ_{a∉T} c_a/(1 − s_a/s_1) q_a‖ < d, r* is that vector plus √(d² − ρ²) v, v the
    unit part in T of r̂, else of the hint, else ±q_1 (the sign closest to the hint).
    """
    w = np.empty(3)
    Q = np.empty((3, 3))
    c = np.empty(3)
    r = np.empty(3)
    _sym_eig(S, D, w, Q)
    n2 = 0.0
    for a in range(D):
        acc = 0.0
        for t in range(D):
            acc += Q[a, t] * rhat[t]
        c[a] = acc
        n2 += rhat[a] * rhat[a]
    rho0 = math.sqrt(n2)
    if rho0 == d:
        for t in range(D):
            u[t] = rhat[t] / rho0
        return 0 if rho0 > _DEGENERATE_M else -1
    if rho0 > d:
        lo, hi = 0.0, math.inf
        movable = False
        for a in range(D):
            movable = movable or (w[a] > 0.0 and c[a] != 0.0)
        if not movable:
            return -1  # nothing can move this separation
    else:
        smax = w[0]
        if not smax > 0.0:
            return -1
        lo, hi = -1.0 / smax, 0.0
        ntop = 1
        while ntop < D and w[ntop] >= smax * (1.0 - 1e-10):
            ntop += 1
        ct2 = 0.0
        for a in range(ntop):
            ct2 += c[a] * c[a]
        ct = math.sqrt(ct2)
        if ct <= 1e-12 * d:  # the hard case, in closed form
            if ct == 0.0:  # v from the hint instead
                for a in range(ntop):
                    c[a] = 0.0
                    for t in range(D):
                        c[a] += Q[a, t] * hint[t]
            rr2 = 0.0
            nv2 = 0.0
            for t in range(D):
                r[t] = 0.0  # the part outside T
                u[t] = 0.0  # v, not yet normalised
                for a in range(D):
                    if a < ntop:
                        u[t] += c[a] * Q[a, t]
                    else:
                        r[t] += c[a] / (1.0 - w[a] / smax) * Q[a, t]
                rr2 += r[t] * r[t]
                nv2 += u[t] * u[t]
            if rr2 < d * d:
                nv = math.sqrt(nv2)
                if not nv >= 1e-6:  # ±q_1, the sign closest to the hint
                    nv = 0.0
                    for t in range(D):
                        u[t] = Q[0, t]
                        nv += Q[0, t] * hint[t]
                    nv = -1.0 if nv < 0.0 else 1.0
                tau = math.sqrt(d * d - rr2)
                for t in range(D):  # ‖r + τ v‖ = d: the parts are orthogonal
                    u[t] = (r[t] + tau * u[t] / nv) / d
                return 0
    nu = 0.0
    for it in range(1, max_iter + 1):
        n2 = 0.0
        dn = 0.0
        for a in range(D):
            den = 1.0 + nu * w[a]
            qa = c[a] / den
            n2 += qa * qa
            dn += qa * qa * w[a] / den
        rho = math.sqrt(n2)
        if abs(rho - d) <= tol:
            for t in range(D):
                acc = 0.0
                for a in range(D):
                    acc += c[a] / (1.0 + nu * w[a]) * Q[a, t]
                u[t] = acc / rho
            return it
        if rho > d:
            lo = nu
        else:
            hi = nu
        # F = 1/d − 1/ρ, F′ = ρ′/ρ² with ρ′ = −dn/ρ
        nu_new = nu + (1.0 / d - 1.0 / rho) * rho * n2 / dn if dn != 0.0 else math.nan
        if not (lo < nu_new < hi):  # also catches NaN
            nu_new = 0.5 * (lo + hi) if hi != math.inf else (2.0 * lo if lo > 0.0 else 1.0)
        if nu_new == nu:
            break
        nu = nu_new
    return -1


@_kernel
def _project_pair(
    p_hat: np.ndarray, sigma: np.ndarray, limits: StackedLimits, k: int, tol: float, max_iter: int, out: PairSolution,
) -> tuple[int, float, float, float, int, float, float, float]:
    """Constraint k alone: g_k(p̂); when it is violated (or ``fixed``), the direction u
    of the solution from the secular equation (:func:`_secular`, S = E B Σ Bᵀ Eᵀ) and
    eqs. 58–60 there: λ = s (u·r̂ − d)/M, p = p̂ − λ Σ Gᵀ (:func:`_pair_gain`; p, gain,
    jac written).

    Returns (status, violation at p̂, violation at p, λ, iterations, u0, u1, u2), the
    violations as in ``violation_before_m``; status _INACTIVE (g_k(p̂) ≤ 0, nothing
    written), _FAILED (nothing meaningful) or _SOLVED.
    """
    idx, geo, hints = limits
    p, gain, jac = out
    i3, j3, D, code = idx[k, 0], idx[k, 1], idx[k, 2], idx[k, 3]
    d = geo[k, 0]
    rhat = np.empty(3)
    rho = _separation(p_hat, idx, geo, k, rhat)
    v0 = abs(rho - d) if code == 2 else max(d - rho if code == 1 else rho - d, 0.0)
    if v0 == 0.0 and code != 2:
        return _INACTIVE, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0
    S = np.empty((3, 3))
    for a in range(D):
        for b in range(a, D):
            S[a, b] = sigma[i3 + a, i3 + b] - sigma[i3 + a, j3 + b] - sigma[j3 + a, i3 + b] + sigma[j3 + a, j3 + b]
    u = np.zeros(3)
    its = _secular(S, rhat, D, d, hints[k], tol, max_iter, u)
    if its < 0:
        return _FAILED, v0, v0, 0.0, its, 0.0, 0.0, 0.0
    sgt = np.empty(p_hat.shape[0])
    M = _pair_gain(sigma, idx, k, u, sgt, gain, jac)
    if not M > 0.0:
        return _FAILED, v0, v0, 0.0, its, 0.0, 0.0, 0.0
    ur = 0.0  # eq. 58: λ = s (u·r̂ − d)/M, p = p̂ − λ Σ Gᵀ
    for a in range(D):
        ur += u[a] * rhat[a]
    lam = (ur - d) / M if code != 1 else (d - ur) / M
    for c in range(p_hat.shape[0]):
        p[c] = p_hat[c] - lam * sgt[c]
    rho = _separation(p, idx, geo, k, rhat)
    v1 = abs(rho - d) if code == 2 else max(d - rho if code == 1 else rho - d, 0.0)
    return _SOLVED, v0, v1, lam, its, u[0], u[1], u[2]


def _secular_limits(tol_m: float, max_iter: int) -> tuple[float, int]:
    """Tolerance on ‖r‖ − d and iteration limit of the secular equation (:func:`_secular`)."""
    return 1e-3 * tol_m, max(4 * max_iter, 60)


# ---------------------------------------------------------------------------
# whitening and the SQP's QPs
# ---------------------------------------------------------------------------


