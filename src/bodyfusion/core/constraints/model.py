"""Distance constraints between body-worn systems: the problem, its conventions, its data.

The fuser stacks the constrained systems' position estimates
``p_hat = [p_1; ...; p_n]`` (3n,), ENU metres, with their marginal covariance
``sigma`` (3n, 3n), m², and asks the solvers for the constrained positions

    p* = argmin ½ (p − p̂)ᵀ Σ⁻¹ (p − p̂)   s.t. every DistanceConstraint holds,

plus the gain μ with Σ* = (I − μ) Σ (I − μ)ᵀ ([KFSC2015] eqs. 55–60).
Spreading the correction to full error states is the fuser's job; note that
``Σ⁻¹ (p* − p̂) = −jacobianᵀ λ`` (fields of :class:`ConstraintSolution`), so it
needs no inverse of Σ.

Constraint k between systems i and j, with r_k(p) = E (p_i + l_i − p_j − l_j)
(E = [I2 0] when ``horizontal`` else I3; l are nav-frame lever arms, metres):

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
object, else the one passed in ``hint_directions``, else east (+x).

Here: :class:`DistanceConstraint`, :class:`ConstraintSolution`, the constraint
set's index geometry (:class:`_Layout`, cached per set), the input checks, the hint
directions, :func:`violations`, :func:`linearised` and :func:`constrained_covariance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from bodyfusion.core.constraints.kernels import _DEGENERATE_M, _all_finite

KINDS = ("max", "min", "fixed")
_KIND_CODE = {"max": 0, "min": 1, "fixed": 2}


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


# ---------------------------------------------------------------------------
# input checks and hint directions
# ---------------------------------------------------------------------------


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
# violations and solutions
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


def linearised(p: np.ndarray, constraints: Sequence[DistanceConstraint]) -> tuple[np.ndarray, np.ndarray]:
    """Every constraint's g_k (m; ≤ 0 where it holds) and its gradient ∇g_k (K, 3n) at the
    stacked positions p (3n,): the rows ±Eᵀu of the module docstring (zero where ‖r_k‖ = 0)."""
    lay = _layout(p.shape[0] // 3, constraints)
    pl = p.tolist()
    g, rho = lay.g_all(pl)
    J = np.zeros((lay.m, p.shape[0]))
    for k in range(lay.m):
        if rho[k] > 0.0:
            u = np.asarray(lay.r(pl, k)) / (-rho[k] if lay.code[k] == 1 else rho[k])
            J[k, lay.i3[k]:lay.i3[k] + lay.dims[k]] = u
            J[k, lay.j3[k]:lay.j3[k] + lay.dims[k]] = -u
    return np.asarray(g), J


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
