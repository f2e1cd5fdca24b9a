"""A filter's health as it runs: does each covariance and each update mean what it says?

- **Covariance checks**: P symmetric and positive semi-definite. The asymmetry is
  max |P − Pᵀ| (unit of P); the minimum eigenvalue is that of ½ (P + Pᵀ). The states mix
  units (m², rad², (m/s²)²...), so a violation is judged on the correlation form
  C = D^-½ ½(P + Pᵀ) D^-½, D = diag(P) (1 where a variance is 0): a non-finite entry, a
  negative variance, |P_ij − P_ji| > :data:`RTOL` √(P_ii P_jj), or λ_min(C) < −:data:`RTOL`
  (:class:`CovarianceHealth`).
- **NIS** of an m-dimensional update, yᵀ S⁻¹ y with y the innovation and S its covariance:
  a consistent filter averages m (:class:`NisTally`, :class:`NisRecord`, before any gating).
- **Quaternion norm**: max |‖q‖ − 1| over a run.

Every filter keeps these while it runs; metrics.json ``systems.<name>.health`` reports them
(docs/contract.md). The figures against truth (NEES) are :mod:`bodyfusion.evaluation.consistency`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bodyfusion.base.records import GrowingArray
from bodyfusion.nav.covariance_kernels import covariance_parts

RTOL = 1e-9
"""Relative tolerance of the covariance checks (asymmetry and negative eigenvalues of the
correlation form)."""
PROBES = 8
"""Covariances of a batch of checks decomposed first for the floor of the rest
(:meth:`CovarianceHealth.add_many`)."""


# --------------------------------------------------------------------------- covariance


def covariance_defects(P: np.ndarray, floor: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Asymmetry max |P − Pᵀ|, minimum eigenvalue of ½ (P + Pᵀ), and the violation flag of
    covariances P (..., n, n) (see the module docstring); each of shape (...).

    With a ``floor``, the minimum eigenvalue of a covariance certified above it and positive
    definite (:func:`~bodyfusion.nav.covariance_kernels.covariance_parts`) is not computed
    but NaN: what a running minimum at ``floor`` needs (:class:`CovarianceHealth`), at a
    Cholesky factorisation's cost instead of an eigenvalue decomposition's."""
    P = np.asarray(P, dtype=float)
    lead, n = P.shape[:-2], P.shape[-1]
    flat = np.ascontiguousarray(P.reshape(-1, n, n))
    sym = np.empty_like(flat)
    asym, flagged, lam_min = np.empty(len(flat)), np.empty(len(flat), dtype=bool), np.empty(len(flat))
    certified = np.empty(len(flat), dtype=bool)
    covariance_parts(flat, RTOL, np.nan if floor is None or n == 2 else float(floor), sym, asym, flagged, lam_min,
                     certified)
    if n != 2:  # a 2 × 2 (a trajectory's east–north covariance) has its closed form: LAPACK costs 10×
        lam_min.fill(np.nan)
        exact = ~certified
        lam_min[exact] = np.linalg.eigvalsh(sym[exact])[:, 0]
    # the correlation form D⁻¹ sym D⁻¹ has the inertia of sym (Sylvester): only a covariance
    # with a negative eigenvalue can fail its test, and only those are decomposed again
    negative = np.flatnonzero(lam_min < 0.0)
    if negative.size:
        var = np.diagonal(sym[negative], axis1=-2, axis2=-1)
        scale = np.sqrt(np.where(var > 0.0, var, 1.0))
        corr = sym[negative] / (scale[:, :, None] * scale[:, None, :])
        flagged[negative] |= np.linalg.eigvalsh(corr)[:, 0] < -RTOL
    return asym.reshape(lead), lam_min.reshape(lead), flagged.reshape(lead)


