"""One protocol for the methods that solve the distance constraints, and the layout's choice of one.

Every method (:class:`~bodyfusion.core.constraints.projection.ProjectionSolver`,
:class:`~bodyfusion.core.constraints.qp.QpSolver` on OSQP,
:class:`~bodyfusion.core.constraints.socp.SocpSolver` on cvxpy) is a :class:`ConstraintSolver`:
built once for ``n_systems`` stacked positions and a set of
:class:`~bodyfusion.core.constraints.model.DistanceConstraint`, with a tolerance (m) and an
iteration cap, then asked for the constrained point of each epoch's p̂ (3n,) m and Σ (3n, 3n) m².
The fuser, the constraints on smoothed tracks and the compile-ahead all build theirs with
:func:`constraint_solver`, from the layout's ``fuser`` section.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

from bodyfusion.core.constraints.model import ConstraintSolution, DistanceConstraint
from bodyfusion.core.constraints.projection import ProjectionSolver
from bodyfusion.core.constraints.qp import QpSolver
from bodyfusion.core.constraints.socp import SocpSolver
from bodyfusion.core.layout import ConstraintConfig, FuserConfig


@runtime_checkable
class ConstraintSolver(Protocol):
    """A constraint-solving method (module docstring): its ``method`` name, and :meth:`solve`.
    Construction: ``(n_systems, constraints, *, tol_m, max_iter)``."""

    method: str

    def solve(self, p_hat: Any, sigma: Any) -> ConstraintSolution:
        """The constrained positions p* (3n,) m nearest p̂ in Σ's metric, with the multipliers
        and the gain μ of Σ* = (I − μ) Σ (I − μ)ᵀ; never raises for a failed solve (a fallback
        to the projection is flagged in the solution)."""
        ...


SOLVERS: dict[str, type[ConstraintSolver]] = {"projection": ProjectionSolver, "qp": QpSolver, "socp": SocpSolver}
"""The methods by the layout's ``fuser.method``."""


def distance_constraints(configs: Sequence[ConstraintConfig], order: Sequence[str]) -> list[DistanceConstraint]:
    """Layout constraints (their ``distance_m`` numbers) as solver constraints over the systems in ``order``."""
    out = []
    for c in configs:
        a, b = c.between
        lever = {k: np.asarray(v, dtype=float) for k, v in c.lever_arms_m.items()}
        out.append(DistanceConstraint(i=order.index(a), j=order.index(b), kind=c.kind, distance_m=c.distance_m,
                                      horizontal=c.horizontal, lever_i_m=lever.get(a), lever_j_m=lever.get(b)))
    return out


def constraint_solver(method: str, n_systems: int, constraints: Sequence[DistanceConstraint],
                      fuser: FuserConfig) -> ConstraintSolver:
    """The ``method`` for these constraints, with the ``fuser`` section's tolerance and iteration cap."""
    return SOLVERS[method](n_systems, constraints, tol_m=fuser.tolerance_m, max_iter=fuser.max_iterations)
