"""The SOCP method for the distance constraints: cvxpy, a reference, not a hot path.

DPP (compiled once), in the whitened variable y = L⁻¹ (p − p̂) of
:mod:`bodyfusion.core.constraints.sqp` (p in ENU metres, Σ = L Lᵀ). ``max``
constraints are exact second-order cones; ``min`` constraints half-spaces
linearised about the current point (re-linearised until they settle); a ``fixed``
constraint is the cone when p̂ is outside the circle and the half-space when
inside. Interior-point solutions are only accurate to ≈ √gap along the
constraint surface (1e-7–1e-6 m seen with Clarabel), so the result is polished by
Newton steps on the KKT system of its active set, and λ, μ are [KFSC2015]
eqs. 58–60 at the polished point (:mod:`bodyfusion.core.constraints.linearisation`).
For ``min`` constraints the SOCP (linearised at p̂) can end at a different local
minimum than the projection, whose single-constraint solve is global.

Solver failure never raises: the projection solution is returned with
``fallback=True``.
"""

from __future__ import annotations

import math
import warnings
from typing import Any, Sequence

import numpy as np

from bodyfusion.base.extras import import_optional
from bodyfusion.core.constraints.kernels import _DEGENERATE_M
from bodyfusion.core.constraints.linearisation import _certify
from bodyfusion.core.constraints.model import (ConstraintSolution, DistanceConstraint, _check_inputs, _direction,
                                               _hint_array, _Layout, _max_violation, _remember,
                                               _unconstrained_solution)
from bodyfusion.core.constraints.projection import fallback_solution
from bodyfusion.core.constraints.sqp import _sqrt_cov


def _kkt_polish(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    W: list[int],
    p: np.ndarray,
    tol_m: float,
    max_steps: int = 6,
) -> np.ndarray | None:
    """Newton on the KKT system of the active set W, in y = L⁻¹(p − p̂):

        y + Σ λ_k ∇c_k(y) = 0,  c_k(y) = 0,   c_k = g_k(p̂ + L y).

    Interior-point solutions are accurate to ≈ √gap along the constraint
    surface (1e-7–1e-6 m here); two or three Newton steps make them exact.
    Returns the polished p, or None when Newton does not settle.
    """
    if not W:
        return p
    n3 = p_hat.shape[0]
    try:
        y = np.linalg.solve(L, p - p_hat)
    except np.linalg.LinAlgError:
        y = np.linalg.lstsq(L, p - p_hat, rcond=None)[0]
    blks = [L[lay.i3[k] : lay.i3[k] + lay.dims[k]] - L[lay.j3[k] : lay.j3[k] + lay.dims[k]] for k in W]
    plh = p_hat.tolist()
    rhat = [np.array(lay.r(plh, k)) for k in W]
    sg = [-1.0 if lay.code[k] == 1 else 1.0 for k in W]
    nW = len(W)
    lam = None
    for step in range(max_steps + 1):
        J = np.empty((nW, n3))
        c = np.empty(nW)
        Hs = []
        for a, k in enumerate(W):
            r = rhat[a] + blks[a] @ y
            rho = float(np.linalg.norm(r))
            if rho <= _DEGENERATE_M:
                return None
            u = r / rho
            ga = u @ blks[a]
            J[a] = sg[a] * ga
            c[a] = sg[a] * (rho - lay.d[k])
            Hs.append(sg[a] * (blks[a].T @ blks[a] - np.multiply.outer(ga, ga)) / rho)
        if lam is None:
            lam = -np.linalg.lstsq(J.T, y, rcond=None)[0]
        F1 = y + J.T @ lam
        if np.max(np.abs(F1)) <= 1e-11 * (1.0 + np.max(np.abs(y))) and np.max(np.abs(c)) <= 1e-4 * tol_m:
            if any(lay.code[k] != 2 and lam[a] < 0.0 for a, k in enumerate(W)):
                return None  # a KKT point of the wrong kind
            return p_hat + L @ y
        if step == max_steps:
            return None
        Hl = np.eye(n3) + sum(l * h for l, h in zip(lam, Hs))
        K = np.block([[Hl, J.T], [J, np.zeros((nW, nW))]])
        try:
            delta = np.linalg.solve(K, -np.concatenate([F1, c]))
        except np.linalg.LinAlgError:
            return None
        y = y + delta[:n3]
        lam = lam + delta[n3:]
    return None


