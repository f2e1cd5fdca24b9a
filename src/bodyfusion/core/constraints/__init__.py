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
      closed form). Eqs. 58–60 are then applied at that direction. With a
      single constraint all of it, including finding the constraint
      inactive (the early exit of most epochs), is one kernel call.
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
    triangle of P, dense A); each QP is ``update(Px, q, Ax, l, u)``, a warm
    start at the linearisation point (primal and dual) and ``solve``. By
    default the SQP starts from the projection's point and multipliers: when
    that is the KKT point, the first QP (the Newton step from it) has it as
    its solution, the warm-started ADMM stops after one iteration, the
    nonlinear constraints are checked to ``tol_m`` at OSQP's point and λ, μ
    recomputed there by eqs. 58–60: one QP per epoch (more SQP steps when the
    start is not the KKT point). Started at p̂ instead (``start="p_hat"``,
    independent of the projection): typically 3–4 QPs.
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

Implementation: the per-epoch work of the usual case — one constraint
(projection, certification of a QP's point), the QP's whitening and
linearisation — runs in numba kernels (scalar loops, cached on disk); several
active constraints, the fixed-point scheme and the SOCP use numpy.
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


@_kernel
def _separation(p: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, r: np.ndarray) -> float:
    """r ← r_k(p) = E (p_i + l_i − p_j − l_j) (first dims entries); returns ‖r_k(p)‖."""
    i3, j3 = idx[k, 0], idx[k, 1]
    n2 = 0.0
    for t in range(idx[k, 2]):
        r[t] = p[i3 + t] - p[j3 + t] + geo[k, 1 + t]
        n2 += r[t] * r[t]
    return math.sqrt(n2)


@_kernel
def _pair_gain(
    sigma: np.ndarray, idx: np.ndarray, k: int, u: np.ndarray, sgt: np.ndarray, gain: np.ndarray, jac: np.ndarray
) -> float:
    """Eqs. 58–60's matrices for constraint k linearised with unit direction u (its
    first dims entries): the Jacobian row G = s·(uᵀE on block i, −uᵀE on block j),
    s = −1 for ``min`` else 1, to jac[0]; Σ Gᵀ to sgt; μ = Σ Gᵀ G / M to gain.
    Returns M = G Σ Gᵀ (gain is meaningless unless M > 0).
    """
    n3 = sigma.shape[0]
    i3, j3, D = idx[k, 0], idx[k, 1], idx[k, 2]
    sgn = -1.0 if idx[k, 3] == 1 else 1.0
    for c in range(n3):
        jac[0, c] = 0.0
    for b in range(D):
        jac[0, i3 + b] = sgn * u[b]
        jac[0, j3 + b] -= sgn * u[b]
    M = 0.0
    for r in range(n3):
        acc = 0.0
        for b in range(D):
            acc += (sigma[r, i3 + b] - sigma[r, j3 + b]) * u[b]
        sgt[r] = sgn * acc
        M += jac[0, r] * sgt[r]
    inv_m = 1.0 / M
    for r in range(n3):
        for c in range(n3):
            gain[r, c] = sgt[r] * (jac[0, c] * inv_m)
    return M


@_kernel
def _pair_direction(
    p: np.ndarray, idx: np.ndarray, geo: np.ndarray, hints: np.ndarray, k: int, u: np.ndarray
) -> float:
    """u ← r_k(p)/‖r_k(p)‖ (first dims entries), the hint when ‖r_k‖ ≤ _DEGENERATE_M;
    returns ‖r_k(p)‖."""
    rho = _separation(p, idx, geo, k, u)
    for t in range(idx[k, 2]):
        u[t] = u[t] / rho if rho > _DEGENERATE_M else hints[k, t]
    return rho


@_kernel
def _certify_pair(
    p_hat: np.ndarray, sigma: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, hints: np.ndarray,
    p: np.ndarray, gain: np.ndarray, jac: np.ndarray,
) -> tuple[bool, float, float, float, float]:
    """Eqs. 58–60 at another solver's point p with constraint k active: its direction
    u at p (:func:`_pair_direction`), :func:`_pair_gain` there (gain, jac written) and
    λ = −G (p − p̂)/M, the least-squares multiplier of Σ⁻¹(p − p̂) + λ Gᵀ = 0.
    Returns (M > 0, λ, u0, u1, u2)."""
    u = np.zeros(3)
    _pair_direction(p, idx, geo, hints, k, u)
    sgt = np.empty(p.shape[0])
    M = _pair_gain(sigma, idx, k, u, sgt, gain, jac)
    acc = 0.0
    for c in range(p.shape[0]):
        acc += jac[0, c] * (p[c] - p_hat[c])
    return M > 0.0, -acc / M, u[0], u[1], u[2]


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
            if ct == 0.0:  # v from the hint instead
                for a in range(ntop):
                    c[a] = 0.0
                    for t in range(D):
                        c[a] += Q[a, t] * hint[t]
            rr2 = 0.0
            nv2 = 0.0
            for t in range(D):
                r[t] = 0.0  # the part outside T
                u[t] = 0.0  # v, not yet normalised
                for a in range(D):
                    if a < ntop:
                        u[t] += c[a] * Q[a, t]
                    else:
                        r[t] += c[a] / (1.0 - w[a] / smax) * Q[a, t]
                rr2 += r[t] * r[t]
                nv2 += u[t] * u[t]
            if rr2 < d * d:
                nv = math.sqrt(nv2)
                if not nv >= 1e-6:  # ±q_1, the sign closest to the hint
                    nv = 0.0
                    for t in range(D):
                        u[t] = Q[0, t]
                        nv += Q[0, t] * hint[t]
                    nv = -1.0 if nv < 0.0 else 1.0
                tau = math.sqrt(d * d - rr2)
                for t in range(D):  # ‖r + τ v‖ = d: the parts are orthogonal
                    u[t] = (r[t] + tau * u[t] / nv) / d
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
    """Constraint k alone: g_k(p̂); when it is violated (or ``fixed``), the direction u
    of the solution from the secular equation (:func:`_secular`, S = E B Σ Bᵀ Eᵀ) and
    eqs. 58–60 there: λ = s (u·r̂ − d)/M, p = p̂ − λ Σ Gᵀ (:func:`_pair_gain`; p, gain,
    jac written).

    Returns (status, violation at p̂, violation at p, λ, iterations, u0, u1, u2), the
    violations as in ``violation_before_m``; status _INACTIVE (g_k(p̂) ≤ 0, nothing
    written), _FAILED (nothing meaningful) or _SOLVED.
    """
    i3, j3, D, code = idx[k, 0], idx[k, 1], idx[k, 2], idx[k, 3]
    d = geo[k, 0]
    rhat = np.empty(3)
    rho = _separation(p_hat, idx, geo, k, rhat)
    v0 = abs(rho - d) if code == 2 else max(d - rho if code == 1 else rho - d, 0.0)
    if v0 == 0.0 and code != 2:
        return _INACTIVE, 0.0, 0.0, 0.0, 0, 0.0, 0.0, 0.0
    S = np.empty((3, 3))
    for a in range(D):
        for b in range(a, D):
            S[a, b] = sigma[i3 + a, i3 + b] - sigma[i3 + a, j3 + b] - sigma[j3 + a, i3 + b] + sigma[j3 + a, j3 + b]
    u = np.zeros(3)
    its = _secular(S, rhat, D, d, hints[k], tol, max_iter, u)
    if its < 0:
        return _FAILED, v0, v0, 0.0, its, 0.0, 0.0, 0.0
    sgt = np.empty(p_hat.shape[0])
    M = _pair_gain(sigma, idx, k, u, sgt, gain, jac)
    if not M > 0.0:
        return _FAILED, v0, v0, 0.0, its, 0.0, 0.0, 0.0
    ur = 0.0  # eq. 58: λ = s (u·r̂ − d)/M, p = p̂ − λ Σ Gᵀ
    for a in range(D):
        ur += u[a] * rhat[a]
    lam = (ur - d) / M if code != 1 else (d - ur) / M
    for c in range(p_hat.shape[0]):
        p[c] = p_hat[c] - lam * sgt[c]
    rho = _separation(p, idx, geo, k, rhat)
    v1 = abs(rho - d) if code == 2 else max(d - rho if code == 1 else rho - d, 0.0)
    return _SOLVED, v0, v1, lam, its, u[0], u[1], u[2]


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


# ---------------------------------------------------------------------------
# whitening and the SQP's QPs
# ---------------------------------------------------------------------------


@_kernel
def _cholesky(S: np.ndarray, L: np.ndarray) -> bool:
    """Lower-triangular L with S = L Lᵀ (S's lower triangle is read); False unless S ≻ 0."""
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


def _sqrt_cov(sigma: np.ndarray) -> np.ndarray | None:
    """L with Σ = L Lᵀ: Cholesky, or the symmetric square root for PSD Σ."""
    L = np.empty_like(sigma)
    if _cholesky(sigma, L):
        return L
    s = 0.5 * (sigma + sigma.T)
    w, V = np.linalg.eigh(s)
    if not np.all(np.isfinite(w)) or w[0] < -1e-9 * max(1.0, abs(w[-1])):
        return None
    return V * np.sqrt(np.clip(w, 0.0, None))


@_kernel
def _curvature_scale(H: np.ndarray, neg: np.ndarray) -> float:
    """The largest t in 1, ½, …, 2⁻²⁹ with I + H + t·neg ⪰ 0.1 I (a Cholesky
    factorisation of 0.9 I + H + t·neg succeeds), else 0."""
    n = H.shape[0]
    work = np.empty((n, n))
    fac = np.empty((n, n))
    t = 1.0
    for _ in range(30):
        for a in range(n):
            for b in range(n):
                work[a, b] = H[a, b] + t * neg[a, b]
            work[a, a] += 0.9
        if _cholesky(work, fac):
            return t
        t *= 0.5
    return 0.0


@_kernel
def _linearise(
    p_hat: np.ndarray, L: np.ndarray, idx: np.ndarray, geo: np.ndarray, hints: np.ndarray,
    p: np.ndarray, duals: np.ndarray, A: np.ndarray, lo: np.ndarray, hi: np.ndarray, P: np.ndarray,
) -> None:
    """The constraints of one SQP step (:func:`_sqp`) linearised at p, and its Hessian.

    Row k of A: a_k = u_kᵀ BL_k, BL_k = E B_k L, u_k the direction at p
    (:func:`_pair_direction`); bound lin_k = d_k − u_k·r̂_k into lo/hi on the side(s)
    of its kind (±1e30, OSQP's infinity, on the other). P = I + H with the curvature
    H = Σ_k duals_k (BL_kᵀBL_k − a_k a_kᵀ)/‖r_k‖ = Σ_k duals_k Lᵀ∇²‖r_k‖L; its
    negative part (duals < 0: active ``min``) scaled by :func:`_curvature_scale`.
    """
    n3 = p.shape[0]
    neg = np.zeros((n3, n3))
    has_neg = False
    BL = np.empty((3, n3))
    u = np.empty(3)
    rhat = np.empty(3)
    for a in range(n3):
        for b in range(n3):
            P[a, b] = 0.0
    for k in range(idx.shape[0]):
        i3, j3, D, code = idx[k, 0], idx[k, 1], idx[k, 2], idx[k, 3]
        rho = _pair_direction(p, idx, geo, hints, k, u)
        _separation(p_hat, idx, geo, k, rhat)
        lin = geo[k, 0]
        for t in range(D):
            lin -= u[t] * rhat[t]
        lo[k] = -1e30 if code == 0 else lin
        hi[k] = 1e30 if code == 1 else lin
        for c in range(n3):
            acc = 0.0
            for t in range(D):
                BL[t, c] = L[i3 + t, c] - L[j3 + t, c]
                acc += u[t] * BL[t, c]
            A[k, c] = acc
        if duals[k] == 0.0 or not rho > _DEGENERATE_M:
            continue
        wk = duals[k] / rho
        H = P if wk > 0.0 else neg
        has_neg = has_neg or wk < 0.0
        for a in range(n3):
            for b in range(n3):
                btb = 0.0
                for t in range(D):
                    btb += BL[t, a] * BL[t, b]
                H[a, b] += wk * (btb - A[k, a] * A[k, b])
    if has_neg:
        t = _curvature_scale(P, neg)
        for a in range(n3):
            for b in range(n3):
                P[a, b] += t * neg[a, b]
    for a in range(n3):
        P[a, a] += 1.0


@_kernel
def _stationary_point(A: np.ndarray, duals: np.ndarray, y: np.ndarray) -> None:
    """y = −Aᵀ duals: the whitened point at which multipliers ``duals`` (OSQP's sign)
    satisfy stationarity, y + Σ_k duals_k a_k = 0 (its KKT point, for the projection's)."""
    for c in range(A.shape[1]):
        acc = 0.0
        for k in range(A.shape[0]):
            acc -= duals[k] * A[k, c]
        y[c] = acc


@_kernel
def _linear_term(P: np.ndarray, y: np.ndarray, q: np.ndarray) -> None:
    """q = −H y = y − P y (P = I + H): the QP's linear term, its minimiser the Newton step from y."""
    for a in range(y.shape[0]):
        acc = y[a]
        for b in range(y.shape[0]):
            acc -= P[a, b] * y[b]
        q[a] = acc


@_kernel
def _advance(
    p_hat: np.ndarray, L: np.ndarray, y: np.ndarray, p: np.ndarray, idx: np.ndarray, geo: np.ndarray,
    p_new: np.ndarray, g: np.ndarray,
) -> float:
    """p_new = p̂ + L y and g_k(p_new) for every constraint (module docstring);
    returns the step max |p_new − p|, inf when p_new is not finite."""
    n3 = p.shape[0]
    step = 0.0
    for a in range(n3):
        acc = p_hat[a]
        for b in range(n3):
            acc += L[a, b] * y[b]
        p_new[a] = acc
        if not math.isfinite(acc):
            return math.inf
        step = max(step, abs(acc - p[a]))
    r = np.empty(3)
    for k in range(idx.shape[0]):
        rho = _separation(p_new, idx, geo, k, r)
        g[k] = geo[k, 0] - rho if idx[k, 3] == 1 else rho - geo[k, 0]
    return step


# the usual case, one constraint: the projection certified by one QP


@_kernel
def _qp_start_pair(
    p_hat: np.ndarray, sigma: np.ndarray, idx: np.ndarray, geo: np.ndarray, k: int, hints: np.ndarray,
    tol: float, max_iter: int, L: np.ndarray, p0: np.ndarray, duals: np.ndarray, y0: np.ndarray,
    A: np.ndarray, lo: np.ndarray, hi: np.ndarray, P: np.ndarray, q: np.ndarray,
) -> tuple[int, float]:
    """The QP that certifies the projection onto constraint k, the only one: the
    projection p0 (:func:`_project_pair`), its multiplier in OSQP's sign to duals[k],
    Σ = L Lᵀ (:func:`_cholesky`) and the SQP's QP at p0, started from that KKT point
    (:func:`_linearise`, :func:`_stationary_point` to y0, :func:`_linear_term`).
    Returns (status, violation at p̂); _FAILED also when Σ is not positive definite."""
    n3 = p_hat.shape[0]
    gain = np.empty((n3, n3))
    jac = np.empty((1, n3))
    status, v0, _, lam, _, _, _, _ = _project_pair(p_hat, sigma, idx, geo, k, hints, tol, max_iter, p0, gain, jac)
    if status != _SOLVED:
        return status, v0
    if not _cholesky(sigma, L):
        return _FAILED, v0
    duals[k] = -lam if idx[k, 3] == 1 else lam
    _linearise(p_hat, L, idx, geo, hints, p0, duals, A, lo, hi, P)
    _stationary_point(A, duals, y0)
    _linear_term(P, y0, q)
    return _SOLVED, v0


@_kernel
def _qp_finish_pair(
    p_hat: np.ndarray, sigma: np.ndarray, L: np.ndarray, y: np.ndarray, p0: np.ndarray, idx: np.ndarray,
    geo: np.ndarray, k: int, hints: np.ndarray, p: np.ndarray, gain: np.ndarray, jac: np.ndarray,
) -> tuple[float, float, bool, float, float, float, float]:
    """OSQP's point p = p̂ + L y of the QP of :func:`_qp_start_pair` (:func:`_advance`)
    and eqs. 58–60 there for constraint k (:func:`_certify_pair`; p, gain, jac
    written). Returns (step from p0, g_k(p), M > 0, λ, u0, u1, u2)."""
    g = np.empty(idx.shape[0])
    step = _advance(p_hat, L, y, p0, idx, geo, p, g)
    ok, lam, u0, u1, u2 = _certify_pair(p_hat, sigma, idx, geo, k, hints, p, gain, jac)
    return step, g[k], ok, lam, u0, u1, u2


def _sqp_work(n3: int, m: int) -> tuple[np.ndarray, ...]:
    """Buffers of :func:`_sqp`'s QPs: A (m, n3), lo, hi (m), P (n3, n3), q (n3), g (m)."""
    return np.empty((m, n3)), np.empty(m), np.empty(m), np.empty((n3, n3)), np.empty(n3), np.empty(m)


def _seed_duals(p_hat: np.ndarray, L: np.ndarray, lay: _Layout) -> np.ndarray:
    """Eq. 58's multiplier at p̂ of each violated (or fixed) constraint taken alone,
    (‖r̂‖ − d)/‖a‖² with a = (r̂/‖r̂‖)ᵀ E B L, in OSQP's sign: the first QP's curvature."""
    pl = p_hat.tolist()
    g0, rho0 = lay.g_all(pl)
    duals = np.zeros(lay.m)
    for k in range(lay.m):
        if (g0[k] > 0.0 or lay.code[k] == 2) and rho0[k] > _DEGENERATE_M:
            blk = L[lay.i3[k] : lay.i3[k] + lay.dims[k]] - L[lay.j3[k] : lay.j3[k] + lay.dims[k]]
            a = np.asarray([x / rho0[k] for x in lay.r(pl, k)]) @ blk
            duals[k] = (rho0[k] - lay.d[k]) / float(a @ a)
    return duals


def _sqp(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    hints: np.ndarray,
    tol: float,
    max_iter: int,
    backend,
    step_tol: float | None = None,
    start: tuple[np.ndarray, np.ndarray] | None = None,
    work: tuple[np.ndarray, ...] | None = None,
):
    """Sequential QP in y = L⁻¹(p − p̂) with the constraints' curvature.

    Each QP (:func:`_linearise`, :func:`_linear_term`):
    min ½ yᵀ(I + H)y − (H y_k)ᵀ y  s.t.  lo ≤ A y ≤ hi, with A the distance
    gradients at p_k (rows a_k = u_kᵀ E B_k L) and
    H = Σ_k y_k (BL_kᵀBL_k − a_k a_kᵀ)/‖r_k‖ = Σ_k y_k Lᵀ∇²‖r_k‖L, y_k the
    previous QP's multipliers in OSQP's sign (> 0 at an upper bound). Without
    ``start`` the SQP begins at p̂ and the first QP's curvature is seeded with
    eq. 58's multiplier of each violated constraint (:func:`_seed_duals`), so it
    is already a Newton step. ``start``: (p0, duals0), a KKT point and its
    multipliers in OSQP's sign (the projection's), whitened by
    :func:`_stationary_point`; the first QP is then the Newton step from there,
    its solution p0 itself. Negative curvature (active ``min`` constraints) is
    scaled down so that I + H ⪰ 0.1 I.

    ``backend(P, q, A, lo, hi, y_k, duals_k) -> (ok, y, duals)`` solves one QP,
    warm-started at the linearisation point. Converged: violations ≤ ``tol`` and
    the step ≤ ``step_tol`` (default ``tol``), or Newton's rate shows the next
    step would be. ``work``: :func:`_sqp_work` buffers to reuse. Returns (p, g(p),
    duals, iterations, converged), or None on QP failure; max_iter ≥ 1.
    """
    stol = tol if step_tol is None else step_tol
    n3, m = p_hat.shape[0], lay.m
    A, lo, hi, P, q, g_new = _sqp_work(n3, m) if work is None else work
    if start is None:
        p, duals, y = p_hat, _seed_duals(p_hat, L, lay), np.zeros(n3)
    else:
        (p, duals), y = start, np.empty(n3)
    prev_step = math.inf
    for it in range(1, max_iter + 1):
        _linearise(p_hat, L, lay.idx, lay.geo, hints, p, duals, A, lo, hi, P)
        if it == 1 and start is not None:
            _stationary_point(A, duals, y)
        _linear_term(P, y, q)
        ok, y_new, duals_new = backend(P, q, A, lo, hi, y, duals)
        if not ok:
            return None
        p_new = np.empty(n3)
        step = _advance(p_hat, L, y_new, p, lay.idx, lay.geo, p_new, g_new)
        if not math.isfinite(step):
            return None
        y, duals, p, g = y_new, duals_new, p_new, g_new.tolist()
        if _settled(_max_violation(lay, g), step, prev_step, tol, stol):
            return p, g, duals, it, True
        prev_step = step
    return p, g, duals, max_iter, False


def _settled(viol: float, step: float, prev_step: float, tol: float, stol: float) -> bool:
    """SQP convergence: violations ≤ tol and the step ≤ stol, or Newton's (quadratic)
    rate shows the next step (≈ step³/prev²) would be; the bounds keep this safe
    even under linear convergence (rate ≤ 0.01)."""
    return viol <= tol and (step <= stol or (step <= 100.0 * stol and step**3 <= 1e-2 * stol * prev_step**2))


def _dense_qp_backend(lay: _Layout, tol: float):
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


def _secular_limits(tol_m: float, max_iter: int) -> tuple[float, int]:
    """Tolerance on ‖r‖ − d and iteration limit of the secular equation (:func:`_secular`)."""
    return 1e-3 * tol_m, max(4 * max_iter, 60)


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
        p_hat, sigma, lay.idx, lay.geo, k, hints, *_secular_limits(tol_m, max_iter), p, mu, G
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


def _projection(
    p_hat: np.ndarray,
    sigma: np.ndarray,
    lay: _Layout,
    hints: np.ndarray,
    tol_m: float,
    max_iter: int,
    scheme: str = "newton",
) -> tuple[ConstraintSolution, dict[int, list[float]]]:
    """The projection method (module docstring): (solution, directions of its active constraints)."""
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
    sol, _ = _projection(p, s, lay, _hint_array(lay, hint_directions), tol_m, max_iter, scheme)
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
        self._hints = _hint_array(self._lay)

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        p, s = _check_inputs(p_hat, sigma, self.n_systems)
        sol, dirs = _projection(p, s, self._lay, self._hints, self.tol_m, self.max_iter, self.scheme)
        _remember(self._hints, dirs)
        return sol


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


# ---------------------------------------------------------------------------
# OSQP
# ---------------------------------------------------------------------------

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
    (typically 3–4 QPs).
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
        self._hints = _hint_array(self._lay)
        self.fallbacks = 0
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

    def _backend(self, P, q, A, lo, hi, y_warm, duals_warm):
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
        sol, dirs = _projection(p_hat, sigma, self._lay, self._hints, self.tol_m, max(self.max_iter, 1))
        _remember(self._hints, dirs)
        sol.fallback = True
        return sol

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
        status, viol0 = _qp_start_pair(p_hat, sigma, lay.idx, lay.geo, 0, self._hints, tol, its,
                                       L, p0, duals, y0, A, lo, hi, P, q)
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
        step, g, ok, lam, u0, u1, u2 = _qp_finish_pair(p_hat, sigma, L, y, p0, lay.idx, lay.geo, 0, self._hints,
                                                        p, mu, G)
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
            ref, _ = _projection(p_hat, sigma, lay, self._hints, self.tol_m, self.max_iter)
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



def _kkt_polish(
    p_hat: np.ndarray,
    L: np.ndarray,
    lay: _Layout,
    W: list[int],
    p: np.ndarray,
    hints: np.ndarray,
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
            sol, dirs = _projection(p_hat, sigma, self._lay, self._hints, self.tol_m, max(self.max_iter, 1))
            _remember(self._hints, dirs)
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
        _remember(self._hints, dirs)
        return ConstraintSolution(
            p=p, active=W, multipliers=lam_full, gain=mu,
            violation_before_m=viol0, violation_after_m=_max_violation(lay, g),
            iterations=it, converged=True, method="socp", jacobian=G,
        )
