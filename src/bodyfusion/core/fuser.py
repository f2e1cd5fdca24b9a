"""The central fuser: drives every system through time and enforces the body's distance limits.

At each sync epoch the constrained systems are advanced to the epoch, their positions
and covariances stacked, all active constraints solved together in position space
(:mod:`bodyfusion.core.constraints`), and the correction spread to each system's full error
state (docs/architecture.md, "Distance constraints"):

    x* − x̂ = P_{x,p} Σ⁻¹ (p* − p̂) = −P_{x,p} Jᵀ λ,
    P* = (I − M) P (I − M)ᵀ,  M = P_{x,p} Jᵀ (J Σ Jᵀ)⁻¹ J S,

where P = blkdiag(P_1 … P_n) is the stacked error-state covariance, S selects the
positions, Σ = S P Sᵀ, and J, λ are the active constraints' Jacobian and multipliers
at the solution ([KFSC2015] eqs. 55–60 written for the full state). Each system
then takes its own block. The cross-covariances the constraint creates are dropped, as
in the papers, unless ``fuser.cross_covariance`` is on: then the fuser keeps them and
carries them between epochs with each system's accumulated transition,
C_ij ← Φ_i C_ij Φ_jᵀ (the systems' process noises are independent).

Aiding sources (:class:`bodyfusion.core.system.AidingSource`, e.g. a UWB tag) give scalar
measurements of one system's position (a range to an anchor) or of two systems'
positions (a range between two body-worn tags). At each measurement time the fuser
advances the measured systems to it (their state refers to their last sample at or
before it) and applies a gated EKF update on their stacked error states (the project's one,
:func:`bodyfusion.nav.kalman.gated_update`):

    y = z − h(p̂),  H = [∂h/∂p_i S_i ...],  s = H P Hᵀ + r,  NIS = y²/s,
    K = P Hᵀ / s,  δx = K y,  P* = (I − K H) P (I − K H)ᵀ + K r Kᵀ  (Joseph form),

rejected when the NIS exceeds the source's chi-square gate (NLOS outliers). Systems
measured together with another (body-to-body ranges) and constrained systems form one
joint state: with ``fuser.cross_covariance`` the update uses and keeps their
cross-covariances (so it also corrects the other joint members through them, and
C_ij ← (I − K H) C_ij stays consistent); without, each update acts on the measured
systems' blocks alone and the correlation it creates is dropped, as for constraints.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Set
from dataclasses import dataclass, field

import numpy as np

from bodyfusion.base.errors import FusionError
from bodyfusion.core.capabilities import AbsoluteFixes, PositionResets, TransitionTracking, offers
from bodyfusion.core.heading import HeadingTie
from bodyfusion.core.layout import BodyConfig, ConstraintConfig, FuserConfig
from bodyfusion.core.limits import LimitGuard
from bodyfusion.nav.kalman import gated_update
from bodyfusion.nav.measurements import chi2_gate
from bodyfusion.core.constraints import ConstraintSolution
from bodyfusion.core.constraints.solvers import constraint_solver, distance_constraints
from bodyfusion.core.constraints.truncation import DensityTruncation
from bodyfusion.core.constraint_log import ConstraintLog
from bodyfusion.core.joint_smoothing import JointCorrections
from bodyfusion.core.epoch_state import EpochOutput
from bodyfusion.core.schedule import CONSTRAINT, MEASUREMENT, TIE, EventSchedule
from bodyfusion.core.system import AidingSource, SensorSystem

LIMIT_STEP_M = 0.05
"""A limit that follows the gait is rounded up to a multiple of this (m): one solver per step."""
TIE_GATE_PROBABILITY = 0.999
"""Chi-square gate (1 degree of freedom) of a relative-heading measurement."""


@dataclass
class FuserReport:
    """What the fuser did; becomes metrics.json ``constraints`` where constraints exist.

    epochs: sync epochs at which constraints were checked; activations: epochs where
    at least one was active; tail_truncations: epochs where none was, but the estimate's
    density crossed a limit and was truncated there (``inequality: truncation``,
    :mod:`bodyfusion.core.constraints.truncation`); multipliers: λ of every activation (m⁻² scale, see
    :mod:`bodyfusion.core.constraints`) and solve times (µs) of every epoch are in
    ``constraint_log`` (:attr:`multipliers`, :attr:`solve_times_us`); violations in metres.
    """

    method: str
    epochs: int = 0
    activations: int = 0
    tail_truncations: int = 0
    solver_fallbacks: int = 0
    not_converged: int = 0
    max_violation_before_m: float = 0.0
    max_violation_after_m: float = 0.0
    measurements_rejected: int = 0
    """Aiding measurements beyond their gate."""
    ties_rejected: int = 0
    """Relative-heading measurements beyond their gate."""
    wall_s: float = 0.0
    constraint_log: ConstraintLog | None = None
    """Every constraint at every sync epoch (:class:`~bodyfusion.core.constraint_log.ConstraintLog`)."""
    heading_ties: list[HeadingTie] = field(default_factory=list)
    """The relative headings measured through the run, each with its log."""
    limits: LimitGuard | None = None
    """The constraints' limits through the run: the gait they followed, the fights they met."""

    @property
    def multipliers(self) -> np.ndarray:
        """λ of every activation, in the order they were made (empty without constraints)."""
        return np.empty(0) if self.constraint_log is None else self.constraint_log.active_multipliers

    @property
    def solve_times_us(self) -> np.ndarray:
        """The solver's wall time (µs) at every epoch (empty without constraints)."""
        return np.empty(0) if self.constraint_log is None else self.constraint_log.solve_us[:self.constraint_log.n]


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


