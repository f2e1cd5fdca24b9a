"""Compiled per-call steps of the phone's filter: its covariance time step (one hypothesis of the
bank); its measurement update is the project's one (:func:`bodyfusion.nav.kalman.kalman_update`).

The filter's matrices are small (n = 9 or 10 error states, m ≤ 3 measurement rows) and its
transitions and Jacobians mostly zero: compiled, a step costs a few microseconds where the
numpy expression of :mod:`bodyfusion.plugins.hand_pdr.bank_filter` cost tens (one call per
product, a new array each). Zero entries of F and H are skipped, which leaves every sum
unchanged; the sums of the products run in index order, so results agree with the numpy
(BLAS) products to rounding. One signature each: C-contiguous float64 arrays,
a float gate, ``phi`` (0, 0) when the fuser's transition Φ is not tracked; the product M ← A M
they both make twice is a kernel of its own (inlined at the four sites it cost 0.4–0.8 s more
of a cold start), the smaller helpers are inlined. The temporaries live in the compiled code
(no Python object per call).
"""

from __future__ import annotations

import numba
import numpy as np

from bodyfusion.base.linalg_kernels import assign, left_multiply, symmetrise


@numba.njit(cache=True)
def transition(P: np.ndarray, F: np.ndarray, Q: np.ndarray, phi: np.ndarray) -> None:
    """Time step of the error covariance in place: P ← (M + Mᵀ) / 2, M = F P Fᵀ + Q (all (n, n));
    and Φ ← F Φ when ``phi`` is (n, n) (the fuser's transition since its last sync)."""
    n = P.shape[0]
    work = np.empty((n, n))
    left_multiply(F, P, work)  # P ← F P
    for i in range(n):  # work ← (F P) Fᵀ + Q
        for j in range(n):
            s = 0.0
            for k in range(n):
                f = F[j, k]
                if f != 0.0:
                    s += P[i, k] * f
            work[i, j] = s + Q[i, j]
    assign(P, work)
    symmetrise(P)
    if phi.shape[0] == n:
        left_multiply(F, phi, work)
