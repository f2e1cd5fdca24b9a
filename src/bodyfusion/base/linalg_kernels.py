"""Compiled small dense linear algebra shared by the kernels of several packages."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, error_model="numpy")
def cholesky(S: np.ndarray, L: np.ndarray) -> bool:
    """Lower-triangular L with S = L Lᵀ (S's lower triangle is read); False unless S ≻ 0
    (a pivot not positive, or not a number)."""
    n = S.shape[0]
    for j in range(n):
        for i in range(j):
            L[i, j] = 0.0
        s = S[j, j]
        for t in range(j):
            s -= L[j, t] * L[j, t]
        if not s > 0.0:
            return False
        ljj = math.sqrt(s)
        L[j, j] = ljj
        for i in range(j + 1, n):
            acc = S[i, j]
            for t in range(j):
                acc -= L[i, t] * L[j, t]
            L[i, j] = acc / ljj
    return True