class JointState:
    """Systems corrected together (constraint members, ends of body-to-body measurements):
    their stacked error-state layout and, with ``track``, the cross-covariances between
    them, carried between corrections as C_ij ← Φ_i C_ij Φ_jᵀ.

    ``blocks[k]``: slice of system k's error state in the stack; ``pos``: stacked indices
    of every system's δp, in system order.
    """

    def __init__(self, systems: list[SensorSystem], track: bool) -> None:
        self.systems = systems
        self.track = track
        sizes = [s.covariance().shape[0] for s in systems]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.blocks = [slice(int(offsets[k]), int(offsets[k + 1])) for k in range(len(systems))]
        self.pos = np.concatenate([offsets[k] + np.arange(s.position_indices.start, s.position_indices.stop)
                                   for k, s in enumerate(systems)])
        self.cross = np.zeros((offsets[-1], offsets[-1]))
        self._P = np.zeros_like(self.cross)
        self.corrections: JointCorrections | None = None
        """Every correction made, for the joint smoother (:meth:`keep_corrections`)."""
        if track:
            for s in systems:
                if not offers(s, TransitionTracking):
                    raise FusionError(f"system {s.name!r} ({s.plugin_name}) cannot track cross-covariances: "
                                      "set fuser.cross_covariance false")
                s.track_transition()

    def advance(self, t: float) -> None:
        """Advance every system to t; carry the cross-covariances with each one's Φ."""
        for k, s in enumerate(self.systems):
            s.advance(t)
            if self.track:
                self._left_multiply(k, s.transition_since_sync())

    def _left_multiply(self, k: int, A: np.ndarray) -> None:
        """C_kj ← A C_kj for every j ≠ k (and C_jk = C_kjᵀ)."""
        b = self.blocks[k]
        self.cross[b, :] = A @ self.cross[b, :]
        self.cross[:, b] = self.cross[b, :].T
        self.cross[b, b] = 0.0

    def covariance(self) -> np.ndarray:
        """Stacked covariance: each system's own blocks, the tracked cross-covariances (one
        buffer, rewritten at each call; its blocks between systems stay zero when they are not
        tracked)."""
        P = self._P
        if self.track:
            np.copyto(P, self.cross)
        for b, s in zip(self.blocks, self.systems):
            P[b, b] = s.covariance()
        return P

    def keep_corrections(self) -> None:
        """Log every correction from now on (time, stacked prior and posterior covariance, δx:
        :class:`~bodyfusion.core.joint_smoothing.JointCorrections`), for the joint smoother of a
        tracked joint state."""
        if self.track:
            self.corrections = JointCorrections([s.name for s in self.systems],
                                                [b.stop - b.start for b in self.blocks])

    def correct(self, t: float, dx: np.ndarray, P_new: np.ndarray, which: list[int],
                measured: Set[int] = frozenset()) -> None:
        """Hand each system in ``which`` its block of δx and P* (the correction at time t, s, of
        the stacked state whose covariance :meth:`covariance` last gave): as its own correction to the
        ``measured`` systems, as a relative one (derived from the others' estimates too) to
        the rest; keep P*'s cross-covariances when tracking (then ``which`` must be every
        system: all of them moved)."""
        if self.corrections is not None:
            self.corrections.record(t, self._P, P_new, dx, own=bool(measured))
        for k in which:
            b = self.blocks[k]
            if k in measured:
                self.systems[k].apply_correction(dx[b], P_new[b, b])
            else:
                self.systems[k].apply_relative_correction(dx[b], P_new[b, b])
        if self.track:
            self.cross = P_new.copy()
            for b in self.blocks:
                self.cross[b, b] = 0.0


