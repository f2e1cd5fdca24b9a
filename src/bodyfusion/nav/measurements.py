"""Aiding measurements applied at discrete epochs (not per sample), with innovation gating.

Position fix: z = p_true + v, v ~ N(0, σ² I) (ENU, m); innovation y = z − p̂ = δp + v,
H = [I 0 0 0 0]. The fix is rejected when its normalised innovation squared
yᵀ S⁻¹ y exceeds the chi-square quantile of the configured gate probability (3 dof).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bodyfusion.nav.error_state import inject
from bodyfusion.nav.kalman import inv3_sym, update_selected


def chi2_gate(probability: float, dof: int) -> float:
    """NIS threshold that a consistent innovation of ``dof`` dimensions stays below
    with the given probability: the chi-square quantile 2 P⁻¹(dof/2, probability), P⁻¹ the
    inverse regularised lower incomplete gamma function (``scipy.stats.chi2.ppf`` bit for bit,
    without importing scipy.stats, which is slow to import)."""
    from scipy.special import gammaincinv

    return float(2 * gammaincinv(dof / 2, probability))


@dataclass
class GateCounts:
    """Accepted and rejected measurements of one kind."""

    accepted: int = 0
    rejected: int = 0


def position_fix_update(x: np.ndarray, P: np.ndarray, z_n: np.ndarray, sigma_m: float, gate_nis: float,
                        counts: GateCounts, phi: np.ndarray) -> float:
    """Gated position update of the 15-state filter; x (16,), P (15, 15) and the
    transition accumulator phi (see :func:`bodyfusion.nav.kalman.update_selected`) in place.

    Returns the NIS; a fix whose NIS exceeds ``gate_nis`` changes nothing.
    """
    y = np.ascontiguousarray(z_n - x[0:3], dtype=np.float64)
    r_var = sigma_m * sigma_m
    S = P[0:3, 0:3] + r_var * np.eye(3)
    nis = float(y @ inv3_sym(S) @ y)
    if nis > gate_nis:
        counts.rejected += 1
        return nis
    dx = np.empty(15)
    update_selected(P, np.int64(0), y, r_var, dx, phi)
    inject(x, dx)
    counts.accepted += 1
    return nis
