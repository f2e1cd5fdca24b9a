"""The projection method for the distance constraints: [KFSC2015] eqs. 55–60, linearised at the solution.

Linearise the active constraints about a point and project p̂ (ENU, metres) onto
them as equalities, p* = p̂ − Σ Gᵀ (G Σ Gᵀ)⁻¹ (G p̂ − h), μ = Σ Gᵀ (G Σ Gᵀ)⁻¹ G
(:mod:`bodyfusion.core.constraints.linearisation`). The paper linearises once,
about p̂. Re-linearising about the new point and projecting again
(``scheme="fixed_point"``, kept as an option and as the last-resort fallback)
converges only linearly, and slowly when Σ is anisotropic: on random two-foot
problems it needed a median ≈ 12 iterations for 1e-9 m and often did not
converge in 100. So the default ``scheme="newton"`` finds the linearisation point
by Newton's method:

* one candidate constraint (violated, or ``fixed``) — the usual case: in the
  pair's difference space the solution is r(ν) = (I + ν S)⁻¹ r̂ with
  S = E B Σ Bᵀ Eᵀ (2x2 or 3x3) and ν = λ/‖r‖; ‖r(ν)‖ = d is solved by
  safeguarded Newton on 1/d − 1/‖r(ν)‖ (the Moré–Sorensen secular equation: a
  few scalar iterations, monotone for ``max``, the global minimum for the
  non-convex ``min``, the degenerate "hard case" in closed form). Eqs. 58–60 are
  then applied at that direction. With a single constraint all of it, including
  finding the constraint inactive (the early exit of most epochs), is one kernel
  call.
* several candidates: the SQP of :mod:`bodyfusion.core.constraints.sqp` with a
  small dense QP solver (Lawson–Hanson on the dual) in place of OSQP, then
  eqs. 58–60 at the converged point with that QP's active set.

When the separation of a single ``min``/``fixed`` constraint is zero (no direction,
see the hint directions of :mod:`bodyfusion.core.constraints.model`) the
projection solves that degenerate ("hard") case exactly: the systems separate
along the principal axis of largest relative uncertainty
S = E(Σ_ii − Σ_ij − Σ_ji + Σ_jj)Eᵀ, with the sign closest to the hint (east when
there is none).

:func:`project` is also the start and the fallback of the QP and SOCP solvers.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from bodyfusion.core.constraints.kernels import (_FAILED, _INACTIVE, PairSolution, StackedLimits, _project_pair,
                                                 _secular_limits)
from bodyfusion.core.constraints.linearisation import _finish
from bodyfusion.core.constraints.model import (ConstraintSolution, DistanceConstraint, _check_inputs, _direction,
                                               _hint_array, _layout, _Layout, _max_violation, _remember,
                                               _unconstrained_solution)
from bodyfusion.core.constraints.sqp import QpBackend, _sqp, _sqrt_cov

__all__ = ["solve_projection", "ProjectionSolver", "project", "fallback_solution"]


# ---------------------------------------------------------------------------
# linearised QP with a small dense dual active set (fixed-point scheme, several candidates)
# ---------------------------------------------------------------------------


def _dual_active_set(M: np.ndarray, e: np.ndarray, is_eq: np.ndarray, tol: float) -> np.ndarray:
    """min ½λᵀMλ − eᵀλ, λ_k ≥ 0 unless is_eq[k] (Lawson–Hanson on the dual QP).

    w = e − Mλ is the linearised constraint value (> 0 violated).
    """
    m = len(e)
    lam = np.zeros(m)
    free = [k for k in range(m) if is_eq[k]]

    def sub(Pset: list[int]) -> np.ndarray:
        Mp = M[np.ix_(Pset, Pset)]
        try:
            return np.linalg.solve(Mp, e[Pset])
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(Mp, e[Pset], rcond=None)[0]

    if free:
        lam[free] = sub(free)
    for _ in range(3 * m + 10):
        w = e - M @ lam
        cand = [k for k in range(m) if k not in free and w[k] > tol]
        if not cand:
            break
        free.append(max(cand, key=lambda k: w[k]))
        for _inner in range(3 * m + 10):
            z = sub(free)
            bad = [a for a, k in enumerate(free) if not is_eq[k] and z[a] <= 0.0]
            if not bad:
                lam[:] = 0.0
                lam[free] = z
                break
            alpha = min(lam[free[a]] / (lam[free[a]] - z[a]) for a in bad)
            cur = lam[free]
            new = cur + alpha * (z - cur)
            lam[:] = 0.0
            lam[free] = new
            free = [k for k in free if is_eq[k] or lam[k] > 1e-15]
            lam[[k for k in range(m) if k not in free]] = 0.0
    return lam


def _fixed_point(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    hints: np.ndarray,
    tol_m: float,
    max_iter: int,
) -> tuple[np.ndarray, list[int], dict[int, list[float]], int, bool]:
    """The paper's scheme: linearise all constraints about p, solve the linearised
    QP (dual active set), re-linearise about the new point, repeat."""
    p = p_hat.copy()
    is_eq = np.array([code == 2 for code in lay.code])
    sgn = [-1.0 if code == 1 else 1.0 for code in lay.code]
    plh = p_hat.tolist()
    rhat = [lay.r(plh, k) for k in range(lay.m)]
    W: list[int] = []
    for it in range(1, max_iter + 1):
        pl = p.tolist()
        dirs = [_direction(lay.r(pl, k), hints, k) for k in range(lay.m)]
        U = np.zeros((lay.offs[-1], lay.m))
        e = np.empty(lay.m)  # linearised constraint values at p̂: G p̂ − h
        for k in range(lay.m):
            U[lay.offs[k] : lay.offs[k + 1], k] = [sgn[k] * x for x in dirs[k]]
            e[k] = sgn[k] * (sum(a * b for a, b in zip(dirs[k], rhat[k])) - lay.d[k])
        G = U.T @ lay.bmat
        sig_gt = sigma @ G.T
        lam = _dual_active_set(G @ sig_gt, e, is_eq, 1e-3 * tol_m)
        p_new = p_hat - sig_gt @ lam
        W = [k for k in range(lay.m) if is_eq[k] or lam[k] > 0.0]
        step = float(np.max(np.abs(p_new - p)))
        p = p_new
        g, _ = lay.g_all(p.tolist())
        if step <= tol_m and _max_violation(lay, g) <= tol_m:
            pl = p.tolist()
            return p, W, {k: _direction(lay.r(pl, k), hints, k) for k in W}, it, True
    pl = p.tolist()
    return p, W, {k: _direction(lay.r(pl, k), hints, k) for k in W}, max_iter, False


def _dense_qp_backend(lay: _Layout, tol: float) -> QpBackend:
    """Small dense QP solver for :func:`_sqp` (dual active set, no OSQP, no warm start)."""
    sgn = lay.dual_sign
    is_eq = np.array([code == 2 for code in lay.code])

    def solve(P, q, A, lo, hi, y_warm, duals_warm):
        b = np.where(sgn < 0.0, -lo, hi)
        Ar = A * sgn[:, None]  # every row as Ar y ≤ b (== for fixed)
        sol = np.linalg.solve(P, np.column_stack([Ar.T, -q]))
        pinv_at, y0 = sol[:, :-1], sol[:, -1]
        lam = _dual_active_set(Ar @ pinv_at, Ar @ y0 - b, is_eq, 1e-3 * tol)
        return True, y0 - pinv_at @ lam, sgn * lam

    return solve


# ---------------------------------------------------------------------------
# projection driver
# ---------------------------------------------------------------------------


def _pair_solution(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    k: int,
    hints: np.ndarray,
    tol_m: float,
    max_iter: int,
    viol0: float | None,
) -> tuple[ConstraintSolution, dict[int, list[float]]] | None:
    """Constraint k projected alone (:func:`_project_pair`): (solution, {k: direction}).

    None when that fails, or when another constraint is violated at the result (if
    they all hold, it is a KKT point of the whole problem with the others'
    multipliers zero: the optimum when convex). ``viol0`` is the violation at p̂;
    None with a single constraint, whose kernel call also finds it inactive.
    """
    n3 = p_hat.shape[0]
    p = np.empty(n3)
    mu = np.empty((n3, n3))
    G = np.empty((1, n3))
    status, viol0k, viol1, lam, its, u0, u1, u2 = _project_pair(
        p_hat, sigma, StackedLimits(lay.idx, lay.geo, hints), k, *_secular_limits(tol_m, max_iter), PairSolution(p, mu, G)
    )
    if status == _INACTIVE:
        return _unconstrained_solution(p_hat, lay, "projection", 0.0), {}
    if status == _FAILED:
        return None
    if viol0 is None:
        viol0 = viol0k
    else:
        g1, _ = lay.g_all(p.tolist())
        if any(g1[q] > tol_m for q in range(lay.m) if q != k):
            return None
        viol1 = _max_violation(lay, g1)
    lam_full = np.zeros(lay.m)
    lam_full[k] = lam
    sol = ConstraintSolution(
        p=p, active=[k], multipliers=lam_full, gain=mu,
        violation_before_m=viol0, violation_after_m=viol1,
        iterations=its, converged=viol1 <= tol_m, method="projection", jacobian=G,
    )
    return sol, {k: [u0, u1, u2][: lay.dims[k]]}


def project(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    hints: np.ndarray,
    tol_m: float,
    max_iter: int,
    scheme: str = "newton",
) -> tuple[ConstraintSolution, dict[int, list[float]]]:
    """The projection method (module docstring): (solution, directions of its active constraints).

    ``hints`` (m, 3) as :func:`~bodyfusion.core.constraints.model._hint_array` makes
    them; read, not updated (:func:`~bodyfusion.core.constraints.model._remember`
    stores the directions returned)."""
    newton = scheme == "newton" and max_iter > 0
    if newton and lay.m == 1:
        # the usual case: a single kernel call, which also finds the constraint inactive
        out = _pair_solution(p_hat, sigma, lay, 0, hints, tol_m, max_iter, None)
        if out is not None:
            return out
    pl = p_hat.tolist()
    g0, _ = lay.g_all(pl)
    viol0 = _max_violation(lay, g0)
    W = [k for k in range(lay.m) if lay.code[k] == 2 or g0[k] > 0.0]
    if not W:
        return _unconstrained_solution(p_hat, lay, "projection", viol0), {}
    n3 = p_hat.shape[0]

    if newton:
        # --- one constraint active: try each candidate alone (most violated first; a
        # fixed constraint is always active, so with one only it can be tried). A
        # single constraint was tried above.
        if lay.m > 1:
            if len(W) == 1:
                singles = W
            else:
                fixed = [k for k in W if lay.code[k] == 2]
                singles = fixed if len(fixed) == 1 else (sorted(W, key=lambda q: -g0[q]) if not fixed else [])
            for k in singles:
                out = _pair_solution(p_hat, sigma, lay, k, hints, tol_m, max_iter, viol0)
                if out is not None:
                    return out
        # --- several candidates: SQP with a dense QP, then eq. 58 at its point ---
        L = _sqrt_cov(sigma)
        if L is not None:
            res = _sqp(p_hat, L, lay, hints, tol_m, max_iter, _dense_qp_backend(lay, tol_m), 1e-3 * tol_m)
            if res is not None and res[4]:
                p_s, _, duals, its, _ = res
                ps_l = p_s.tolist()
                # λ_k = ±dual (OSQP sign: > 0 at an upper bound, i.e. for max/fixed rows)
                Ws = [k for k in range(lay.m) if lay.code[k] == 2 or lay.dual_sign[k] * duals[k] > 0.0]
                dirs = {k: _direction(lay.r(ps_l, k), hints, k) for k in Ws}
                try:
                    p, Ws, lam_full, mu, G = _finish(p_hat, sigma, lay, Ws, dirs)
                except np.linalg.LinAlgError:
                    p = None
                if p is not None:
                    g1, _ = lay.g_all(p.tolist())
                    viol1 = _max_violation(lay, g1)
                    if viol1 <= tol_m and all(lam_full[k] >= 0.0 for k in Ws if lay.code[k] != 2):
                        return (
                            ConstraintSolution(
                                p=p, active=Ws, multipliers=lam_full, gain=mu,
                                violation_before_m=viol0, violation_after_m=viol1,
                                iterations=its, converged=True, method="projection",
                                jacobian=G,
                            ),
                            dirs,
                        )
    # --- fixed-point scheme (the paper's re-linearisation), also the fallback ---
    if max_iter <= 0:
        p, Wf, dirs, its, ok = p_hat.copy(), [], {}, 0, False
    else:
        p, Wf, dirs, its, ok = _fixed_point(p_hat, sigma, lay, hints, tol_m, max_iter)
    if Wf:
        dW = {k: dirs[k] for k in Wf}
        p, Wf, lam_full, mu, G = _finish(p_hat, sigma, lay, Wf, dW)
    else:
        lam_full, mu, G = np.zeros(lay.m), np.zeros((n3, n3)), np.zeros((0, n3))
    g1, _ = lay.g_all(p.tolist())
    viol1 = _max_violation(lay, g1)
    return (
        ConstraintSolution(
            p=p, active=Wf, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=viol1,
            iterations=its, converged=ok and viol1 <= tol_m, method="projection",
            jacobian=G,
        ),
        {k: dirs[k] for k in Wf},
    )


def fallback_solution(
    p_hat: np.ndarray, sigma: np.ndarray, lay: _Layout, hints: np.ndarray, tol_m: float, max_iter: int
) -> ConstraintSolution:
    """The projection in place of another solver that failed: :func:`project` with at
    least one iteration, its directions stored in ``hints``, ``fallback=True``."""
    sol, dirs = project(p_hat, sigma, lay, hints, tol_m, max(max_iter, 1))
    _remember(hints, dirs)
    sol.fallback = True
    return sol


def _check_scheme(scheme: str) -> str:
    if scheme not in ("newton", "fixed_point"):
        raise ValueError(f"scheme must be 'newton' or 'fixed_point', got {scheme!r}")
    return scheme


def solve_projection(
    p_hat: Any,
    sigma: Any,
    constraints: Sequence[DistanceConstraint],
    *,
    tol_m: float = 1e-6,
    max_iter: int = 20,
    scheme: str = "newton",
    hint_directions: Any = None,
) -> ConstraintSolution:
    """Projection method (eqs. 55–60), linearised at the solution.

    scheme: "newton" (default: the linearisation point is found by Newton's
    method — the secular equation for one candidate constraint, SQP for
    several; see the module docstring) or "fixed_point" (the paper's plain
    re-linearise-and-project iteration; linear convergence, often slow).
    max_iter: Newton/SQP iterations (the scalar secular solve allows
    max(4·max_iter, 60)); 0 returns p̂ unchanged with converged=False.
    hint_directions: optional (n_constraints, 3) directions used when a pair's
    separation is exactly zero (default east).
    """
    _check_scheme(scheme)
    p, s = _check_inputs(p_hat, sigma)
    lay = _layout(p.shape[0] // 3, constraints)
    sol, _ = project(p, s, lay, _hint_array(lay, hint_directions), tol_m, max_iter, scheme)
    return sol


class ProjectionSolver:
    """Projection method with the same interface as :class:`QpSolver`.

    Remembers each constraint's direction at the last solve and uses it when the
    separation is exactly zero (degenerate geometry).
    """

    method = "projection"

    def __init__(
        self,
        n_systems: int,
        constraints: Sequence[DistanceConstraint],
        *,
        tol_m: float = 1e-6,
        max_iter: int = 20,
        scheme: str = "newton",
    ) -> None:
        self.n_systems = int(n_systems)
        self.constraints = tuple(constraints)
        self._lay = _Layout(self.n_systems, self.constraints)
        self.tol_m = float(tol_m)
        self.max_iter = int(max_iter)
        self.scheme = _check_scheme(scheme)
        self._hints = _hint_array(self._lay)

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        p, s = _check_inputs(p_hat, sigma, self.n_systems)
        sol, dirs = project(p, s, self._lay, self._hints, self.tol_m, self.max_iter, self.scheme)
        _remember(self._hints, dirs)
        return sol
