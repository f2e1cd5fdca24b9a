"""Eqs. 58–60 of [KFSC2015] on a set of distance constraints linearised about a point.

With the constraints W active and linearised with unit directions u_k — rows
G_k = s_k (u_kᵀE on block i, −u_kᵀE on block j), s_k = −1 for ``min`` else 1, and
G p̂ − h = s_k (u_k·r̂_k − d_k) — the constrained positions (ENU, metres), the
multipliers and the gain are

    p = p̂ − Σ Gᵀ λ,   λ = (G Σ Gᵀ)⁻¹ (G p̂ − h)          (eq. 58),
    μ = Σ Gᵀ (G Σ Gᵀ)⁻¹ G,   Σ* = (I − μ) Σ (I − μ)ᵀ     (eqs. 59–60).

The projection applies them at its converged linearisation point. The QP and the
SOCP *certify* their own point p with them: λ then solves the stationarity
condition Σ⁻¹ (p − p̂) + Gᵀ λ = 0 in least squares, and inequality constraints
whose λ comes out ≤ 0 leave the active set. One active constraint is one kernel
call; several use numpy.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from bodyfusion.core.constraints.kernels import _certify_pair
from bodyfusion.core.constraints.model import _direction, _Layout


def _eq_project(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    W: Sequence[int],
    dirs: dict[int, list[float]],
    p_given: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Project p̂ onto the constraints W linearised with directions ``dirs``.

    Returns (p, λ_W, μ, G). With ``p_given`` the point is kept and λ is the
    least-squares multiplier of the stationarity condition at that point
    (used to certify QP/SOCP solutions).
    """
    rows = lay.rows(W)
    K = len(rows)
    U = np.zeros((K, len(W)))
    e = np.empty(len(W))
    pl = p_hat.tolist()
    pos = 0
    for col, k in enumerate(W):
        u = dirs[k]
        s = -1.0 if lay.code[k] == 1 else 1.0
        D = lay.dims[k]
        U[pos : pos + D, col] = [s * x for x in u]
        r = lay.r(pl, k)
        e[col] = s * (sum(a * b for a, b in zip(u, r)) - lay.d[k])  # G p̂ − h
        pos += D
    plus, minus = lay.plus[rows], lay.minus[rows]
    sig_bt = sigma[:, plus] - sigma[:, minus]  # Σ Bᵀ (3n, K)
    sig_gt = sig_bt @ U  # Σ Gᵀ (3n, |W|)
    G = U.T @ lay.bmat[rows]  # (|W|, 3n)
    M = G @ sig_gt  # G Σ Gᵀ
    try:
        if p_given is None:
            lam = np.linalg.solve(M, e)
        else:
            lam = -np.linalg.lstsq(M, G @ (p_given - p_hat), rcond=None)[0]
        mu = sig_gt @ np.linalg.solve(M, G)
    except np.linalg.LinAlgError:
        Mp = np.linalg.pinv(M)
        lam = Mp @ e if p_given is None else -Mp @ (G @ (p_given - p_hat))
        mu = sig_gt @ (Mp @ G)
    p = p_hat - sig_gt @ lam if p_given is None else p_given
    return p, lam, mu, G


def _finish(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    W: list[int],
    dirs: dict[int, list[float]],
    p_given: np.ndarray | None = None,
) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray, np.ndarray]:
    """(p, active, multipliers (m,), μ, jacobian) for active set W at its directions."""
    n3 = p_hat.shape[0]
    lam_full = np.zeros(lay.m)
    if not W:
        p = p_hat.copy() if p_given is None else p_given
        return p, [], lam_full, np.zeros((n3, n3)), np.zeros((0, n3))
    p, lam, mu, G = _eq_project(p_hat, sigma, lay, W, dirs, p_given)
    lam_full[list(W)] = lam
    return p, list(W), lam_full, mu, G


def _certify(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    p: np.ndarray,
    g: list[float],
    hints: np.ndarray,
    tol_act: float,
) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, dict[int, list[float]]]:
    """Active set, multipliers and μ at a solution ``p`` (with g = g(p)) found by an
    external solver: candidates are the fixed constraints and those within
    ``tol_act`` of their bound; λ from the stationarity condition at p (least
    squares), inequality constraints with λ ≤ 0 leave one by one."""
    W = [k for k in range(lay.m) if lay.code[k] == 2 or g[k] >= -tol_act]
    while True:
        W2, lam_full, mu, G, dirs = _multipliers_at(p_hat, sigma, lay, W, p, hints)
        wrong = [(lam_full[k], k) for k in W2 if lay.code[k] != 2 and lam_full[k] <= 0.0]
        if not wrong:
            return W2, lam_full, mu, G, dirs
        W = [k for k in W if k != min(wrong)[1]]


def _multipliers_at(
    p_hat: np.ndarray, sigma: np.ndarray, lay: _Layout, W: list[int], p: np.ndarray, hints: np.ndarray
) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, dict[int, list[float]]]:
    """(active, multipliers (m,), μ, jacobian, directions) with the constraints W
    linearised at p and λ from the stationarity condition there (eqs. 58–60)."""
    if len(W) == 1:  # the usual case: one kernel call
        k, n3 = W[0], p.shape[0]
        mu = np.empty((n3, n3))
        G = np.empty((1, n3))
        ok, lam, u0, u1, u2 = _certify_pair(p_hat, sigma, lay.idx, lay.geo, k, hints, p, mu, G)
        if not ok:
            raise np.linalg.LinAlgError("constraint direction has zero variance")
        lam_full = np.zeros(lay.m)
        lam_full[k] = lam
        return W, lam_full, mu, G, {k: [u0, u1, u2][: lay.dims[k]]}
    pl = p.tolist()
    dirs = {k: _direction(lay.r(pl, k), hints, k) for k in W}
    _, W2, lam_full, mu, G = _finish(p_hat, sigma, lay, W, dirs, p_given=p)
    return W2, lam_full, mu, G, dirs