def _pick_cvxpy_solver(cp: Any) -> str:
    installed = cp.installed_solvers()
    for name in ("CLARABEL", "ECOS", "SCS"):
        if name in installed:
            return name
    raise RuntimeError(f"no conic solver for cvxpy installed (have {installed})")


class SocpSolver:
    """Exact cones for ``max`` constraints, linearised ``min``/``fixed`` (cvxpy, DPP).

    Variables: y = L⁻¹ (p − p̂). Parameters: BL_k (D×3n), r̂_k (D) for the cones;
    a row and bound per linearised half-space. The problem is built once and is
    DPP (``is_dpp()``), so cvxpy compiles it at the first solve only. Solver:
    Clarabel, else ECOS, else SCS (tight tolerances; override with
    ``solver``/``solver_options``). The interior-point point is polished by
    Newton steps on the KKT system of its active set (module docstring).
    """

    method = "socp"

    def __init__(
        self,
        n_systems: int,
        constraints: Sequence[DistanceConstraint],
        *,
        tol_m: float = 1e-6,
        max_iter: int = 20,
        solver: str | None = None,
        solver_options: dict[str, Any] | None = None,
    ) -> None:
        # late: heavy to import (≈ 0.5 s), only this reference method uses it, an optional extra
        cp = import_optional("cvxpy", "socp", "fuser.method=socp")

        self._cp = cp
        self.n_systems = int(n_systems)
        self.constraints = tuple(constraints)
        self._lay = lay = _Layout(self.n_systems, self.constraints)
        self.tol_m = float(tol_m)
        self.max_iter = int(max_iter)
        self._hints = _hint_array(lay)
        self.fallbacks = 0
        n3 = 3 * self.n_systems
        self._n3 = n3
        self.solver = solver or _pick_cvxpy_solver(cp)
        opts: dict[str, Any] = {}
        if self.solver == "CLARABEL":
            opts = dict(tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10, tol_ktratio=1e-8, max_iter=200)
        elif self.solver == "ECOS":
            opts = dict(abstol=1e-10, reltol=1e-10, feastol=1e-10, max_iters=200)
        elif self.solver == "SCS":
            opts = dict(eps_abs=1e-9, eps_rel=1e-9, max_iters=200000)
        if solver_options:
            opts.update(solver_options)
        self._opts = opts
        self._y = cp.Variable(n3)
        self._cone: dict[int, tuple[Any, Any]] = {}
        self._half: dict[int, tuple[Any, Any]] = {}
        cons = []
        for k in range(lay.m):
            D, code = lay.dims[k], lay.code[k]
            if code in (0, 2):
                B = cp.Parameter((D, n3))
                r0 = cp.Parameter(D)
                self._cone[k] = (B, r0)
                cons.append(cp.norm(B @ self._y + r0, 2) <= lay.d[k])
            if code in (1, 2):
                a = cp.Parameter(n3)
                lb = cp.Parameter()
                self._half[k] = (a, lb)
                cons.append(a @ self._y >= lb)
        self._problem = cp.Problem(cp.Minimize(cp.sum_squares(self._y)), cons)
        if not self._problem.is_dpp():  # pragma: no cover - by construction
            raise RuntimeError("SOCP is not DPP")

    def is_dpp(self) -> bool:
        return bool(self._problem.is_dpp())

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        p_hat, sigma = _check_inputs(p_hat, sigma, self.n_systems)
        try:
            sol = self._solve(p_hat, sigma)
        except Exception:  # never raise on solver failure
            sol = None
        if sol is None:
            self.fallbacks += 1
            sol = fallback_solution(p_hat, sigma, self._lay, self._hints, self.tol_m, self.max_iter)
        return sol

    def _solve(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution | None:
        cp = self._cp
        lay = self._lay
        pl = p_hat.tolist()
        g0, rho0 = lay.g_all(pl)
        viol0 = _max_violation(lay, g0)
        if not lay.has_fixed and all(x <= 0.0 for x in g0):
            return _unconstrained_solution(p_hat, lay, "socp", viol0)
        if self.max_iter <= 0:
            return None
        L = _sqrt_cov(sigma)
        if L is None:
            return None
        BL = L[lay.plus] - L[lay.minus]
        rhat = [lay.r(pl, k) for k in range(lay.m)]
        for k, (B, r0) in self._cone.items():
            B.value = BL[lay.offs[k] : lay.offs[k + 1]]
            r0.value = np.array(rhat[k])
        zero_b = {k: np.zeros((lay.dims[k], self._n3)) for k in self._cone}
        p = p_hat
        converged = False
        it = 0
        zero = np.zeros(self._n3)
        g: list[float] = g0
        for it in range(1, self.max_iter + 1):
            pk = p.tolist()
            for k, (a, lb) in self._half.items():
                r = lay.r(pk, k)
                if lay.code[k] == 2:
                    # fixed: decided once from p̂. Outside the circle the cone alone is
                    # exact; inside, only the linearised half-space (the two together
                    # meet in a single point, which interior-point solvers dislike)
                    B, r0 = self._cone[k]
                    if rho0[k] > lay.d[k]:
                        B.value = BL[lay.offs[k] : lay.offs[k + 1]]
                        r0.value = np.array(rhat[k])
                        a.value, lb.value = zero, -1.0
                        continue
                    B.value, r0.value = zero_b[k], np.zeros(lay.dims[k])
                u = _direction(r, self._hints, k)
                a.value = np.asarray(u) @ BL[lay.offs[k] : lay.offs[k + 1]]
                lb.value = lay.d[k] - math.fsum([x * z for x, z in zip(u, rhat[k])])
            with warnings.catch_warnings():  # accuracy is checked (and polished) below
                warnings.simplefilter("ignore")
                self._problem.solve(solver=self.solver, warm_start=True, **self._opts)
            if self._problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self._y.value is None:
                return None
            p_new = p_hat + L @ np.asarray(self._y.value)
            step = float(np.max(np.abs(p_new - p)))
            p = p_new
            g, _ = lay.g_all(p.tolist())
            if _max_violation(lay, g) > 10.0 * self.tol_m and (not self._half or step > self.tol_m):
                continue  # keep re-linearising
            # polish on the active set of this solution; accept when it is a KKT point
            W, _, _, _, _ = _certify(p_hat, sigma, lay, p, g, self._hints, 1e3 * self.tol_m)
            pp = _kkt_polish(p_hat, L, lay, W, p, self.tol_m)
            # accept a feasible KKT point near the SOCP point: within 1 mm, or (while the
            # linearised min/fixed pieces still move) within 20 times the last step
            if W and pp is not None and float(np.max(np.abs(pp - p))) <= max(1e-3, 20.0 * step):
                gp, _ = lay.g_all(pp.tolist())
                if _max_violation(lay, gp) <= self.tol_m:
                    p, g = pp, gp
                    converged = True
                    break
            if _max_violation(lay, g) <= self.tol_m and (not self._half or step <= self.tol_m):
                converged = True  # unpolished but settled
                break
        if not converged:
            return None
        W, lam_full, mu, G, dirs = _certify(p_hat, sigma, lay, p, g, self._hints, 10.0 * self.tol_m)
        _remember(self._hints, dirs)
        return ConstraintSolution(
            p=p, active=W, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=_max_violation(lay, g),
            iterations=it, converged=True, method="socp", jacobian=G,
        )
