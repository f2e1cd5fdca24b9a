"""Distance constraints between body-worn systems, solved in POSITION space ([KFSC2015] eqs. 55–60).

The fuser stacks the constrained systems' position estimates p̂ = [p_1; ...; p_n]
(3n,), ENU metres, with their marginal covariance Σ (3n, 3n), and asks for the
constrained positions

    p* = argmin ½ (p − p̂)ᵀ Σ⁻¹ (p − p̂)   s.t. every DistanceConstraint holds,

plus the gain μ with Σ* = (I − μ) Σ (I − μ)ᵀ. The constraints bound the distance
‖E (p_i + l_i − p_j − l_j)‖ between two systems (``max``, ``min`` or ``fixed``,
horizontal or 3-D, with lever arms); their functions, the multiplier sign and the
handling of a zero separation are defined in :mod:`.model`.

Methods
-------
All three reach the same point — the KKT point of the nonlinear problem, which is
also the fixed point of the paper's "linearise about the current point and
project" iteration — and report μ from eqs. 59–60 with the active constraints
linearised at p*.

``projection`` (:func:`solve_projection`, :class:`ProjectionSolver`)
    The paper's projection, linearised at the solution: Newton's method (the
    secular equation for one candidate constraint, an SQP for several) finds the
    linearisation point (:mod:`.projection`).
``qp`` (:class:`QpSolver`)
    The SQP with OSQP on the whitened QPs, by default started from the
    projection: one QP per epoch certifies it (:mod:`.qp`).
``socp`` (:class:`SocpSolver`)
    cvxpy, exact cones for ``max`` constraints, polished by Newton on the KKT
    system: a reference/oracle, not a hot path (:mod:`.socp`).

Solver failure never raises: :class:`QpSolver` and :class:`SocpSolver` then return
the projection solution with ``fallback=True``.

Modules, each importing only those above it:

* :mod:`.kernels` — the numba kernels of one constraint's projection and certification,
  cached on disk; :mod:`.qp_kernels` — those of the SQP's QPs (linearisation, OSQP's start);
* :mod:`.model` — :class:`DistanceConstraint`, :class:`ConstraintSolution`, the
  stacked layout, input checks, hint directions, :func:`violations`, :func:`linearised`,
  :func:`constrained_covariance`;
* :mod:`.linearisation` — eqs. 58–60 on a linearised active set, certification of
  another solver's point;
* :mod:`.sqp` — whitening and the sequential QP with a pluggable QP solver;
* :mod:`.projection`, :mod:`.qp`, :mod:`.socp` — the three methods;
* :mod:`.solvers` — the :class:`~.solvers.ConstraintSolver` protocol they share, the methods by
  name, and the layout's constraints and solver built from its sections.
* :mod:`.truncation` — the fuser's density truncation of the joint error state at the
  limits, compiled ([Simon2010]).
"""

from bodyfusion.core.constraints.model import (ConstraintSolution, DistanceConstraint, constrained_covariance,
                                               linearised, violations)
from bodyfusion.core.constraints.projection import ProjectionSolver, solve_projection
from bodyfusion.core.constraints.qp import QpSolver
from bodyfusion.core.constraints.socp import SocpSolver

__all__ = [
    "DistanceConstraint",
    "ConstraintSolution",
    "violations",
    "solve_projection",
    "ProjectionSolver",
    "QpSolver",
    "SocpSolver",
    "constrained_covariance",
    "linearised",
]
