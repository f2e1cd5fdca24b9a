"""The QP method for the distance constraints: OSQP on the SQP's whitened, linearised QPs.

The SQP of :mod:`bodyfusion.core.constraints.sqp` (y = L⁻¹ (p − p̂), p in ENU
metres, Σ = L Lᵀ; each QP the Newton step of the linearised constraints with
their curvature) with OSQP as its QP solver. OSQP is set up once with fixed
sparsity (dense upper triangle of P, dense A); each QP is
``update(Px, q, Ax, l, u)``, a warm start at the linearisation point (primal and
dual) and ``solve``. By default the SQP starts from the projection's point and
multipliers: when that is the KKT point, the first QP (the Newton step from it)
has it as its solution, the warm-started ADMM stops after one iteration, the
nonlinear constraints are checked to ``tol_m`` at OSQP's point and λ, μ
recomputed there by [KFSC2015] eqs. 58–60
(:mod:`bodyfusion.core.constraints.linearisation`): one QP per epoch (more SQP
steps when the start is not the KKT point). Started at p̂ instead
(``start="p_hat"``, independent of the projection): typically 3–6 QPs, a local
method (see :class:`QpSolver`).

Solver failure never raises: the projection solution is returned with
``fallback=True``.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from bodyfusion.core.constraints.kernels import _INACTIVE, _SOLVED, PairSolution, StackedLimits, _secular_limits
from bodyfusion.core.constraints.qp_kernels import PairStart, QpArrays, _qp_finish_pair, _qp_start_pair
from bodyfusion.core.constraints.linearisation import _certify
from bodyfusion.core.constraints.model import (ConstraintSolution, DistanceConstraint, _check_inputs, _hint_array,
                                               _Layout, _max_violation, _remember, _unconstrained_solution)
from bodyfusion.core.constraints.projection import fallback_solution, project
from bodyfusion.core.constraints.sqp import _settled, _sqp, _sqp_work, _sqrt_cov

_OSQP_SOLVED = 1  # OSQP's status value


class QpSolver:
    """Linearised QP of all constraints at once, solved by OSQP (see module docstring).

    Set up once with fixed sparsity; each QP updates P (dense upper triangle), q,
    A (dense), l, u and is warm-started (primal and dual) at the SQP's
    linearisation point. ``osqp_settings`` override the defaults. ``fast_calls``
    uses OSQP's compiled solver object directly (the operations of
    ``OSQP.update``/``warm_start``/``solve`` without their Python bookkeeping);
    the public API is used otherwise.

    Settings: eps_abs = eps_rel = 1e-8 on the whitened QP (y in units of Σ's
    square root); no scaling (whitening already makes P = I + H); the
    termination test at every ADMM iteration (warm-started at its solution, a QP
    stops after one); no polishing (a reduced KKT factorisation per solve, ≈ 10 µs,
    for accuracy nothing downstream uses: the nonlinear constraints are checked
    to tol_m at the QP's point and λ, μ are recomputed there by eq. 58).

    ``start="projection"`` (default): the SQP starts from the projection's point
    and multipliers, so one QP certifies that point when it is the KKT point
    (further SQP steps when it is not, e.g. a wrong active set). With a single
    constraint that is two kernel calls around one OSQP solve.
    ``start="p_hat"``: the SQP starts at p̂, independent of the projection
    (typically 3–6 QPs, ≤ 11 on random problems). It guarantees a KKT point: for
    ``max`` limits (convex) the solution; for ``min`` and ``fixed`` ones (non-convex)
    it is a local method, with the global minimum (the projection's) on random
    problems, but on exactly symmetric ones (coincident systems, or p̂'s separation
    on a principal axis of the pair's covariance) it can stop at a saddle point.
    """

    method = "qp"

    def __init__(
        self,
        n_systems: int,
        constraints: Sequence[DistanceConstraint],
        *,
        tol_m: float = 1e-6,
        max_iter: int = 20,
        osqp_settings: dict[str, Any] | None = None,
        fast_calls: bool = True,
        start: str = "projection",
    ) -> None:
        if start not in ("p_hat", "projection"):
            raise ValueError(f"start must be 'p_hat' or 'projection', got {start!r}")
        self.start = start

        self.n_systems = int(n_systems)
        self.constraints = tuple(constraints)
        self._lay = _Layout(self.n_systems, self.constraints)
        self.tol_m = float(tol_m)
        self.max_iter = int(max_iter)
        self._hints = _hint_array(self._lay)
        self.fallbacks = 0
        import osqp  # with scipy.sparse and jinja2 ~50 ms of every start otherwise: only QP runs load it
        import scipy.sparse as sp

        n3 = 3 * self.n_systems
        m = self._lay.m
        # CSC of the upper triangle stores column by column: rows 0..j of column j
        cols = np.concatenate([np.full(j + 1, j) for j in range(n3)])
        rows = np.concatenate([np.arange(j + 1) for j in range(n3)])
        P = sp.csc_matrix(((rows == cols).astype(float), rows, np.concatenate([[0], np.cumsum(np.arange(1, n3 + 1))])),
                          shape=(n3, n3))
        self._p_flat = rows * n3 + cols  # positions of the CSC triangle in a row-major n3×n3
        # A dense m × n3, CSC column-major: entries (0..m-1, j) per column
        a_indptr = np.arange(0, m * n3 + 1, m) if m else np.zeros(n3 + 1, dtype=int)
        a_indices = np.tile(np.arange(m), n3)
        A = sp.csc_matrix((np.ones(m * n3), a_indices, a_indptr), shape=(m, n3))
        settings = dict(
            eps_abs=1e-8, eps_rel=1e-8, eps_prim_inf=1e-12, eps_dual_inf=1e-12, scaling=0,
            polishing=False, warm_starting=True, verbose=False, max_iter=4000, check_termination=1,
        )
        if osqp_settings:
            settings.update(osqp_settings)
        self._osqp = osqp.OSQP()
        if m:
            self._osqp.setup(P, np.zeros(n3), A, np.full(m, -np.inf), np.full(m, np.inf), **settings)
        ext = getattr(self._osqp, "_solver", None)
        self._fast = bool(
            fast_calls and ext is not None and hasattr(ext, "update_data_mat")
            and hasattr(ext, "update_data_vec") and hasattr(ext, "warm_start") and hasattr(ext, "solution")
        )
        # QP buffers, reused (OSQP copies the data in); the single-constraint path's
        # L, projection p0, its multiplier and whitened point y0
        self._work = _sqp_work(n3, m)
        self._pair_work = np.empty((n3, n3)), np.empty(n3), np.empty(m), np.empty(n3)

    # -- OSQP calls -------------------------------------------------------
    def _qp(self, Px: np.ndarray, q: np.ndarray, Ax: np.ndarray, l: np.ndarray, u: np.ndarray,
            x0: np.ndarray, y0: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """Update every vector and matrix, warm-start at (x0, y0), solve: (status, x, y)."""
        if self._fast:
            ext = self._osqp._solver
            ext.update_data_vec(q, l, u)
            ext.update_data_mat(Px, None, Ax, None)
            ext.warm_start(x0, y0)
            ext.solve()
            sol = ext.solution
            return ext.info.status_val, sol.x, sol.y
        self._osqp.update(Px=Px, q=q, Ax=Ax, l=l, u=u)
        self._osqp.warm_start(x=x0, y=y0)
        res = self._osqp.solve(raise_error=False)
        return res.info.status_val, res.x, res.y

    def _backend(self, P: np.ndarray, q: np.ndarray, A: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 y_warm: np.ndarray, duals_warm: np.ndarray) -> tuple[bool, np.ndarray, np.ndarray]:
        """One QP of :func:`_sqp` through OSQP."""
        status, y, duals = self._qp(P.take(self._p_flat), q, A.ravel(order="F"), lo, hi, y_warm, duals_warm)
        return status == _OSQP_SOLVED, y, duals

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        p_hat, sigma = _check_inputs(p_hat, sigma, self.n_systems)
        try:
            sol = self._solve(p_hat, sigma)
        except Exception:  # never raise on solver failure
            sol = None
        if sol is None:
            return self._fallback(p_hat, sigma)
        return sol

    def _fallback(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution:
        self.fallbacks += 1
        return fallback_solution(p_hat, sigma, self._lay, self._hints, self.tol_m, self.max_iter)

    def _solve(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution | None:
        if self.start == "projection" and self._lay.m == 1 and self.max_iter > 0:
            sol = self._solve_pair(p_hat, sigma)
            if sol is not None:
                return sol
        return self._solve_sqp(p_hat, sigma)

    def _solve_pair(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution | None:
        """The usual case, one constraint: its projection certified by one QP, with
        a kernel call either side of OSQP (:func:`_qp_start_pair`,
        :func:`_qp_finish_pair`). None when that QP does not settle it, as judged by
        :func:`_sqp` and :func:`_certify`, or fails: then the general SQP runs."""
        lay = self._lay
        n3 = p_hat.shape[0]
        A, lo, hi, P, q, _ = self._work
        L, p0, duals, y0 = self._pair_work
        tol, its = _secular_limits(self.tol_m, self.max_iter)
        limits = StackedLimits(lay.idx, lay.geo, self._hints)
        status, viol0 = _qp_start_pair(p_hat, sigma, limits, 0, tol, its, PairStart(L, p0, duals, y0),
                                       QpArrays(A, lo, hi, P, q))
        if status == _INACTIVE:
            return _unconstrained_solution(p_hat, lay, "qp", viol0)
        if status != _SOLVED:
            return None
        ok, y, _ = self._backend(P, q, A, lo, hi, y0, duals)
        if not ok:
            return None
        p = np.empty(n3)
        mu = np.empty((n3, n3))
        G = np.empty((1, n3))
        step, g, ok, lam, u0, u1, u2 = _qp_finish_pair(p_hat, sigma, L, y, p0, limits, 0, PairSolution(p, mu, G))
        viol1 = _max_violation(lay, [g])
        if not (ok and _settled(viol1, step, math.inf, self.tol_m, self.tol_m)
                and (lay.has_fixed or (g >= -10.0 * self.tol_m and lam > 0.0))):
            return None
        _remember(self._hints, {0: [u0, u1, u2][: lay.dims[0]]})
        return ConstraintSolution(
            p=p, active=[0], multipliers=np.array([lam]), gain=mu,
            violation_before_m=viol0, violation_after_m=viol1,
            iterations=1, converged=True, method="qp", jacobian=G,
        )

    def _solve_sqp(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution | None:
        """The general case: SQP from the projection or from p̂, then :func:`_certify`."""
        lay = self._lay
        ref = None
        if self.start == "projection":
            ref, _ = project(p_hat, sigma, lay, self._hints, self.tol_m, self.max_iter)
            viol0 = ref.violation_before_m
        else:
            viol0 = _max_violation(lay, lay.g_all(p_hat.tolist())[0])
        if viol0 == 0.0 and not lay.has_fixed:
            return _unconstrained_solution(p_hat, lay, "qp", viol0)
        if self.max_iter <= 0:
            return None
        L = _sqrt_cov(sigma)
        if L is None:
            return None
        start = None if ref is None else (ref.p, lay.dual_sign * ref.multipliers)
        res = _sqp(p_hat, L, lay, self._hints, self.tol_m, self.max_iter, self._backend, start=start, work=self._work)
        if res is None or not res[4]:
            return None
        p, g, _, it, _ = res
        W, lam_full, mu, G, dirs = _certify(p_hat, sigma, lay, p, g, self._hints, 10.0 * self.tol_m)
        _remember(self._hints, dirs)
        return ConstraintSolution(
            p=p, active=W, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=_max_violation(lay, g),
            iterations=it, converged=True, method="qp", jacobian=G,
        )
