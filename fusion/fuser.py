"""The central fuser: drives every system through time and enforces the body's distance limits.

At each sync epoch the constrained systems are advanced to the epoch, their positions
and covariances stacked, all active constraints solved together in position space
(:mod:`fusion.constraints`), and the correction spread to each system's full error
state (DESIGN.md, "Distance constraints"):

    x* − x̂ = P_{x,p} Σ⁻¹ (p* − p̂) = −P_{x,p} Jᵀ λ,
    P* = (I − M) P (I − M)ᵀ,  M = P_{x,p} Jᵀ (J Σ Jᵀ)⁻¹ J S,

where P = blkdiag(P_1 … P_n) is the stacked error-state covariance, S selects the
positions, Σ = S P Sᵀ, and J, λ are the active constraints' Jacobian and multipliers
at the solution (PDR/GNSS paper eqs. 55–60 written for the full state). Each system
then takes its own block. The cross-covariances the constraint creates are dropped, as
in the papers, unless ``fuser.cross_covariance`` is on: then the fuser keeps them and
carries them between epochs with each system's accumulated transition,
C_ij ← Φ_i C_ij Φ_jᵀ (the systems' process noises are independent).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from fusion.config import ConstraintConfig, FuserConfig
from fusion.constraints import (ConstraintSolution, DistanceConstraint, ProjectionSolver, QpSolver,
                                SocpSolver)
from fusion.system import SensorSystem

SOLVERS = {"projection": ProjectionSolver, "qp": QpSolver, "socp": SocpSolver}


@dataclass
class FuserReport:
    """What the fuser did; becomes metrics.json ``constraints`` where constraints exist.

    epochs: sync epochs at which constraints were checked; activations: epochs where
    at least one was active; multipliers: λ of every activation (m⁻² scale, see
    :mod:`fusion.constraints`); violations in metres; solve times in µs.
    """

    method: str
    epochs: int = 0
    activations: int = 0
    solver_fallbacks: int = 0
    not_converged: int = 0
    max_violation_before_m: float = 0.0
    max_violation_after_m: float = 0.0
    multipliers: list[float] = field(default_factory=list)
    solve_times_us: list[float] = field(default_factory=list)
    wall_s: float = 0.0


def distance_constraints(configs: list[ConstraintConfig], order: list[str]) -> list[DistanceConstraint]:
    """Layout constraints as solver constraints over the systems in ``order``."""
    out = []
    for c in configs:
        a, b = c.between
        lever = {k: np.asarray(v, dtype=float) for k, v in c.lever_arms_m.items()}
        out.append(DistanceConstraint(i=order.index(a), j=order.index(b), kind=c.kind, distance_m=c.distance_m,
                                      horizontal=c.horizontal, lever_i_m=lever.get(a), lever_j_m=lever.get(b)))
    return out


def epoch_times(systems: list[SensorSystem], config: FuserConfig) -> np.ndarray:
    """Sync epochs (s) inside the span all constrained systems cover."""
    t0 = max(s.t_start for s in systems)
    t1 = min(s.t_end for s in systems)
    if config.epochs == "events":
        times = np.concatenate([s.sync_times() for s in systems])
    elif config.epochs == "interval":
        times = np.arange(t0 + config.interval_s, t1, config.interval_s)
    else:
        times = np.concatenate([s.sample_times() for s in systems])
    times = np.unique(times)
    return times[(times > t0) & (times <= t1)]


def spread_correction(P: np.ndarray, pos: np.ndarray, solution: ConstraintSolution,
                      positions_only: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Joint error-state correction dx and covariance P* from a position-space solution.

    P: (n, n) joint error-state covariance of the constrained systems (block diagonal
    unless cross-covariances are tracked); pos: indices of their positions in it, in
    the order of the solver's stacked positions. ``positions_only`` keeps every other
    state out of the correction (Schmidt consider states: their rows of the gain are
    zero; the Joseph form keeps P* the exact covariance of that sub-optimal update).
    """
    P_xp = P[:, pos]
    J = solution.jacobian
    lam = solution.multipliers[solution.active]
    dx = -P_xp @ (J.T @ lam)
    JS = J @ P[pos][:, pos] @ J.T
    M = np.zeros_like(P)
    M[:, pos] = P_xp @ J.T @ np.linalg.solve(JS, J)
    if positions_only:
        others = np.setdiff1d(np.arange(P.shape[0]), pos)
        dx[others] = 0.0
        M[others] = 0.0
    IM = np.eye(P.shape[0]) - M
    P_new = IM @ P @ IM.T
    return dx, 0.5 * (P_new + P_new.T)