@dataclass
class CovarianceHealth:
    """Running figures of the covariance checks of one system: ``checks`` made,
    ``max_asymmetry`` (max |P − Pᵀ|), ``min_eigenvalue`` (of ½ (P + Pᵀ)), ``violations``
    (checks that failed, see :func:`covariance_defects`), the time of the first one (s), and
    the last check's asymmetry and minimum eigenvalue (``end``)."""

    checks: int = 0
    max_asymmetry: float = 0.0
    min_eigenvalue: float = float("inf")
    violations: int = 0
    first_violation_t_s: float | None = None
    end_asymmetry: float | None = None
    end_min_eigenvalue: float | None = None

    def add(self, P: np.ndarray, t: float) -> None:
        """Check one covariance P (n, n) at time t (s)."""
        self.add_many(np.asarray(P, dtype=float)[None], np.array([t], dtype=float))

    def add_many(self, covs: np.ndarray, t: np.ndarray) -> None:
        """Check covariances (K, n, n) at times t (K,) s, in time order.

        Only the smallest eigenvalue over all checks is kept, so only covariances that may hold
        it are decomposed: :data:`PROBES` of them, evenly spread and the last (the ``end``),
        are; their minimum and the running one give a floor, and the others are decomposed
        only where a Cholesky factorisation does not certify them above it
        (:func:`covariance_defects`). The same figures as decomposing every one, to the
        factorisation's rounding."""
        if len(covs) == 0:
            return
        if len(covs) > PROBES and covs.shape[-1] > 2:
            probes = np.linspace(0, len(covs) - 1, PROBES).round().astype(int)
            _, lam_probe, _ = covariance_defects(covs[probes])
            asym, lam, bad = covariance_defects(covs, min(self.min_eigenvalue, float(lam_probe.min())))
            lam[probes] = lam_probe
        else:
            asym, lam, bad = covariance_defects(covs)
        self.checks += len(covs)
        self.max_asymmetry = max(self.max_asymmetry, float(asym.max()))
        self.min_eigenvalue = min(self.min_eigenvalue, float(np.nanmin(lam)))
        self.violations += int(bad.sum())
        if self.first_violation_t_s is None and bad.any():
            self.first_violation_t_s = float(t[np.argmax(bad)])
        self.end_asymmetry, self.end_min_eigenvalue = float(asym[-1]), float(lam[-1])

    @classmethod
    def of(cls, covs: np.ndarray, t: np.ndarray, piece: int = 1 << 14) -> CovarianceHealth:
        """The figures of covariances (K, n, n) at times t (K,) s, checked ``piece`` at a time
        (the checks' temporaries are ~10 copies of what they check: a whole hour's at once
        held ~90 MB)."""
        health = cls()
        for a in range(0, len(covs), piece):
            health.add_many(covs[a:a + piece], t[a:a + piece])
        return health

    def to_dict(self) -> dict:
        """The metrics.json form."""
        return {"checks": self.checks, "max_asymmetry": self.max_asymmetry,
                "min_eigenvalue": self.min_eigenvalue if self.checks else None,
                "violations": self.violations, "first_violation_t_s": self.first_violation_t_s,
                "end": {"asymmetry": self.end_asymmetry, "min_eigenvalue": self.end_min_eigenvalue}}


def quaternion_norm_deviation(q: np.ndarray) -> float:
    """max |‖q‖ − 1| over quaternions (N, 4); 0 for none."""
    q = np.asarray(q, dtype=float)
    return float(np.max(np.abs(np.linalg.norm(q, axis=1) - 1.0), initial=0.0))


# --------------------------------------------------------------------------- NIS


def nis(y: np.ndarray, S: np.ndarray) -> float:
    """Normalised innovation squared yᵀ S⁻¹ y of innovation y (m,) with covariance S (m, m)."""
    y = np.atleast_1d(np.asarray(y, dtype=float))
    return float(y @ np.linalg.solve(np.atleast_2d(S), y))


@dataclass
class NisTally:
    """NIS of one aiding type of ``dof`` dimensions: ``count`` updates, the ``total`` of
    their NIS (before any gating; None: only the count is kept) and how many lay
    ``beyond_gate`` (rejected or de-weighted)."""

    dof: int
    count: int = 0
    total: float | None = 0.0
    beyond_gate: int = 0

    def add(self, value: float, within_gate: bool = True) -> None:
        """Count one update's NIS."""
        self.count += 1
        self.total += float(value)
        self.beyond_gate += int(not within_gate)

    def to_dict(self) -> dict:
        """The metrics.json form: ``mean`` (None without updates) beside its ``expected`` value,
        the measurement dimension."""
        return {"dof": self.dof, "expected": float(self.dof), "count": self.count,
                "mean": self.total / self.count if self.count and self.total is not None else None,
                "beyond_gate": self.beyond_gate}


class NisRecord:
    """Every update of one aiding type of ``dof`` dimensions: its time (s), its NIS before any
    gating and whether it lay within the gate, kept in growing arrays
    (:class:`~bodyfusion.base.records.GrowingArray`); :meth:`tally` is the metrics.json summary."""

    def __init__(self, dof: int) -> None:
        self.dof = dof
        self._rows = GrowingArray((3,))

    def add(self, t: float, value: float, within_gate: bool = True) -> None:
        """Record one update at time t (s)."""
        self._rows.append((t, value, within_gate))

    def __len__(self) -> int:
        return len(self._rows)

    def forget_before(self, t: float) -> None:
        """Drop the updates before ``t`` (s) (they are in time order)."""
        self._rows.drop_first(int(np.searchsorted(self._rows.view()[:, 0], t)))

    def tally(self) -> NisTally:
        """Count, NIS total and the updates beyond the gate."""
        rows = self._rows.view()
        return NisTally(self.dof, len(rows), float(rows[:, 1].sum()), int((rows[:, 2] == 0.0).sum()))

    def columns(self) -> dict[str, np.ndarray]:
        """``t`` (s), ``nis``, ``dof``, ``accepted`` (within the gate) of every update, in time order."""
        rows = self._rows.view()
        return {"t": rows[:, 0].copy(), "nis": rows[:, 1].copy(), "dof": np.full(len(rows), self.dof),
                "accepted": rows[:, 2] != 0.0}


def innovation_columns(parts: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The updates of several aiding types (name → its ``t``, ``nis``, ``dof``, ``accepted``
    columns, :meth:`NisRecord.columns`) as one set of columns in time order: ``t``, ``aiding``
    (the name), ``nis``, ``dof``, ``accepted``."""
    parts = [{**cols, "aiding": np.full(len(cols["t"]), kind)} for kind, cols in parts.items()]
    if not parts:
        return {}
    columns = {key: np.concatenate([p[key] for p in parts]) for key in ("t", "aiding", "nis", "dof", "accepted")}
    order = np.argsort(columns["t"], kind="stable")
    return {key: value[order] for key, value in columns.items()}
