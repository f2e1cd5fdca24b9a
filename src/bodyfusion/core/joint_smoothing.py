"""The joint RTS of systems the fuser corrected together (``smoother.joint``).

With ``fuser.cross_covariance`` the fuser's joint state is the stacked state of its members (the
constrained feet, the ends of heading ties and body-to-body ranges) with their cross-covariances
carried between corrections, and each correction (a distance constraint, a tie) is an update of
that stacked state. Smoothed one system at a time, such a correction can only be kept as a known
input of each (it was derived from the other's filtered estimate too); smoothed here, it is
information that reaches both smoothed tracks.

The smoother is the fixed-interval RTS of the stacked state in the modified Bryson–Frazier form
(:func:`~bodyfusion.plugins.foot_ins.smoothing_mbf.mbf_sweep`): an adjoint lam (n,) and Lam
(n, n) over every member's error state, with dxs = −P lam and Ps = P − P Lam P of the stacked
covariance P. Between two joint corrections the members evolve independently (block-diagonal
transitions and own updates), so the sweep moves one member at a time: member q is swept back from
its sample at the later correction to its sample at the earlier one while the members before it
stand at the earlier correction and those after it at the later one. Its cross-covariance with
them is the fuser's at the earlier correction, C⁺, carried by its own steps and by the later
members' transitions over the stretch (U_p): Z_q(i) = A_q(i…) C⁺_qp U_pᵀ (p > q) or
A_q(i…) C⁺_qp (p < q). At a correction the whole adjoint is taken back through the update
from the fuser's prior and posterior stacked covariances and its correction dx
(:func:`_through_correction`):

    lam⁻ = −(P⁻)⁻¹ (e + dx),  e = −P⁺ lam⁺,
    Lam⁻ = (P⁻)⁻¹ (P⁻ − P⁺ + P⁺ Lam⁺ P⁺) (P⁻)⁻¹,

the general form of an update (any update: a projection, a truncation, a tie), exact where the
update is a Kalman update of the stacked state. Corrections at the same samples of every member
are taken as one. The cross-covariance a member's forward carriage reaches at the later
correction is checked against the fuser's (``cross_rebuild_rel_error``).

One approximation: a member's own update (a foot's ZUPT) is not a Kalman update of the stacked
state, since the fuser's filter does not let it correct the others through the cross-covariance;
the sweep takes it back as the member's own (its adjoint, and the cross block X ← Aᵀ X, the
others' adjoint left as it is). The order the members are swept in exposes it: on the dual-foot
Vicon walk, sweeping the right foot first instead of the left moves the smoothed tracks by
1.6 mm at most at the layout's limit, 10 mm with a 0.4 m limit. Taken back in the general form
of the stacked state instead (the textbook RTS of this filter), those updates need the inverse of
a stacked covariance that a hard limit has left nearly singular, and the sweep diverged.

The core knows no sensor: a member is what :meth:`~bodyfusion.core.capabilities.JointSmoothing.joint_smoothing_member`
returns (:class:`JointMember`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
import scipy.linalg

from bodyfusion.base.errors import FusionError


class JointMember(Protocol):
    """One system's part in the joint RTS (the foot INS's:
    :class:`~bodyfusion.plugins.foot_ins.smoothing_joint.JointRtsMember`)."""

    size: int
    samples: int

    def sample_at(self, t: float) -> int:
        """The sample the system stood at when the fuser corrected it at time t (s)."""

    def transfer(self, a: int, b: int) -> np.ndarray:
        """The closed-loop transition (size, size) from sample a to b."""

    def sweep(self, a: int, b: int, write_last: bool, W: np.ndarray, lam: np.ndarray, Lam: np.ndarray,
              X: np.ndarray, lam_o: np.ndarray, Lam_oo: np.ndarray) -> np.ndarray:
        """Sweep back from b to a with the cross-covariance W at a; returns the one at b."""

    def finish(self, diagnostics: dict) -> dict:
        """Hand the smoothed track to the system; returns the system's smoothing diagnostics."""


@dataclass
class JointCorrections:
    """Every correction of the fuser's joint state (:class:`~bodyfusion.core.fuser.JointState`)
    while its cross-covariances are tracked: time (s), the stacked prior and posterior
    covariances and the correction (n,), and whether any member took it as its own measurement
    (an aiding source's of one system: then the joint smoother does not apply)."""

    names: list[str]
    sizes: list[int]
    t: list[float] = field(default_factory=list)
    P_prior: list[np.ndarray] = field(default_factory=list)
    P_post: list[np.ndarray] = field(default_factory=list)
    dx: list[np.ndarray] = field(default_factory=list)
    own: bool = False

    def record(self, t: float, P_prior: np.ndarray, P_post: np.ndarray, dx: np.ndarray, own: bool) -> None:
        self.t.append(float(t))
        self.P_prior.append(P_prior.copy())
        self.P_post.append(P_post.copy())
        self.dx.append(dx.copy())
        self.own |= own