class Fuser:
    """Runs the layout's systems to the end of their data, enforcing the constraints.

    Parameters: ``systems`` (name → system, initialised and heading-aligned),
    ``config`` (the layout's ``fuser`` section), ``constraints`` (the layout's list).
    Result: ``report`` (:class:`FuserReport`).
    """

    def __init__(self, systems: Mapping[str, SensorSystem], config: FuserConfig,
                 constraints: list[ConstraintConfig] | None = None) -> None:
        self.systems = systems
        self.config = config
        self.constraints = constraints or []
        self.report = FuserReport(method=config.method)

    def run(self) -> FuserReport:
        t_begin = time.perf_counter()
        if self.config.method != "none" and self.constraints:
            self._run_constrained()
        for system in self.systems.values():
            system.advance(system.t_end)
        self.report.wall_s = time.perf_counter() - t_begin
        return self.report

    def _run_constrained(self) -> None:
        order = list(dict.fromkeys(name for c in self.constraints for name in c.between))
        members = [self.systems[name] for name in order]
        solver_cls = SOLVERS[self.config.method]
        solver = solver_cls(len(members), distance_constraints(self.constraints, order),
                            tol_m=self.config.tolerance_m, max_iter=self.config.max_iterations)
        sizes = [s.covariance().shape[0] for s in members]
        offsets = np.concatenate([[0], np.cumsum(sizes)])
        blocks = [slice(offsets[k], offsets[k + 1]) for k in range(len(members))]
        pos = np.concatenate([offsets[k] + np.arange(s.position_indices.start, s.position_indices.stop)
                              for k, s in enumerate(members)])
        track = self.config.cross_covariance
        joint = np.zeros((offsets[-1], offsets[-1]))
        if track:
            for s in members:
                s.track_transition()
        n3 = 3 * len(members)
        p_hat = np.empty(n3)
        sigma = np.zeros((n3, n3))
        rep = self.report
        for t in epoch_times(members, self.config):
            covs = []
            for k, s in enumerate(members):
                s.advance(t)
                P = s.covariance()
                covs.append(P)
                p_hat[3 * k:3 * k + 3] = s.position_n()
                sigma[3 * k:3 * k + 3, 3 * k:3 * k + 3] = P[s.position_indices, s.position_indices]
            if track:
                # cross blocks: C_ij ← Φ_i C_ij Φ_jᵀ, then the marginal position cross-covariances
                phis = [s.transition_since_sync() for s in members]
                for a in range(len(members)):
                    for b in range(a + 1, len(members)):
                        c = phis[a] @ joint[blocks[a], blocks[b]] @ phis[b].T
                        joint[blocks[a], blocks[b]] = c
                        joint[blocks[b], blocks[a]] = c.T
                        pa, pb = members[a].position_indices, members[b].position_indices
                        sigma[3 * a:3 * a + 3, 3 * b:3 * b + 3] = c[pa, pb]
                        sigma[3 * b:3 * b + 3, 3 * a:3 * a + 3] = c[pa, pb].T
            t0 = time.perf_counter_ns()
            sol = solver.solve(p_hat, sigma)
            rep.solve_times_us.append((time.perf_counter_ns() - t0) / 1e3)
            rep.epochs += 1
            rep.solver_fallbacks += int(sol.fallback)
            rep.not_converged += int(not sol.converged)
            rep.max_violation_before_m = max(rep.max_violation_before_m, sol.violation_before_m)
            rep.max_violation_after_m = max(rep.max_violation_after_m, sol.violation_after_m)
            if not sol.active:
                continue
            rep.activations += 1
            rep.multipliers.extend(float(v) for v in sol.multipliers[sol.active])
            for k, P in enumerate(covs):
                joint[blocks[k], blocks[k]] = P
            dx, P_new = spread_correction(joint, pos, sol, self.config.correct == "positions")
            if track:
                joint[:] = P_new
            for k, s in enumerate(members):
                s.apply_correction(dx[blocks[k]], P_new[blocks[k], blocks[k]])