class Fuser:
    """Runs the layout's systems to the end of their data, enforcing the constraints and
    applying the aiding sources' measurements, in time order (at one time: measurements
    first, then the heading ties, the constraints, and an output epoch last).

    Parameters: ``systems`` (name → system, initialised and heading-aligned),
    ``config`` (the layout's ``fuser`` section), ``constraints`` (the layout's list, every limit
    in metres: :func:`~bodyfusion.core.limits.resolve_constraints`; ``follows_gait``: which
    follow the feet's strides, ``body``: the wearer, :class:`~bodyfusion.core.limits.LimitGuard`),
    ``aiding`` (name → aiding source), ``ties`` (the relative headings kept through the run,
    :class:`~bodyfusion.core.heading.HeadingTie`: measured at both systems' sync epochs, after
    the measurements and before the constraints of one time), ``output`` (an
    :class:`~bodyfusion.core.epoch_state.EpochOutput`: states emitted every ``interval_s`` of
    data, to its sinks; None: none). Result: ``report`` (:class:`FuserReport`).

    It is a clock (:class:`~bodyfusion.core.schedule.EventSchedule`): :meth:`advance` takes
    every event up to the time all systems' data are decided
    (:meth:`~bodyfusion.core.system.SensorSystem.decided_until`), :meth:`finish` the rest and
    the systems' last samples. :meth:`run` is both: a batch run is a live run whose data were
    all in hand at its start, and takes the same events in the same order.
    """

    def __init__(self, systems: Mapping[str, SensorSystem], config: FuserConfig,
                 constraints: list[ConstraintConfig] | None = None,
                 aiding: Mapping[str, AidingSource] | None = None, ties: list[HeadingTie] | None = None,
                 follows_gait: list[bool] | None = None, body: BodyConfig | None = None,
                 output: EpochOutput | None = None) -> None:
        self.systems = systems
        self.config = config
        self.constraints = constraints or []
        self.follows_gait = follows_gait or [False] * len(self.constraints)
        self.body = body or BodyConfig()
        self.aiding = dict(aiding or {})
        self.ties = list(ties or [])
        self.output = output
        self.report = FuserReport(method=config.method, heading_ties=self.ties)
        self._wall_s = 0.0
        constrained = self.config.method != "none" and bool(self.constraints)
        order = list(dict.fromkeys(name for c in self.constraints for name in c.between)) if constrained else []
        n_constrained = len(order)
        self._sources = list(self.aiding.values())
        for src in self._sources:
            pairs = {src.measured_systems(k) for k in range(len(src.measurement_times()))}
            order += [name for pair in pairs if len(pair) > 1 for name in pair if name not in order]
        order += [name for tie in self.ties for name in (tie.reference, tie.system) if name not in order]
        self.joint = JointState([self.systems[name] for name in order], self.config.cross_covariance) if order else None
        self._index = {name: k for k, name in enumerate(order)}
        members: list[SensorSystem] = []
        if constrained:
            members = self.joint.systems[:n_constrained]
            self._order = order[:n_constrained]
            self._solvers: dict[tuple[float, ...], tuple] = {}
            parts = [s.body_part for s in members]
            self.report.limits = LimitGuard(self.constraints, self.follows_gait, self._order, parts,
                                            {i: np.empty(0) for i in range(n_constrained) if parts[i] == "foot"},
                                            self.body, self.config.relax_fights)
            self.report.constraint_log = ConstraintLog(self.constraints, order[:n_constrained])
            self._pos = self.joint.pos[:3 * n_constrained].astype(np.int64)
            n_joint = self.joint.cross.shape[0]  # Σ = P[pos][:, pos] by flat indices: a quarter of np.ix_'s cost
            self._sigma_index = (self._pos[:, None] * n_joint + self._pos[None, :]).ravel()
            self._corrected = list(range(len(order) if self.joint.track else n_constrained))
            self._positions = [s.position_n for s in members]  # bound once: called at every epoch
            self._truncating = self.config.inequality == "truncation"
        tied = [self.systems[n] for n in dict.fromkeys(m for tie in self.ties for m in (tie.reference, tie.system))]
        if self.ties:
            self._tie_gate = chi2_gate(TIE_GATE_PROBABILITY, 1)
        self.schedule = EventSchedule(members, self._sources, tied, config, list(self.systems.values()),
                                      output.interval_s if output is not None else None,
                                      self.report.limits.add_sync_times if constrained else None)

    def decided_until(self) -> float:
        """The time (s) up to which every system's and aiding source's data are decided (∞: all)."""
        return min((p.decided_until() for p in (*self.systems.values(), *self._sources)), default=math.inf)

    def advance(self, until: float = math.inf) -> float:
        """Take every event up to ``until`` (s) and the data's decided time; returns the schedule's
        horizon (s) after it."""
        t_begin = time.perf_counter()
        horizon = min(until, self.decided_until())
        events = self.schedule.until(horizon)
        log = self.report.constraint_log
        if log is not None:
            log.reserve(sum(kind == CONSTRAINT for _, kind, _, _ in events))
        for t, kind, i, k in events:
            if kind == MEASUREMENT:
                self._measurement(self._sources[i], k, t)
            elif kind == TIE:
                self._tie_epoch(t)
            elif kind == CONSTRAINT:
                self._constraint_epoch(t)
            else:
                self.output.emit(t, self.systems, self.report)
        self._wall_s += time.perf_counter() - t_begin
        return self.schedule.horizon

    def forget_before(self, t: float) -> None:
        """Drop what the fuser keeps of the epochs before ``t`` (s): the constraint log's rows, the
        heading ties' measurements and the feet's sync times the limits have passed (a live run
        that keeps a bounded history; the report's counts stay whole)."""
        for tie in self.ties:
            tie.forget_before(t)
        if self.report.constraint_log is not None:
            self.report.constraint_log.forget_before(t)
        if self.report.limits is not None:
            self.report.limits.forget_passed()

    def finish(self) -> FuserReport:
        """Every remaining event, then every system to its last sample."""
        self.advance(math.inf)
        t_begin = time.perf_counter()
        for system in self.systems.values():
            system.advance(system.t_end)
        self._wall_s += time.perf_counter() - t_begin
        self.report.wall_s = self._wall_s
        return self.report

    def run(self) -> FuserReport:
        """The whole run: :meth:`finish` from the start."""
        return self.finish()

    def _measurement(self, src: AidingSource, k: int, t: float) -> None:
        """Gated scalar update with measurement k of ``src`` at time t."""
        names = src.measured_systems(k)
        measured = [self.systems[name] for name in names]
        if any(t < s.t_start or t > s.t_end for s in measured):
            src.record(k, None, False)
            return
        joint = [self._index[name] for name in names if name in self._index]
        if joint:
            self.joint.advance(t)
            P = self.joint.covariance()
            offsets = [self.joint.blocks[self._index[name]].start for name in names]
            which = list(range(len(self.joint.systems))) if self.joint.track else joint
        else:  # one system on its own
            measured[0].advance(t)
            P = measured[0].covariance()
            offsets = [0]
        m = src.measure(k, [s.position_n() for s in measured])
        H = np.zeros(P.shape[0])
        for row, s, off in zip(np.atleast_2d(m.H_p), measured, offsets):
            H[off + s.position_indices.start:off + s.position_indices.stop] += row
        nis, accepted, dx, P_new = gated_update(P, H, m.r_var, m.z - m.predicted, src.gate_nis)
        src.record(k, nis, accepted)
        if not accepted:
            self.report.measurements_rejected += 1
            return
        if joint:
            # a measurement of one system is its own; one between systems (or spread to the
            # others by the cross-covariances) is relative for every system it moves
            self.joint.correct(t, dx, P_new, which, measured=frozenset(joint) if len(names) == 1 else frozenset())
        else:
            measured[0].apply_correction(dx, P_new)

    def _tie_epoch(self, t: float) -> None:
        """Measure every heading tie whose stretch is complete at time t (gated scalar update of
        the two systems' joint error state, relative for both) and start its next stretch."""
        joint = self.joint
        joint.advance(t)
        for tie in self.ties:
            a, b = self._index[tie.reference], self._index[tie.system]
            ref, sys = joint.systems[a], joint.systems[b]
            tie.add(ref.position_n(), sys.position_n())
            got = tie.measure(self._lateral_sd(ref, tie), self._lateral_sd(sys, tie))
            if got is None:
                continue
            z, r_var = got
            P = joint.covariance()
            H = np.zeros(P.shape[0])
            H[joint.blocks[b]] += sys.yaw_error_row()
            H[joint.blocks[a]] -= ref.yaw_error_row()
            nis, accepted, dx, P_new = gated_update(P, H, r_var, z, self._tie_gate)
            tie.log.append((t, z, float(np.sqrt(r_var)), nis, accepted))
            self.report.ties_rejected += int(not accepted)
            if accepted:
                joint.correct(t, dx, P_new, list(range(len(joint.systems))) if joint.track else [a, b])
            tie.restart_at(ref.position_n(), sys.position_n())

    @staticmethod
    def _lateral_sd(system: SensorSystem, tie: HeadingTie) -> float:
        """A stretch end's lateral σ (m): the tie's for a dead-reckoning system, the horizontal
        position σ for one whose heading (and position) is geographic."""
        if not system.heading_is_absolute:
            return tie.lateral_sd_m
        P = system.covariance()
        rows = system.position_indices
        return float(np.sqrt(max(0.5 * (P[rows.start, rows.start] + P[rows.start + 1, rows.start + 1]),
                                 tie.lateral_sd_m**2)))

    def _constraint_epoch(self, t: float) -> None:
        """Solve the active constraints among the constrained systems (the first joint ones) at
        time t and spread the correction (to every joint system when cross-covariances are
        tracked)."""
        joint, rep, pos = self.joint, self.report, self._pos
        joint.advance(t)
        self.follow_position_resets()
        P = joint.covariance()
        p_hat = np.concatenate([position() for position in self._positions])
        limits = rep.limits.limits(t, p_hat)
        solver, truncation = self._solvers_for(limits)
        sigma = P.take(self._sigma_index).reshape(pos.size, pos.size)
        t0 = time.perf_counter_ns()
        sol = solver.solve(p_hat, sigma)
        solve_us = (time.perf_counter_ns() - t0) / 1e3
        rep.limits.watch(t, p_hat, sigma, limits)
        rep.epochs += 1
        rep.solver_fallbacks += int(sol.fallback)
        rep.not_converged += int(not sol.converged)
        rep.max_violation_before_m = max(rep.max_violation_before_m, sol.violation_before_m)
        rep.max_violation_after_m = max(rep.max_violation_after_m, sol.violation_after_m)
        if self._truncating:
            dx, P_new, tail = truncation.correct(P, pos, p_hat, sol)
            if not sol.active and not tail.any():
                rep.constraint_log.record(t, p_hat, p_hat, sol, solve_us, limits)
                return
            rep.tail_truncations += int(not sol.active)
        elif sol.active:
            dx, P_new = spread_correction(P, pos, sol, self.config.correct == "positions")
            tail = None
        else:
            rep.constraint_log.record(t, p_hat, p_hat, sol, solve_us, limits)
            return
        rep.activations += int(bool(sol.active))
        joint.correct(t, dx, P_new, self._corrected)
        rep.constraint_log.record(t, p_hat, p_hat + dx[pos], sol, solve_us, limits, tail)

    def follow_position_resets(self) -> None:
        """Move the body with a system that took its position afresh from its absolute sensor
        (:class:`~bodyfusion.core.capabilities.PositionResets`) by more than a limit it is held
        to: every system reached from it through the constraints, but those with absolute fixes
        of their own (and what lies beyond them), moves by the same amount (a translation: a
        relative correction, covariance kept), so that the constraint follows the fix instead of
        dragging the system back from it at every epoch. Each move is in the limits' record
        (:meth:`~bodyfusion.core.limits.LimitGuard.follow`)."""
        guard = self.report.limits
        for name, system in zip(self._order, self.joint.systems):
            if not offers(system, PositionResets):
                continue
            for t_reset, move in system.take_position_resets():
                if not guard.beyond_limits(name, move):
                    continue
                followers = self._held_to(name)
                for follower in followers:
                    held = self.systems[follower]
                    dx = np.zeros(held.P.shape[0])
                    dx[held.position_indices] = move
                    held.apply_relative_correction(dx, held.P.copy())
                guard.follow(t_reset, name, followers, move)

    def _held_to(self, name: str) -> list[str]:
        """The systems reached from ``name`` through the constraints, not passing through (nor
        taking) one that carries absolute fixes of its own."""
        reached, todo = [name], [name]
        while todo:
            here = todo.pop()
            for c in self.constraints:
                if here in c.between:
                    other = c.between[1] if c.between[0] == here else c.between[0]
                    system = self.systems[other]
                    if other in reached or (offers(system, AbsoluteFixes) and system.absolute_fixes() is not None):
                        continue
                    reached.append(other)
                    todo.append(other)
        return reached[1:]

    def _solvers_for(self, limits: np.ndarray) -> tuple:
        """The solver and the density truncation of the constraints at ``limits`` (m), built once
        per set of limits (a limit that follows the gait moves in :data:`LIMIT_STEP_M` steps)."""
        key = tuple(float(d) if not follows else float(np.ceil(d / LIMIT_STEP_M) * LIMIT_STEP_M)
                    for d, follows in zip(limits, self.follows_gait))
        built = self._solvers.get(key)
        if built is None:
            cons = distance_constraints([c.model_copy(update={"distance_m": d}) for c, d in zip(self.constraints, key)],
                                        self._order)
            n = len(self._order)
            built = (constraint_solver(self.config.method, n, cons, self.config),
                     DensityTruncation(cons, n, self.config.correct == "positions"))
            self._solvers[key] = built
        limits[:] = key
        return built