def _through_correction(P_prior: np.ndarray, P_post: np.ndarray, dx: np.ndarray, lam: np.ndarray,
                        Lam: np.ndarray) -> bool:
    """(lam, Lam) in place from after a correction of the stacked state to before it (module
    docstring). False (and zeros: the sweep restarts from the filter there) when P⁻ is not
    positive definite."""
    e = -P_post @ lam
    Ps = P_post - P_post @ Lam @ P_post
    d = np.diag(P_prior)
    if not np.all(d > 0.0):
        lam[:] = 0.0
        Lam[:] = 0.0
        return False
    s = 1.0 / np.sqrt(d)  # Jacobi-scaled: the diagonal spans many decades
    try:
        factor = scipy.linalg.cho_factor(P_prior * s[:, None] * s[None, :], check_finite=False)
    except np.linalg.LinAlgError:
        lam[:] = 0.0
        Lam[:] = 0.0
        return False
    # one solve for (P⁻)⁻¹ [P⁻ − Ps | e + dx], one for the right-hand (P⁻)⁻¹
    B = np.column_stack([P_prior - Ps, e + dx]) * s[:, None]
    Y = s[:, None] * scipy.linalg.cho_solve(factor, B, check_finite=False)
    lam[:] = -Y[:, -1]
    M = s[:, None] * scipy.linalg.cho_solve(factor, s[:, None] * Y[:, :-1].T, check_finite=False)
    Lam[:] = 0.5 * (M + M.T)
    return True


def _events(members: list[JointMember], log: JointCorrections) -> list[tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                          np.ndarray]]:
    """The log's corrections as events (each member's sample, P⁻, P⁺, dx), those at the same
    samples of every member taken as one (P⁻ of the first, P⁺ of the last, the corrections summed)."""
    events: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for t, P0, P1, dx in zip(log.t, log.P_prior, log.P_post, log.dx):
        at = np.array([m.sample_at(t) for m in members], dtype=np.int64)
        if events and np.array_equal(events[-1][0], at):
            last = events[-1]
            events[-1] = (at, last[1], P1, last[3] + dx)
        else:
            events.append((at, P0, P1, dx))
    return events


def smooth_jointly(members: dict[str, JointMember], log: JointCorrections) -> dict[str, dict]:
    """The joint RTS of ``members`` (in the order of the fuser's joint state) over the corrections
    in ``log``; each member hands its smoothed track to its system. Returns each member's
    smoothing diagnostics (the joint sweep's under ``joint``)."""
    t0 = time.perf_counter()
    if log.own:
        raise FusionError("a measurement of one system moved the joint state (an aiding source's)")
    order = list(members.values())
    sizes = [m.size for m in order]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    blocks = [np.arange(offsets[k], offsets[k + 1]) for k in range(len(order))]
    n = int(offsets[-1])
    events = _events(order, log)
    lam, Lam = np.zeros(n), np.zeros((n, n))
    ends = np.array([m.samples - 1 for m in order], dtype=np.int64)
    failures, rebuild = 0, 0.0
    members_q = []  # per member: its block, the others' indices and the index grids between them
    for q in range(len(order)):
        own = blocks[q]
        others = np.concatenate([blocks[p] for p in range(len(order)) if p != q])
        members_q.append((own, others, np.ix_(own, own), np.ix_(own, others), np.ix_(others, own),
                          np.ix_(others, others), [(p, np.ix_(own, blocks[p])) for p in range(len(order)) if p != q]))
    for g in range(len(events) - 1, -2, -1):
        starts = events[g][0] if g >= 0 else np.zeros(len(order), dtype=np.int64)
        C = events[g][2] if g >= 0 else np.zeros((n, n))  # the cross-covariances after event g
        # the later members' transitions over the stretch (the first's is never needed)
        U = [None] + [order[p].transfer(int(starts[p]), int(ends[p])) for p in range(1, len(order))]
        for q, member in enumerate(order):
            own, others, qq, qo, oq, oo, pairs = members_q[q]
            W = np.hstack([C[qp] @ U[p].T if p > q else C[qp] for p, qp in pairs])
            lam_q, Lam_qq, X = lam[own], Lam[qq], np.ascontiguousarray(Lam[qo])
            Z_end = member.sweep(int(starts[q]), int(ends[q]), g == len(events) - 1, W, lam_q, Lam_qq, X,
                                 lam[others], np.ascontiguousarray(Lam[oo]))
            lam[own] = lam_q
            Lam[qq] = Lam_qq
            Lam[qo] = X
            Lam[oq] = X.T
            if q == 0 and g + 1 < len(events):  # every other member at the later correction: the fuser's prior there
                C_next = events[g + 1][1][qo]
                rebuild = max(rebuild, float(np.max(np.abs(Z_end - C_next)) / max(np.max(np.abs(C_next)), 1e-300)))
        if g >= 0:
            _, P_prior, P_post, dx = events[g]
            failures += not _through_correction(P_prior, P_post, dx, lam, Lam)
            ends = starts
    diagnostics = {"members": list(members), "corrections": len(log.t), "events": len(events),
                   "correction_failures": failures, "cross_rebuild_rel_error": rebuild,
                   "wall_s": time.perf_counter() - t0}
    return {name: member.finish(diagnostics) for name, member in members.items()}
