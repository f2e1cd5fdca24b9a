"""Compiled part of the covariance checks (:func:`bodyfusion.nav.filter_health.covariance_defects`).

One pass over each covariance instead of a dozen numpy temporaries the size of the whole batch,
and a Cholesky certificate in place of an eigenvalue decomposition where the smallest
eigenvalue cannot matter (the checks run after every fuser correction: 18 → ~4 µs a 15 × 15
covariance)."""

from __future__ import annotations

import math

import numba
import numpy as np

from bodyfusion.base.linalg_kernels import cholesky


@numba.njit(cache=True)
def covariance_parts(P: np.ndarray, rtol: float, floor: float, sym: np.ndarray, asym: np.ndarray,
                     flagged: np.ndarray, lam_2x2: np.ndarray, certified: np.ndarray) -> None:
    """For each covariance P[k] (n, n): ``asym[k]`` = max |P − Pᵀ| (P's non-finite entries read
    as 0), ``flagged[k]`` when an entry is not finite, a variance of ½ (P + Pᵀ) is negative or
    |P_ij − P_ji| > ``rtol`` √(s_ii s_jj) (``rtol`` ≥ 0; s_ii read as 1 where it is not positive);
    for n = 2, ``lam_2x2[k]`` the smaller eigenvalue of ½ (P + Pᵀ) in closed form
    ½ (a + c) − hypot(½ (a − c), b).

    ``certified[k]`` (unless ``floor`` is NaN: then all False) when the smallest eigenvalue of
    ½ (P + Pᵀ) is above ``floor`` and it is positive definite: Cholesky factorisations of
    ½ (P + Pᵀ) − floor·I and (when floor < 0) of ½ (P + Pᵀ) succeed. Up to the factorisation's
    rounding (relative to its norm): a certified covariance can neither lower a minimum
    eigenvalue already at ``floor`` nor be indefinite. ``sym[k]`` = ½ (P + Pᵀ) where it is not
    certified (what is decomposed afterwards); left unwritten where it is."""
    K, n = P.shape[0], P.shape[1]
    scale = np.empty(n)
    S = np.empty((n, n))
    W = np.empty((n, n))
    L = np.empty((n, n))
    for k in range(K):
        finite = True
        for a in range(n):
            for b in range(n):
                if not math.isfinite(P[k, a, b]):
                    finite = False
        top = 0.0
        bad = not finite
        for a in range(n):
            for b in range(n):
                pab = P[k, a, b] if finite else 0.0
                pba = P[k, b, a] if finite else 0.0
                S[a, b] = 0.5 * (pab + pba)
        for a in range(n):
            v = S[a, a]
            if v < 0.0:
                bad = True
            scale[a] = math.sqrt(v) if v > 0.0 else 1.0
        for a in range(n):  # |P_ab − P_ba| is that of (b, a): each pair once
            for b in range(a + 1, n):
                pab = P[k, a, b] if finite else 0.0
                pba = P[k, b, a] if finite else 0.0
                d = abs(pab - pba)
                if d > top:
                    top = d
                if d != 0.0 and d / (scale[a] * scale[b]) > rtol:
                    bad = True
        asym[k] = top
        flagged[k] = bad
        if n == 2:
            lam_2x2[k] = 0.5 * (S[0, 0] + S[1, 1]) - math.hypot(0.5 * (S[0, 0] - S[1, 1]), S[0, 1])
        ok = False
        if not math.isnan(floor):
            for a in range(n):
                for b in range(n):
                    W[a, b] = S[a, b]
                W[a, a] -= floor
            ok = cholesky(W, L)
            if ok and floor < 0.0:
                ok = cholesky(S, L)
        certified[k] = ok
        if not ok:
            for a in range(n):
                for b in range(n):
                    sym[k, a, b] = S[a, b]
