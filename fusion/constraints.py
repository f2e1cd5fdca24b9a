"""Distance constraints between body-worn systems, solved in POSITION space.

The fuser stacks the constrained systems' position estimates
``p_hat = [p_1; ...; p_n]`` (3n,), ENU metres, with their marginal covariance
``sigma`` (3n, 3n), and asks this module for the constrained positions

    p* = argmin ½ (p − p̂)ᵀ Σ⁻¹ (p − p̂)   s.t. every DistanceConstraint holds,

plus the gain μ with Σ* = (I − μ) Σ (I − μ)ᵀ (PDR/GNSS paper, eqs. 55–60).
Spreading the correction to full error states is the fuser's job; note that
``Σ⁻¹ (p* − p̂) = −jacobianᵀ λ`` (fields of :class:`ConstraintSolution`), so it
needs no inverse of Σ.

Constraint k between systems i and j, with r_k(p) = E (p_i + l_i − p_j − l_j)
(E = [I2 0] when ``horizontal`` else I3; l are nav-frame lever arms):

* ``max``:   g_k(p) = ‖r_k‖ − d ≤ 0     (convex)
* ``min``:   g_k(p) = d − ‖r_k‖ ≤ 0     (non-convex)
* ``fixed``: g_k(p) = ‖r_k‖ − d = 0

Multiplier sign convention (all methods): the Lagrangian is
``½ (p − p̂)ᵀ Σ⁻¹ (p − p̂) + Σ_k λ_k g_k(p)``, so at the solution

    Σ⁻¹ (p* − p̂) + Σ_k λ_k ∇g_k(p*) = 0,   λ_k ≥ 0 for max/min,
    λ_k g_k(p*) = 0;  λ_k of a ``fixed`` constraint has either sign
    (> 0 when the systems were pulled together, < 0 when pushed apart).

Gradient of the distance: ∇‖r_k‖ = (+Eᵀu on block i, −Eᵀu on block j),
u = r_k/‖r_k‖; a lever arm shifts r_k but not the gradient. When
‖r_k‖ == 0 the direction is undefined: methods then use a *hint* direction —
the direction this constraint had at the previous solve of the same solver
object, else the one passed in ``hint_directions``, else east (+x). For a
single ``min``/``fixed`` constraint the projection solves that degenerate
("hard") case exactly: the systems separate along the principal axis of
largest relative uncertainty S = E(Σ_ii − Σ_ij − Σ_ji + Σ_jj)Eᵀ, with the sign
closest to the hint (east when there is none).

Methods
-------
All three reach the same point — the KKT point of the nonlinear problem, which
is also the fixed point of the paper's "linearise about the current point and
project" iteration — and report μ from eqs. 59–60 with the active constraints
linearised at p*.

``projection`` (:func:`solve_projection`, :class:`ProjectionSolver`)
    The paper's eqs. 55–60: linearise the active constraints about a point and
    project p̂ onto them as equalities,
    p* = p̂ − Σ Gᵀ (G Σ Gᵀ)⁻¹ (G p̂ − h), μ = Σ Gᵀ (G Σ Gᵀ)⁻¹ G.
    The paper linearises once, about p̂. Re-linearising about the new point
    and projecting again (``scheme="fixed_point"``, kept as an option and as
    the last-resort fallback) converges only linearly, and slowly when Σ is
    anisotropic: on random two-foot problems it needed a median ≈ 12
    iterations for 1e-9 m and often did not converge in 100. So the default
    ``scheme="newton"`` finds the linearisation point by Newton's method:

    * one candidate constraint (violated, or ``fixed``) — the usual case: in
      the pair's difference space the solution is r(ν) = (I + ν S)⁻¹ r̂ with
      S = E B Σ Bᵀ Eᵀ (2x2 or 3x3) and ν = λ/‖r‖; ‖r(ν)‖ = d is solved by
      safeguarded Newton on 1/d − 1/‖r(ν)‖ (the Moré–Sorensen secular
      equation: a few scalar iterations, monotone for ``max``, the global
      minimum for the non-convex ``min``, the degenerate "hard case" in
      closed form). Eqs. 58–60 are then applied at that direction.
    * several candidates: the SQP described under ``qp`` with a small dense
      QP solver (Lawson–Hanson on the dual) in place of OSQP, then eqs. 58–60
      at the converged point with that QP's active set.
``qp`` (:class:`QpSolver`)
    OSQP on the linearised problem in the whitened variable
    y = L⁻¹ (p − p̂), Σ = L Lᵀ (Cholesky; symmetric square root if Σ is only
    PSD): the objective is ½‖y‖² and each constraint is one row
    u_kᵀ (r̂_k + E B_k L y) {≤, ≥, =} d_k. Whitening makes the QP well
    conditioned whatever the scale of Σ and needs no Σ⁻¹. Re-linearised until
    the nonlinear constraints hold to ``tol_m`` and the step is below
    ``tol_m`` (or Newton's quadratic rate shows the next step would be). For
    the reason above the re-linearised QPs carry the constraints' curvature
    (a sequential-QP Newton step): P = I + Σ_k y_k Lᵀ ∇²‖r_k‖ L, y_k the
    previous QP's multipliers; the first QP's curvature is seeded with eq. 58's
    multipliers at p̂. Negative curvature (active ``min``) is scaled down to
    keep P ⪰ 0.1 I. OSQP is set up once with fixed sparsity (dense upper
    triangle of P, dense A); each QP is ``update(Px, q, Ax, l, u)`` plus a
    warm-started ``solve``. Typically 3 QPs per epoch.
``socp`` (:class:`SocpSolver`)
    cvxpy, DPP (compiled once), same whitened variable. ``max`` constraints
    are exact second-order cones; ``min`` constraints half-spaces linearised
    about the current point (re-linearised until they settle); a ``fixed``
    constraint is the cone when p̂ is outside the circle and the half-space
    when inside. Interior-point solutions are only accurate to ≈ √gap along
    the constraint surface (1e-7–1e-6 m seen with Clarabel), so the result is
    polished by Newton steps on the KKT system of its active set. For ``min``
    constraints the SOCP (linearised at p̂) can end at a different local
    minimum than the projection, whose single-constraint solve is global. A
    reference/oracle, not a hot path.

Solver failure never raises: :class:`QpSolver` and :class:`SocpSolver` then
return the projection solution with ``fallback=True``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numba
import numpy as np

__all__ = [
    "DistanceConstraint",
    "ConstraintSolution",
    "violations",
    "solve_projection",
    "ProjectionSolver",
    "QpSolver",
    "SocpSolver",
    "constrained_covariance",
]

KINDS = ("max", "min", "fixed")
_KIND_CODE = {"max": 0, "min": 1, "fixed": 2}
_DEGENERATE_M = 1e-12  # ‖r‖ below this (m) is "no direction"


# ---------------------------------------------------------------------------
# public data types
# ---------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class DistanceConstraint:
    """‖E (p_i + l_i − p_j − l_j)‖ {<=, >=, ==} distance_m, E = horizontal selector [I2 0] or I3."""

    i: int  # index of the first system in the stacked vector
    j: int
    kind: str  # "max" (<=), "min" (>=), "fixed" (==)
    distance_m: float
    horizontal: bool = True
    lever_i_m: np.ndarray | None = None  # (3,) nav-frame lever arm added to p_i
    lever_j_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"constraint kind must be one of {KINDS}, got {self.kind!r}")
        for name in ("i", "j"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                raise ValueError(f"constraint system index {name} must be an int >= 0, got {v!r}")
            object.__setattr__(self, name, int(v))
        if self.i == self.j:
            raise ValueError(f"constraint joins system {self.i} to itself")
        d = float(self.distance_m)
        if not math.isfinite(d) or d < 0.0 or (d == 0.0 and self.kind != "min"):
            raise ValueError(
                f"{self.kind} distance must be finite and > 0 (>= 0 for min), got {self.distance_m!r}"
            )
        object.__setattr__(self, "distance_m", d)
        object.__setattr__(self, "horizontal", bool(self.horizontal))
        for name in ("lever_i_m", "lever_j_m"):
            v = getattr(self, name)
            if v is None:
                continue
            a = np.array(v, dtype=float).reshape(-1)
            if a.shape != (3,) or not np.all(np.isfinite(a)):
                raise ValueError(f"{name} must be a finite (3,) vector, got {v!r}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "_hash", hash(self._key()))

    @property
    def dims(self) -> int:
        """Number of constrained components: 2 (horizontal) or 3."""
        return 2 if self.horizontal else 3

    def _key(self) -> tuple:
        li = None if self.lever_i_m is None else tuple(self.lever_i_m.tolist())
        lj = None if self.lever_j_m is None else tuple(self.lever_j_m.tolist())
        return (self.i, self.j, self.kind, self.distance_m, self.horizontal, li, lj)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, DistanceConstraint):
            return NotImplemented
        return self._key() == other._key()

    def __hash__(self) -> int:
        return self._hash  # type: ignore[attr-defined]


@dataclass
class ConstraintSolution:
    """Result of one constrained solve.

    p: (3n,) constrained positions.
    active: indices of the constraints active at the solution.
    multipliers: (n_constraints,) λ_k, 0 for inactive; convention in the module
        docstring (Σ⁻¹(p* − p̂) + Σ λ_k ∇g_k = 0, λ ≥ 0 for max/min).
    gain: (3n, 3n) μ with Σ* = (I − μ) Σ (I − μ)ᵀ; zeros when nothing is active.
    violation_before_m / violation_after_m: max over constraints of the
        (nonlinear) violation at p̂ / at p, 0 when all hold.
    iterations: solver iterations (Newton steps, QPs or SOCPs).
    converged: the nonlinear constraints hold to tol_m and the iteration settled.
    method: "projection", "qp" or "socp" — the method that produced ``p``.
    fallback: True when the requested solver failed and ``p`` is the projection.
    jacobian: (n_active, 3n) rows ∇g_k(p*) of the active constraints, in the
        order of ``active``; Σ⁻¹(p* − p̂) = −jacobianᵀ multipliers[active] and
        μ = Σ Jᵀ (J Σ Jᵀ)⁻¹ J.
    """

    p: np.ndarray
    active: list[int]
    multipliers: np.ndarray
    gain: np.ndarray
    violation_before_m: float
    violation_after_m: float
    iterations: int
    converged: bool
    method: str
    fallback: bool = False
    jacobian: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))


# ---------------------------------------------------------------------------
# layout: constraint geometry as small arrays, cached per constraint set
# ---------------------------------------------------------------------------


class _Layout:
    """Precomputed index geometry of a constraint set over n systems."""

    __slots__ = (
        "n", "m", "cons", "i3", "j3", "dims", "d", "code", "b", "has_fixed",
        "plus", "minus", "offs", "bmat", "idx", "geo", "dual_sign",
    )

    def __init__(self, n_systems: int, constraints: Sequence[DistanceConstraint]) -> None:
        cons = tuple(constraints)
        for k, c in enumerate(cons):
            if not isinstance(c, DistanceConstraint):
                raise TypeError(f"constraint {k} is not a DistanceConstraint: {c!r}")
            if c.i >= n_systems or c.j >= n_systems:
                raise ValueError(
                    f"constraint {k} joins systems {c.i} and {c.j}, but only {n_systems} are stacked"
                )
        self.n = n_systems
        self.m = len(cons)
        self.cons = cons
        self.i3 = [3 * c.i for c in cons]
        self.j3 = [3 * c.j for c in cons]
        self.dims = [c.dims for c in cons]
        self.d = [c.distance_m for c in cons]
        self.code = [_KIND_CODE[c.kind] for c in cons]
        self.has_fixed = any(code == 2 for code in self.code)
        b = []
        for c in cons:
            li = np.zeros(3) if c.lever_i_m is None else c.lever_i_m
            lj = np.zeros(3) if c.lever_j_m is None else c.lever_j_m
            b.append([float(x) for x in (li - lj)[: c.dims]])
        self.b = b
        plus, minus, offs = [], [], [0]
        for k in range(self.m):
            plus.extend(range(self.i3[k], self.i3[k] + self.dims[k]))
            minus.extend(range(self.j3[k], self.j3[k] + self.dims[k]))
            offs.append(offs[-1] + self.dims[k])
        self.plus = np.array(plus, dtype=np.intp)
        self.minus = np.array(minus, dtype=np.intp)
        self.offs = offs
        bm = np.zeros((len(plus), 3 * n_systems))
        bm[np.arange(len(plus)), self.plus] = 1.0
        bm[np.arange(len(plus)), self.minus] -= 1.0
        self.bmat = bm  # (K, 3n): r = bmat p + b
        # the same geometry for the kernels: (i3, j3, dims, kind code) and (d, b padded to 3)
        self.idx = np.array([[self.i3[k], self.j3[k], self.dims[k], self.code[k]] for k in range(self.m)],
                            dtype=np.int64).reshape(self.m, 4)
        self.geo = np.array([[self.d[k]] + self.b[k] + [0.0] * (3 - self.dims[k]) for k in range(self.m)],
                            dtype=float).reshape(self.m, 4)
        # OSQP's multiplier sign: > 0 at an upper bound (max, fixed), < 0 at a lower one (min)
        self.dual_sign = np.array([-1.0 if code == 1 else 1.0 for code in self.code])

    def r(self, pl: list[float], k: int) -> list[float]:
        """r_k as a Python list from positions given as a Python list."""
        i3, j3, b = self.i3[k], self.j3[k], self.b[k]
        return [pl[i3 + a] - pl[j3 + a] + b[a] for a in range(self.dims[k])]

    def g_all(self, pl: list[float]) -> tuple[list[float], list[float]]:
        """(g_k, ‖r_k‖) for every constraint; g as in the module docstring."""
        g, rho = [], []
        for k in range(self.m):
            r = self.r(pl, k)
            nr = math.sqrt(sum(x * x for x in r))
            rho.append(nr)
            code = self.code[k]
            g.append(self.d[k] - nr if code == 1 else nr - self.d[k])
        return g, rho

    def violation_values(self, g: list[float]) -> list[float]:
        return [abs(x) if code == 2 else x for x, code in zip(g, self.code)]

    def rows(self, W: Sequence[int]) -> np.ndarray:
        """Stacked component indices (into K) of the constraints in W."""
        out: list[int] = []
        for k in W:
            out.extend(range(self.offs[k], self.offs[k + 1]))
        return np.array(out, dtype=np.intp)


_LAYOUT_CACHE: dict[tuple, _Layout] = {}


def _layout(n_systems: int, constraints: Sequence[DistanceConstraint]) -> _Layout:
    key = (n_systems, tuple(constraints))
    lay = _LAYOUT_CACHE.get(key)
    if lay is None:
        if len(_LAYOUT_CACHE) > 256:
            _LAYOUT_CACHE.clear()
        lay = _Layout(n_systems, constraints)
        _LAYOUT_CACHE[key] = lay
    return lay


# Kernels: scalar loops only (array expressions cost numba compile time); the numpy
# error model gives IEEE inf/nan instead of exceptions, results carry a status instead.
_kernel = numba.njit(cache=True, error_model="numpy")


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


def _check_inputs(p_hat: Any, sigma: Any, n_systems: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """p̂ (3n,) and Σ (3n, 3n) as C-contiguous float arrays (the kernels' one signature)."""
    p = np.ascontiguousarray(p_hat, dtype=float)
    if p.ndim != 1 or p.shape[0] % 3 != 0 or p.shape[0] == 0:
        raise ValueError(f"p_hat must be a (3n,) vector, got shape {p.shape}")
    if n_systems is not None and p.shape[0] != 3 * n_systems:
        raise ValueError(f"p_hat must have shape ({3 * n_systems},), got {p.shape}")
    s = np.ascontiguousarray(sigma, dtype=float)
    if s.shape != (p.shape[0], p.shape[0]):
        raise ValueError(f"sigma must have shape {(p.shape[0], p.shape[0])}, got {s.shape}")
    if not _all_finite(p, s):
        raise ValueError("p_hat and sigma must be finite")
    return p, s


def _unit(v: Sequence[float]) -> list[float] | None:
    nv = math.sqrt(math.fsum([x * x for x in v]))
    if not nv > _DEGENERATE_M or not math.isfinite(nv):
        return None
    return [x / nv for x in v]


# Hint directions (module docstring) are kept resolved, one row per constraint of an
# (m, 3) array: the unit direction within the constraint's dims, zero-padded; east
# when there is none. Kernels and Python read row k's first dims entries.


def _hint_array(lay: _Layout, directions: Any = None) -> np.ndarray:
    """Hint rows from ``directions`` (m, ≤ 3) — each restricted to its constraint's dims,
    east where that is zero — or all east."""
    out = np.zeros((lay.m, 3))
    out[:, 0] = 1.0
    if directions is not None:
        h = np.asarray(directions, dtype=float).reshape(lay.m, -1)
        for k in range(lay.m):
            u = _unit(h[k, : lay.dims[k]].tolist())
            if u is not None:
                out[k] = 0.0
                out[k, : len(u)] = u
    return out


def _remember(hints: np.ndarray, dirs: dict[int, list[float]]) -> None:
    """Store the directions of a solve (unit, length dims) as the constraints' hints."""
    for k, u in dirs.items():
        hints[k, : len(u)] = u


def _hint(hints: np.ndarray, k: int, dim: int) -> list[float]:
    return hints[k, :dim].tolist()


def _direction(r: list[float], hints: np.ndarray, k: int) -> list[float]:
    u = _unit(r)
    return u if u is not None else _hint(hints, k, len(r))


# ---------------------------------------------------------------------------
# public helpers
# ---------------------------------------------------------------------------


def violations(p: Any, constraints: Sequence[DistanceConstraint]) -> np.ndarray:
    """Per-constraint violation (m) at ``p`` (3n,): >0 violated, ≤0 satisfied.

    max: ‖r‖ − d; min: d − ‖r‖; fixed: |‖r‖ − d| (never negative).
    """
    p = np.asarray(p, dtype=float)
    if p.ndim != 1 or p.shape[0] % 3 != 0:
        raise ValueError(f"p must be a (3n,) vector, got shape {p.shape}")
    lay = _layout(p.shape[0] // 3, constraints)
    g, _ = lay.g_all(p.tolist())
    return np.array(lay.violation_values(g), dtype=float)


def constrained_covariance(sigma: Any, gain: Any) -> np.ndarray:
    """Σ* = (I − μ) Σ (I − μ)ᵀ, symmetrised."""
    s = np.asarray(sigma, dtype=float)
    mu = np.asarray(gain, dtype=float)
    a = np.eye(s.shape[0]) - mu
    out = a @ s @ a.T
    return 0.5 * (out + out.T)


def _max_violation(lay: _Layout, g: list[float]) -> float:
    out = 0.0
    for x, code in zip(g, lay.code):
        if code == 2 and x < 0.0:
            x = -x
        if x > out:
            out = x
    return out


def _unconstrained_solution(p_hat: np.ndarray, lay: _Layout, method: str, viol: float) -> ConstraintSolution:
    n3 = p_hat.shape[0]
    return ConstraintSolution(
        p=p_hat.copy(),
        active=[],
        multipliers=np.zeros(lay.m),
        gain=np.zeros((n3, n3)),
        violation_before_m=viol,
        violation_after_m=viol,
        iterations=0,
        converged=True,
        method=method,
        jacobian=np.zeros((0, n3)),
    )


# ---------------------------------------------------------------------------
# eq. 58–60 on a set of linearised constraints
# ---------------------------------------------------------------------------


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
    if len(W) == 1:
        return _eq_project_single(p_hat, sigma, lay, W[0], dirs[W[0]], p_given)
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


def _eq_project_single(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    k: int,
    u: list[float],
    p_given: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_eq_project` for one constraint, by :func:`_eq58_pair`."""
    n3 = p_hat.shape[0]
    p = np.empty(n3) if p_given is None else p_given
    mu = np.empty((n3, n3))
    G = np.empty((1, n3))
    ok, lam = _eq58_pair(p_hat, sigma, lay.idx, lay.geo, k, np.array(u), p_given is not None, p, mu, G)
    if not ok:
        raise np.linalg.LinAlgError("constraint direction has zero variance")
    return p, np.array([lam]), mu, G


@_kernel
def _eq58_pair(
    p_hat: np.ndarray, sigma: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, u: np.ndarray,
    given: bool, p: np.ndarray, gain: np.ndarray, jac: np.ndarray,
) -> tuple[bool, float]:
    """Eqs. 58–60 for constraint k linearised with unit direction u (first dims entries).

    Jacobian row G = s·(uᵀE on block i, −uᵀE on block j), s = −1 for ``min`` else 1
    (written to jac[0]); M = G Σ Gᵀ; gain μ = Σ Gᵀ G / M. Projection (``given`` false):
    λ = s (u·r̂ − d)/M and p = p̂ − λ Σ Gᵀ (written to p). Given p (certifying another
    solver's point, p read): λ = −G (p − p̂)/M, the least-squares multiplier of
    Σ⁻¹(p − p̂) + λ Gᵀ = 0. Returns (M > 0, λ); nothing is meaningful when M ≤ 0.
    """
    n3 = p_hat.shape[0]
    i3, j3, D = idx[k, 0], idx[k, 1], idx[k, 2]
    sgn = -1.0 if idx[k, 3] == 1 else 1.0
    for c in range(n3):
        jac[0, c] = 0.0
    for b in range(D):
        jac[0, i3 + b] = sgn * u[b]
        jac[0, j3 + b] -= sgn * u[b]
    sgt = np.empty(n3)  # Σ Gᵀ
    M = 0.0
    for r in range(n3):
        acc = 0.0
        for b in range(D):
            acc += (sigma[r, i3 + b] - sigma[r, j3 + b]) * u[b]
        sgt[r] = sgn * acc
        M += jac[0, r] * sgt[r]
    if not M > 0.0:
        return False, 0.0
    if given:
        acc = 0.0
        for c in range(n3):
            acc += jac[0, c] * (p[c] - p_hat[c])
        lam = -acc / M
    else:
        ur = 0.0
        for b in range(D):
            ur += u[b] * (p_hat[i3 + b] - p_hat[j3 + b] + geo[k, 1 + b])
        lam = sgn * (ur - geo[k, 0]) / M
        for c in range(n3):
            p[c] = p_hat[c] - lam * sgt[c]
    inv_m = 1.0 / M
    for r in range(n3):
        for c in range(n3):
            gain[r, c] = sgt[r] * (jac[0, c] * inv_m)
    return True, lam


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


# ---------------------------------------------------------------------------
# projection, Newton scheme: one active constraint (scalar secular equation)
# ---------------------------------------------------------------------------

_SOLVED, _INACTIVE, _FAILED = 0, 1, 2  # status of _project_pair


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
            rr2 = 0.0
            for t in range(D):
                acc = 0.0
                for a in range(ntop, D):
                    acc += c[a] / (1.0 - w[a] / smax) * Q[a, t]
                r[t] = acc
                rr2 += acc * acc
            rr = math.sqrt(rr2)
            if rr < d:
                v = np.empty(3)
                nv2 = 0.0
                for t in range(D):
                    acc = 0.0
                    for a in range(ntop):
                        ca = c[a]
                        if ct == 0.0:
                            ca = 0.0
                            for s in range(D):
                                ca += Q[a, s] * hint[s]
                        acc += ca * Q[a, t]
                    v[t] = acc
                    nv2 += acc * acc
                nv = math.sqrt(nv2)
                if not nv >= 1e-6:
                    qh = 0.0
                    for t in range(D):
                        qh += Q[0, t] * hint[t]
                    nv = -1.0 if qh < 0.0 else 1.0
                    for t in range(D):
                        v[t] = Q[0, t]
                tau = math.sqrt(d * d - rr * rr)
                n2 = 0.0
                for t in range(D):
                    r[t] += tau * v[t] / nv
                    n2 += r[t] * r[t]
                nr = math.sqrt(n2)
                for t in range(D):
                    u[t] = r[t] / nr
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
    p_hat: np.ndarray, sigma: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, hints: np.ndarray,
    tol: float, max_iter: int, p: np.ndarray, gain: np.ndarray, jac: np.ndarray,
) -> tuple[int, float, float, float, int, float, float, float]:
    """Constraint k alone: g_k(p̂); when it is violated (or ``fixed``), the direction of
    the solution from the secular equation (:func:`_secular`, S = E B Σ Bᵀ Eᵀ) and
    eqs. 58–60 there (:func:`_eq58_pair`: p, gain, jac written).

    Returns (status, g_k(p̂), g_k(p), λ, iterations, u0, u1, u2); status _INACTIVE (g_k ≤ 0,
    nothing written) or _FAILED (nothing meaningful) or _SOLVED.
    """
    i3, j3, D, code = idx[k, 0], idx[k, 1], idx[k, 2], idx[k, 3]
    d = geo[k, 0]
    rhat = np.empty(3)
    n2 = 0.0
    for a in range(D):
        rhat[a] = p_hat[i3 + a] - p_hat[j3 + a] + geo[k, 1 + a]
        n2 += rhat[a] * rhat[a]
    rho = math.sqrt(n2)
    g0 = d - rho if code == 1 else rho - d
    if code != 2 and g0 <= 0.0:
        return _INACTIVE, g0, g0, 0.0, 0, 0.0, 0.0, 0.0
    S = np.empty((3, 3))
    for a in range(D):
        for b in range(a, D):
            S[a, b] = sigma[i3 + a, i3 + b] - sigma[i3 + a, j3 + b] - sigma[j3 + a, i3 + b] + sigma[j3 + a, j3 + b]
    u = np.zeros(3)
    its = _secular(S, rhat, D, d, hints[k], tol, max_iter, u)
    if its < 0:
        return _FAILED, g0, g0, 0.0, its, 0.0, 0.0, 0.0
    ok, lam = _eq58_pair(p_hat, sigma, idx, geo, k, u, False, p, gain, jac)
    if not ok:
        return _FAILED, g0, g0, 0.0, its, 0.0, 0.0, 0.0
    n2 = 0.0
    for a in range(D):
        x = p[i3 + a] - p[j3 + a] + geo[k, 1 + a]
        n2 += x * x
    rho = math.sqrt(n2)
    g1 = d - rho if code == 1 else rho - d
    return _SOLVED, g0, g1, lam, its, u[0], u[1], u[2]


# ---------------------------------------------------------------------------
# linearised QP with a small dense dual active set (fixed-point scheme)
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
    hints: dict[int, list[float]] | None,
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


# ---------------------------------------------------------------------------
# whitening
# ---------------------------------------------------------------------------


def _sqrt_cov(sigma: np.ndarray) -> np.ndarray | None:
    """L with Σ = L Lᵀ: Cholesky, or the symmetric square root for PSD Σ."""
    try:
        return np.linalg.cholesky(sigma)
    except np.linalg.LinAlgError:
        pass
    s = 0.5 * (sigma + sigma.T)
    w, V = np.linalg.eigh(s)
    if not np.all(np.isfinite(w)) or w[0] < -1e-9 * max(1.0, abs(w[-1])):
        return None
    return V * np.sqrt(np.clip(w, 0.0, None))


def _sqp(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    g0: list[float],
    rho0: list[float],
    hints: dict[int, list[float]] | None,
    tol: float,
    max_iter: int,
    backend,
    step_tol: float | None = None,
    start: tuple[np.ndarray, np.ndarray, list[float]] | None = None,
):
    """Sequential QP in y = L⁻¹(p − p̂) with the constraints' curvature.

    Each QP: min ½ yᵀ(I + H)y − (H y_k)ᵀ y  s.t.  lo ≤ A y ≤ hi, with A the
    distance gradients at p_k (rows a_k = u_kᵀ E B_k L) and
    H = Σ_k y_k (BL_kᵀBL_k − a_k a_kᵀ)/‖r_k‖ = Σ_k y_k Lᵀ∇²‖r_k‖L, y_k the
    previous QP's multipliers in OSQP's sign (> 0 at an upper bound). The
    first QP's curvature is seeded with eq. 58's multiplier of each violated
    constraint at p̂, so it is already a Newton step. Negative curvature
    (active ``min`` constraints) is scaled down so that I + H ⪰ 0.1 I.

    ``backend(H, q, A, lo, hi) -> (ok, y, duals)`` solves one QP. Converged:
    violations ≤ ``tol`` and the step ≤ ``step_tol`` (default ``tol``).
    ``start``: (p0, y0 = L⁻¹(p0 − p̂), duals0) instead of (p̂, 0, eq. 58 seeds).
    Returns (p, g(p), duals, iterations, converged), or None on QP failure.
    """
    stol = tol if step_tol is None else step_tol
    n3, m = p_hat.shape[0], lay.m
    pl = p_hat.tolist()
    blks = [L[lay.i3[k] : lay.i3[k] + lay.dims[k]] - L[lay.j3[k] : lay.j3[k] + lay.dims[k]] for k in range(m)]
    btb: list[np.ndarray | None] = [None] * m
    rhat = [lay.r(pl, k) for k in range(m)]
    duals = [0.0] * m
    for k in range(m if start is None else 0):
        if (g0[k] > 0.0 or lay.code[k] == 2) and rho0[k] > _DEGENERATE_M:
            a = np.asarray([x / rho0[k] for x in rhat[k]]) @ blks[k]
            duals[k] = (rho0[k] - lay.d[k]) / float(a @ a)
    eye = np.eye(n3)
    y = np.zeros(n3)
    p, pk = p_hat, pl
    if start is not None:
        p, y, duals = start[0], start[1], list(start[2])
        pk = p.tolist()
    A = np.empty((m, n3))
    lo = [0.0] * m
    hi = [0.0] * m
    prev_step = math.inf
    g = g0
    for it in range(1, max_iter + 1):
        H = None
        neg = None
        for k in range(m):
            r = lay.r(pk, k)
            rho = math.sqrt(math.fsum([x * x for x in r]))
            u = [x / rho for x in r] if rho > _DEGENERATE_M else _hint(hints, k, lay.dims[k])
            a = np.asarray(u) @ blks[k]
            A[k] = a
            lin = lay.d[k] - math.fsum([x * z for x, z in zip(u, rhat[k])])
            code = lay.code[k]
            lo[k] = -1e30 if code == 0 else lin
            hi[k] = 1e30 if code == 1 else lin
            if duals[k] != 0.0 and rho > _DEGENERATE_M:
                if btb[k] is None:
                    btb[k] = blks[k].T @ blks[k]
                curv = (duals[k] / rho) * (btb[k] - np.multiply.outer(a, a))
                if duals[k] > 0.0:
                    H = curv if H is None else H + curv
                else:
                    neg = curv if neg is None else neg + curv
        if neg is not None:
            base = eye if H is None else eye + H
            t = 1.0
            for _ in range(30):
                if np.linalg.eigvalsh(base + t * neg)[0] >= 0.1:
                    break
                t *= 0.5
            else:
                t = 0.0
            H = t * neg if H is None else H + t * neg
        q = None if H is None else -(H @ y)
        ok, y_new, yd = backend(H, q, A, lo, hi)
        if not ok:
            return None
        p_new = p_hat + L @ y_new
        pn = p_new.tolist()
        if not math.isfinite(math.fsum(pn)):
            return None
        step = max([abs(x - z) for x, z in zip(pn, pk)])
        y, duals, p, pk = y_new, yd, p_new, pn
        g, _ = lay.g_all(pk)
        if _max_violation(lay, g) <= tol and (
            step <= stol
            # Newton (quadratic) convergence: the next step would be ≈ step³/prev²;
            # the bounds keep this safe even under linear convergence (rate ≤ 0.01)
            or (step <= 100.0 * stol and step**3 <= 1e-2 * stol * prev_step**2)
        ):
            return p, g, duals, it, True
        prev_step = step
    return p, g, duals, max_iter, False


def _dense_qp_backend(lay: _Layout, tol: float):
    """Small dense QP solver for :func:`_sqp` (dual active set, no OSQP)."""
    sgn = np.array([-1.0 if code == 1 else 1.0 for code in lay.code])
    is_eq = np.array([code == 2 for code in lay.code])

    def solve(H, q, A, lo, hi):
        b = np.array([-lo[k] if lay.code[k] == 1 else hi[k] for k in range(lay.m)])
        Ar = A * sgn[:, None]  # every row as Ar y ≤ b (== for fixed)
        if H is None:
            pinv_at, y0 = Ar.T, np.zeros(A.shape[1])
        else:
            P = np.eye(A.shape[1]) + H
            sol = np.linalg.solve(P, np.column_stack([Ar.T, -q]))
            pinv_at, y0 = sol[:, :-1], sol[:, -1]
        lam = _dual_active_set(Ar @ pinv_at, Ar @ y0 - b, is_eq, 1e-3 * tol)
        return True, y0 - pinv_at @ lam, (sgn * lam).tolist()

    return solve


# ---------------------------------------------------------------------------
# projection driver
# ---------------------------------------------------------------------------


def _projection(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    hints: dict[int, list[float]] | None,
    tol_m: float,
    max_iter: int,
    scheme: str = "newton",
) -> tuple[ConstraintSolution, dict[int, list[float]]]:
    pl = p_hat.tolist()
    g0, _ = lay.g_all(pl)
    viol0 = _max_violation(lay, g0)
    W = [k for k in range(lay.m) if lay.code[k] == 2 or g0[k] > 0.0]
    if not W:
        return _unconstrained_solution(p_hat, lay, "projection", viol0), {}
    n3 = p_hat.shape[0]

    if scheme == "newton" and max_iter > 0:
        # --- fast path: one constraint active ------------------------------
        # Try each candidate alone (most violated first; a fixed constraint is
        # always active, so with one only it can be tried). If the result
        # satisfies every other constraint, it is a KKT point of the whole
        # problem with the others' multipliers zero (the optimum when convex).
        if len(W) == 1:
            singles = W
        else:
            fixed = [k for k in W if lay.code[k] == 2]
            singles = fixed if len(fixed) == 1 else (sorted(W, key=lambda q: -g0[q]) if not fixed else [])
        sl = sigma.tolist() if singles else None
        for k in singles:
            out = _single_fast(p_hat, pl, sl, lay, k, hints, tol_m, max_iter)
            if out is not None:
                p, lam, u, mu, G, its = out
                if lay.m == 1:
                    r = lay.r(p.tolist(), 0)
                    g1 = [math.sqrt(math.fsum([x * x for x in r])) - lay.d[0]]
                    if lay.code[0] == 1:
                        g1[0] = -g1[0]
                else:
                    g1, _ = lay.g_all(p.tolist())
                if all(g1[q] <= tol_m for q in range(lay.m) if q != k):
                    lam_full = np.zeros(lay.m)
                    lam_full[k] = lam
                    viol1 = _max_violation(lay, g1)
                    return (
                        ConstraintSolution(
                            p=p, active=[k], multipliers=lam_full, gain=mu,
                            violation_before_m=viol0, violation_after_m=viol1,
                            iterations=its, converged=viol1 <= tol_m, method="projection",
                            jacobian=G[None, :],
                        ),
                        {k: u},
                    )
        # --- several candidates: SQP with a dense QP, then eq. 58 at its point ---
        L = _sqrt_cov(sigma)
        if L is not None:
            _, rho0 = lay.g_all(pl)
            res = _sqp(
                p_hat, L, lay, g0, rho0, hints, tol_m, max_iter, _dense_qp_backend(lay, tol_m), 1e-3 * tol_m
            )
            if res is not None and res[4]:
                p_s, _, duals, its, _ = res
                ps_l = p_s.tolist()
                # λ_k = ±dual (OSQP sign: > 0 at an upper bound, i.e. for max/fixed rows)
                Ws = [k for k in range(lay.m) if lay.code[k] == 2 or (-duals[k] if lay.code[k] == 1 else duals[k]) > 0.0]
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
    if scheme not in ("newton", "fixed_point"):
        raise ValueError(f"scheme must be 'newton' or 'fixed_point', got {scheme!r}")
    p, s = _check_inputs(p_hat, sigma)
    lay = _layout(p.shape[0] // 3, constraints)
    hints = None
    if hint_directions is not None:
        h = np.asarray(hint_directions, dtype=float).reshape(lay.m, -1)
        hints = {k: h[k].tolist() for k in range(lay.m)}
    sol, _ = _projection(p, s, lay, hints, tol_m, max_iter, scheme)
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
        if scheme not in ("newton", "fixed_point"):
            raise ValueError(f"scheme must be 'newton' or 'fixed_point', got {scheme!r}")
        self.scheme = scheme
        self._hints: dict[int, list[float]] = {}

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        p, s = _check_inputs(p_hat, sigma, self.n_systems)
        sol, dirs = _projection(p, s, self._lay, self._hints, self.tol_m, self.max_iter, self.scheme)
        self._hints.update(dirs)
        return sol


def _certify(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    p: np.ndarray,
    g: list[float],
    hints: dict[int, list[float]] | None,
    tol_act: float,
) -> tuple[list[int], np.ndarray, np.ndarray, np.ndarray, dict[int, list[float]]]:
    """Active set, multipliers and μ at a solution ``p`` (with g = g(p)) found by an
    external solver: candidates are the fixed constraints and those within
    ``tol_act`` of their bound; λ from the stationarity condition at p (least
    squares), inequality constraints with λ ≤ 0 leave one by one."""
    pl = p.tolist()
    W = [k for k in range(lay.m) if lay.code[k] == 2 or g[k] >= -tol_act]
    dirs = {k: _direction(lay.r(pl, k), hints, k) for k in W}
    while True:
        _, W2, lam_full, mu, G = _finish(p_hat, sigma, lay, W, dirs, p_given=p)
        wrong = [(lam_full[k], k) for k in W2 if lay.code[k] != 2 and lam_full[k] <= 0.0]
        if not wrong:
            return W2, lam_full, mu, G, {k: dirs[k] for k in W2}
        W = [k for k in W if k != min(wrong)[1]]


# ---------------------------------------------------------------------------
# OSQP
# ---------------------------------------------------------------------------


class QpSolver:
    """Linearised QP of all constraints at once, solved by OSQP (see module docstring).

    Set up once with fixed sparsity; each solve updates P (dense upper triangle),
    q, A (dense), l, u and warm-starts. ``osqp_settings`` override the defaults
    (eps_abs = eps_rel = 1e-10, polishing on). ``fast_calls`` uses OSQP's
    compiled solver object directly for update/solve/solution when available
    (same operations as ``OSQP.update``/``OSQP.solve`` without their Python
    bookkeeping, which costs ≈ 25 µs per call); the public API is used otherwise.

    Tolerances: polishing solves the reduced KKT system of the identified active
    set exactly, so eps 1e-8 gives the same answers as 1e-10 (checked: 5e-8 m
    from the projection either way) with ~30 % fewer ADMM iterations.

    ``start="p_hat"`` (default): the SQP starts at p̂, independent of the
    projection. ``start="projection"``: it starts from the projection's point
    and multipliers, so OSQP certifies that point (one QP when it is the KKT
    point, further SQP steps when it is not, e.g. a wrong active set).
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
        start: str = "p_hat",
    ) -> None:
        import osqp
        import scipy.sparse as sp

        if start not in ("p_hat", "projection"):
            raise ValueError(f"start must be 'p_hat' or 'projection', got {start!r}")
        self.start = start

        self.n_systems = int(n_systems)
        self.constraints = tuple(constraints)
        self._lay = _Layout(self.n_systems, self.constraints)
        self.tol_m = float(tol_m)
        self.max_iter = int(max_iter)
        self._hints: dict[int, list[float]] = {}
        self.fallbacks = 0
        n3 = 3 * self.n_systems
        m = self._lay.m
        self._n3 = n3
        # CSC of the upper triangle stores column by column: rows 0..j of column j
        cols = np.concatenate([np.full(j + 1, j) for j in range(n3)])
        rows = np.concatenate([np.arange(j + 1) for j in range(n3)])
        self._p_rows, self._p_cols = rows, cols
        pdata = (rows == cols).astype(float)
        P = sp.csc_matrix((pdata, rows, np.concatenate([[0], np.cumsum(np.arange(1, n3 + 1))])), shape=(n3, n3))
        # A dense m × n3, CSC column-major: entries (0..m-1, j) per column
        a_indptr = np.arange(0, m * n3 + 1, m) if m else np.zeros(n3 + 1, dtype=int)
        a_indices = np.tile(np.arange(m), n3)
        A = sp.csc_matrix((np.ones(m * n3), a_indices, a_indptr), shape=(m, n3))
        settings = dict(
            eps_abs=1e-8, eps_rel=1e-8, eps_prim_inf=1e-12, eps_dual_inf=1e-12,
            polishing=True, polish_refine_iter=5, warm_starting=True, verbose=False,
            max_iter=4000, check_termination=5,
        )
        if osqp_settings:
            settings.update(osqp_settings)
        self._osqp = osqp.OSQP()
        self._m = m
        if m:
            self._osqp.setup(P, np.zeros(n3), A, np.full(m, -np.inf), np.full(m, np.inf), **settings)
        ext = getattr(self._osqp, "_solver", None)
        self._fast = bool(
            fast_calls and ext is not None and hasattr(ext, "update_data_mat")
            and hasattr(ext, "update_data_vec") and hasattr(ext, "solution")
        )
        self._solved_status = 1  # OSQP_SOLVED
        self._eye = np.eye(n3)
        self._zeros = np.zeros(n3)
        self._p_flat = rows * n3 + cols  # positions of the CSC triangle in a row-major n3×n3
        self._eye_tri = (rows == cols).astype(float)

    # -- OSQP calls -------------------------------------------------------
    def _qp(self, Px: np.ndarray, q: np.ndarray, Ax: np.ndarray, l: np.ndarray, u: np.ndarray):
        l = np.array(l, dtype=float)
        u = np.array(u, dtype=float)
        if self._fast:
            ext = self._osqp._solver
            ext.update_data_vec(q=q, l=l, u=u)
            ext.update_data_mat(P_x=Px, P_i=None, A_x=Ax, A_i=None)
            ext.solve()
            status = int(ext.info.status_val)
            sol = ext.solution
            return status, np.array(sol.x), np.array(sol.y)
        self._osqp.update(Px=Px, q=q, Ax=Ax, l=l, u=u)
        res = self._osqp.solve(raise_error=False)
        return int(res.info.status_val), np.array(res.x), np.array(res.y)

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
        sol, dirs = _projection(p_hat, sigma, self._lay, self._hints, self.tol_m, max(self.max_iter, 1))
        self._hints.update(dirs)
        sol.fallback = True
        return sol

    def _backend(self, H, q, A, lo, hi):
        """One QP through OSQP (fixed sparsity: dense triangle of P, dense A)."""
        if H is None:
            Px, q = self._eye_tri, self._zeros
        else:
            Px = (self._eye + H).take(self._p_flat)
        Ax = A[0] if self._m == 1 else A.T.reshape(-1)
        status, y, yd = self._qp(Px, q, Ax, lo, hi)
        return status == self._solved_status, y, yd.tolist()

    def _solve(self, p_hat: np.ndarray, sigma: np.ndarray) -> ConstraintSolution | None:
        lay = self._lay
        g0, rho0 = lay.g_all(p_hat.tolist())
        viol0 = _max_violation(lay, g0)
        if not lay.has_fixed and all(x <= 0.0 for x in g0):
            return _unconstrained_solution(p_hat, lay, "qp", viol0)
        if self.max_iter <= 0:
            return None
        L = _sqrt_cov(sigma)
        if L is None:
            return None
        start = None
        if self.start == "projection":
            ref, _ = _projection(p_hat, sigma, lay, self._hints, self.tol_m, self.max_iter)
            # p_ref − p̂ = −Σ Jᵀλ = −L Lᵀ Jᵀλ, so y0 = −Lᵀ Jᵀλ; OSQP's multiplier sign is
            # > 0 at an upper bound (max, fixed) and < 0 for min
            y0 = -(L.T @ (ref.jacobian.T @ ref.multipliers[ref.active])) if ref.active else np.zeros(p_hat.shape[0])
            duals0 = [(-x if lay.code[k] == 1 else x) for k, x in enumerate(ref.multipliers.tolist())]
            start = (ref.p, y0, duals0)
        res = _sqp(p_hat, L, lay, g0, rho0, self._hints, self.tol_m, self.max_iter, self._backend, start=start)
        if res is None or not res[4]:
            return None
        p, g, _, it, _ = res
        W, lam_full, mu, G, dirs = _certify(p_hat, sigma, lay, p, g, self._hints, 10.0 * self.tol_m)
        self._hints.update(dirs)
        return ConstraintSolution(
            p=p, active=W, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=_max_violation(lay, g),
            iterations=it, converged=True, method="qp", jacobian=G,
        )


def _kkt_polish(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    W: list[int],
    p: np.ndarray,
    hints: dict[int, list[float]] | None,
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


# ---------------------------------------------------------------------------
# cvxpy SOCP
# ---------------------------------------------------------------------------


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
        import cvxpy as cp

        self._cp = cp
        self.n_systems = int(n_systems)
        self.constraints = tuple(constraints)
        self._lay = lay = _Layout(self.n_systems, self.constraints)
        self.tol_m = float(tol_m)
        self.max_iter = int(max_iter)
        self._hints: dict[int, list[float]] = {}
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
            sol, dirs = _projection(p_hat, sigma, self._lay, self._hints, self.tol_m, max(self.max_iter, 1))
            self._hints.update(dirs)
            sol.fallback = True
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
            pp = _kkt_polish(p_hat, L, lay, W, p, self._hints, self.tol_m)
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
        self._hints.update(dirs)
        return ConstraintSolution(
            p=p, active=W, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=_max_violation(lay, g),
            iterations=it, converged=True, method="socp", jacobian=G,
        )
